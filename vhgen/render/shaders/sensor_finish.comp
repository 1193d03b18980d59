#version 430
// The outputs in one pass: uint16 mm (rounded half up; 0 = none, > 65.535 m invalid) in
// the low half of out[p], the 11-bit raw value round(d_off - 8 d) (2047 = invalid or
// outside 0..2046) in the high half, and the disparity (0 where invalid) in val2.
layout(local_size_x = 8, local_size_y = 8) in;
#include "sensor.glsl"

layout(std430, binding = 4) buffer Val2 { float val2[]; };
layout(std430, binding = 12) buffer Out { uint outv[]; };

uniform bool is_disparity;
uniform float d_off;

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    if (q.x >= size.x || q.y >= size.y) return;
    uint p = uint(q.y * size.x + q.x);
    uint mm = 0u;
    uint raw = 2047u;
    float disp = 0.0;
    if (is_valid(p)) {
        float v = val[p];
        float z = is_disparity ? fb / v : v;
        float m = floor(z * 1000.0 + 0.5);
        if (m >= 1.0 && m <= 65535.0) {
            mm = uint(m);
            disp = is_disparity ? v : fb / v;
            float k = floor(d_off - 8.0 * disp + 0.5);
            if (k >= 0.0 && k <= 2046.0) raw = uint(k);
        }
    }
    outv[p] = mm | (raw << 16);
    val2[p] = disp;
}
