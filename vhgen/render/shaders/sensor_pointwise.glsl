// The per-pixel steps of the GL sensor: each acts on one pixel's state held in locals
// (v: depth or disparity, f: flags, c: incidence) and the effect's parameters (a: up to
// 4 numbers, n: up to 4 integers, in the order of the host's pass). sensor_chain.comp
// runs a run of them in one program (vhgen/render/sensor_gl.py fuses them).

uniform vec4 intr;           // fx, fy, cx, cy
uniform sampler2D proj_tex;  // exact shadows: planar depth seen from the projector

const float DEG85 = 1.4835298641951802;

// a valid pixel becomes a hole of cause k
void drop(inout float v, inout uint f, uint k) {
    if ((f & VALID) != 0u) {
        f = (f & ~VALID) | cause_bit(k);
        v = 0.0;
    }
}

float grazing_angle(float c) {
    return min(acos(clamp(c, 0.0, 1.0)), DEG85);
}

// depth <-> disparity: v <- fb / v where valid
void pw_invert(inout float v, inout uint f, float c, ivec2 q, uint p, vec4 a, ivec4 n,
               uint stream) {
    v = (f & VALID) != 0u ? fb / v : 0.0;
}

// a = (z_min, z_max) (depth)
void pw_range_gate(inout float v, inout uint f, float c, ivec2 q, uint p, vec4 a, ivec4 n,
                   uint stream) {
    if ((f & VALID) != 0u && (v < a.x || v > a.y)) drop(v, f, RANGE);
}

// a = (z_start, z_end, power), n.x = blob_px (depth): one uniform per blob cell, compared
// with each pixel's own probability
void pw_range_dropout(inout float v, inout uint f, float c, ivec2 q, uint p, vec4 a,
                      ivec4 n, uint stream) {
    if ((f & VALID) == 0u) return;
    uint cols = uint((size.x + n.x - 1) / n.x);
    uint cell = uint(q.y / n.x) * cols + uint(q.x / n.x);
    float frac = clamp((v - a.x) / (a.y - a.x), 0.0, 1.0);
    if (draw_uniform(stream, cell, 0u) < pow(frac, a.z)) drop(v, f, RANGE);
}

// n.x model: 0 disparity (a.x = sigma_px, disparity), 1 khoshelham, 2 nguyen (a.y = 1:
// angle term), 3 barron_malik (depth); a pixel pushed to <= 0 is lost (cause NOISE)
void pw_axial_noise(inout float v, inout uint f, float c, ivec2 q, uint p, vec4 a, ivec4 n,
                    uint stream) {
    if ((f & VALID) == 0u) return;
    float g = draw_normal(stream, p, 0u);
    if (n.x == 0) {
        v += a.x * g;
    } else if (n.x == 3) {
        float z_cm = floor(v * 100.0 + 0.5);
        float dq = floor(35130.0 / max(z_cm, 1.0) + g / 6.0 + 0.5);
        v = dq > 0.0 ? 35130.0 / dq / 100.0 : 0.0;
    } else {
        float sigma;
        if (n.x == 1) {
            sigma = 1.425e-3 * v * v;
        } else {
            sigma = 0.0012 + 0.0019 * (v - 0.4) * (v - 0.4);
            float th = grazing_angle(c);
            if (a.y > 0.5 && th > 1.0471975511965976) {
                float rest = 1.5707963267948966 - th;
                sigma += 1e-4 / sqrt(max(v, 1e-6)) * th * th / (rest * rest);
            }
        }
        v += sigma * g;
    }
    if (v <= 0.0) drop(v, f, NOISE);
}

// a = (cos_min, r_max (m; negative: no range rule)) (depth)
void pw_dropout(inout float v, inout uint f, float c, ivec2 q, uint p, vec4 a, ivec4 n,
                uint stream) {
    if ((f & VALID) == 0u) return;
    vec2 xy = (vec2(q) - intr.zw) / intr.xy;
    float r = v * sqrt(dot(xy, xy) + 1.0);
    if (c < a.x || (a.y >= 0.0 && r > a.y)) drop(v, f, DROPOUT);
}

// a.x = step_px (disparity), rounded half up; a pixel quantised to <= 0 is lost
void pw_quantise(inout float v, inout uint f, float c, ivec2 q, uint p, vec4 a, ivec4 n,
                 uint stream) {
    if ((f & VALID) == 0u) return;
    float dq = floor(v / a.x + 0.5) * a.x;
    if (dq <= 0.0) drop(v, f, NOISE); else v = dq;
}

// registration: n = (left, right, top, bottom) px of border outside the IR camera's view
void pw_band(inout float v, inout uint f, float c, ivec2 q, uint p, vec4 a, ivec4 n,
             uint stream) {
    if (q.x < n.x || q.x >= size.x - n.y || q.y < n.z || q.y >= size.y - n.w)
        drop(v, f, REGISTRATION);
}

// a.x = tolerance (depth): shadowed when the projector sees a surface nearer than the
// pixel's own by more than the tolerance at both columns around where the pixel's ray
// meets the projector's image row, or when that lies outside the projector's image
void pw_exact_shadow(inout float v, inout uint f, float c, ivec2 q, uint p, vec4 a,
                     ivec4 n, uint stream) {
    if ((f & VALID) == 0u) return;
    float up = float(q.x) - fb / v;
    int lo = clamp(int(floor(up)), 0, size.x - 1);
    int hi = clamp(lo + 1, 0, size.x - 1);
    float near = v * (1.0 - a.x);
    float z_lo = texelFetch(proj_tex, ivec2(lo, q.y), 0).r;
    float z_hi = texelFetch(proj_tex, ivec2(hi, q.y), 0).r;
    bool occluded = z_lo > 0.0 && z_lo < near && z_hi > 0.0 && z_hi < near;
    if (occluded || up < 0.0 || up > float(size.x - 1)) drop(v, f, SHADOW);
}
