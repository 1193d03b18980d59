#version 430
// The effects that move pixels (EFFECT defined by the host); the whole state moves (value,
// validity and hole causes, ids, incidence). Reads the state (bindings 0-3), writes the
// spare set (4-7).
//   LATERAL: every pixel shows the pixel at (x, y) + sigma (N, N), nearest, clamped to
//            the image;
//   LENS:    every (distorted) pixel shows the ideal pixel its undistorted ray passes
//            through (source[p], from vhgen.sensor.stages.undistort_map); rays leaving
//            the image (NONE) become holes of cause DISTORTION with ids 0.
layout(local_size_x = 8, local_size_y = 8) in;
#include "sensor.glsl"

layout(std430, binding = 4) buffer Val2 { float val2[]; };
layout(std430, binding = 5) buffer Flags2 { uint flags2[]; };
layout(std430, binding = 6) buffer Ids2 { uint ids2[]; };
layout(std430, binding = 7) buffer Inc2 { float inc2[]; };

layout(std430, binding = 8) buffer Source { uint source[]; };

uniform uint stream;
uniform float sigma_px;
uniform bool nguyen;  // sigma grows at grazing angles (incidence at the pixel)

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    if (q.x >= size.x || q.y >= size.y) return;
    uint p = uint(q.y * size.x + q.x);
#if EFFECT == LATERAL
    float s = sigma_px;
    if (nguyen) {
        float th = min(acos(clamp(inc[p], 0.0, 1.0)), 1.4835298641951802);
        s = sigma_px / 0.8 * (0.8 + 0.035 * th / (1.5707963267948966 - th));
    }
    int x = clamp(int(floor(float(q.x) + s * draw_normal(stream, p, 0u) + 0.5)), 0, size.x - 1);
    int y = clamp(int(floor(float(q.y) + s * draw_normal(stream, p, 2u) + 0.5)), 0, size.y - 1);
    uint src = uint(y * size.x + x);
#else
    uint src = source[p];
    if (src == 0xFFFFFFFFu) {
        val2[p] = 0.0;
        flags2[p] = cause_bit(DISTORTION);
        ids2[p] = 0u;
        inc2[p] = inc[0];
        return;
    }
#endif
    val2[p] = val[src];
    flags2[p] = flags[src];
    ids2[p] = ids[src];
    inc2[p] = inc[src];
}
