#version 430
// The per-pixel effects, one program per effect (EFFECT defined by the host). Each acts
// on its own pixel only, in place.
layout(local_size_x = 8, local_size_y = 8) in;
#include "sensor.glsl"

uniform float a;  // the effect's parameters, in the order of the host's pass
uniform float b;
uniform float c;
uniform float d_;
uniform int model;
uniform ivec4 band;  // registration: left, right, top, bottom (px)
uniform vec4 intr;   // fx, fy, cx, cy
uniform sampler2D proj_tex;  // EXACT_SHADOW: planar depth seen from the projector

const float DEG85 = 1.4835298641951802;

float grazing_angle(uint p) {
    return min(acos(clamp(inc[p], 0.0, 1.0)), DEG85);
}

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    if (q.x >= size.x || q.y >= size.y) return;
    uint p = uint(q.y * size.x + q.x);
#if EFFECT == INVERT
    // depth <-> disparity: v <- fb / v where valid
    if (is_valid(p)) val[p] = fb / val[p]; else val[p] = 0.0;
#elif EFFECT == RANGE_GATE
    // a = z_min, b = z_max (depth domain)
    float z = val[p];
    if (is_valid(p) && (z < a || z > b)) remove_pixel(p, RANGE);
#elif EFFECT == RANGE_DROPOUT
    // a = z_start, b = z_end, c = power, model = blob_px (depth domain): one uniform per
    // blob cell, compared with each pixel's own probability
    if (is_valid(p)) {
        uint cols = uint((size.x + model - 1) / model);
        uint cell = uint(q.y / model) * cols + uint(q.x / model);
        float u = draw_uniform(cell, 0u);
        float frac = clamp((val[p] - a) / (b - a), 0.0, 1.0);
        if (u < pow(frac, c)) remove_pixel(p, RANGE);
    }
#elif EFFECT == AXIAL_NOISE
    // model 0 disparity (a = sigma_px, disparity domain); 1 khoshelham, 2 nguyen (b = 1:
    // angle term), 3 barron_malik (depth domain)
    if (is_valid(p)) {
        float n = draw_normal(p, 0u);
        float v = val[p];
        if (model == 0) {
            v += a * n;
        } else if (model == 3) {
            float z_cm = floor(v * 100.0 + 0.5);
            float dq = floor(35130.0 / max(z_cm, 1.0) + n / 6.0 + 0.5);
            v = dq > 0.0 ? 35130.0 / dq / 100.0 : 0.0;
        } else {
            float sigma;
            if (model == 1) {
                sigma = 1.425e-3 * v * v;
            } else {
                sigma = 0.0012 + 0.0019 * (v - 0.4) * (v - 0.4);
                if (b > 0.5) {
                    float th = grazing_angle(p);
                    if (th > 1.0471975511965976) {
                        float g = 1.5707963267948966 - th;
                        sigma += 1e-4 / sqrt(max(v, 1e-6)) * th * th / (g * g);
                    }
                }
            }
            v += sigma * n;
        }
        if (v <= 0.0) remove_pixel(p, NOISE); else val[p] = v;
    }
#elif EFFECT == DROPOUT
    // a = cos_min, b = r_max (m; negative: no range rule) (depth domain)
    if (is_valid(p)) {
        vec2 xy = (vec2(q) - intr.zw) / intr.xy;
        float r = val[p] * sqrt(dot(xy, xy) + 1.0);
        if (inc[p] < a || (b >= 0.0 && r > b)) remove_pixel(p, DROPOUT);
    }
#elif EFFECT == QUANTISE
    // a = step_px (disparity domain), rounded half up; a pixel quantised to <= 0 is lost
    if (is_valid(p)) {
        float dq = floor(val[p] / a + 0.5) * a;
        if (dq <= 0.0) remove_pixel(p, NOISE); else val[p] = dq;
    }
#elif EFFECT == EXACT_SHADOW
    // a = tolerance (depth domain): shadowed when the projector sees a surface nearer
    // than the pixel's own by more than the tolerance at both columns around where the
    // pixel's ray meets the projector's image row, or outside that image
    if (is_valid(p)) {
        float z = val[p];
        float up = float(q.x) - fb / z;
        int lo = clamp(int(floor(up)), 0, size.x - 1);
        int hi = clamp(lo + 1, 0, size.x - 1);
        float near = z * (1.0 - a);
        float z_lo = texelFetch(proj_tex, ivec2(lo, q.y), 0).r;
        float z_hi = texelFetch(proj_tex, ivec2(hi, q.y), 0).r;
        bool occluded = z_lo > 0.0 && z_lo < near && z_hi > 0.0 && z_hi < near;
        if (occluded || up < 0.0 || up > float(size.x - 1)) remove_pixel(p, SHADOW);
    }
#elif EFFECT == BAND
    // registration: the border outside the IR camera's view
    if (q.x < band.x || q.x >= size.x - band.y || q.y < band.z || q.y >= size.y - band.w)
        remove_pixel(p, REGISTRATION);
#endif
}
