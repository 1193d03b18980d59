#version 430
// A run of per-pixel steps (sensor_pointwise.glsl) in one program: the host defines
// STEPS (the calls, in order, each with its parameters prm[i], iprm[i] and its random
// stream), NSTEPS, LOAD (the run starts from the frame's textures) and FINISH (the run
// ends in the outputs, FINISH_DISPARITY: the state holds disparity then).
layout(local_size_x = 8, local_size_y = 8) in;
#include "sensor.glsl"
#include "sensor_pointwise.glsl"

layout(std430, binding = 4) buffer Val2 { float val2[]; };
layout(std430, binding = 12) buffer Out { uint outv[]; };

uniform vec4 prm[NSTEPS];
uniform ivec4 iprm[NSTEPS];
// LOAD: the rendered frame
uniform sampler2D depth_tex;   // .r planar depth (m); NaN, inf, <= 0 = no hit
uniform sampler2D ids_tex;     // .r packed ids as a float (exact below 2^24)
uniform sampler2D inc_tex;     // the incidence in component inc_component
uniform int inc_component;     // 0 or 1 (the renderer's RG target); -1: none (1)
uniform bool want_ids;
uniform uvec4 glass_a;         // the scene classes with no return (window glass), as bits:
uniform uvec4 glass_b;         // classes 0-127 in glass_a, 128-255 in glass_b

bool no_return(uint cls) {
    uvec4 w = cls < 128u ? glass_a : glass_b;
    uint i = (cls >> 5) & 3u;
    uint word = i == 0u ? w.x : (i == 1u ? w.y : (i == 2u ? w.z : w.w));
    return ((word >> (cls & 31u)) & 1u) != 0u;
}
// FINISH: the output encoding
uniform float d_off;

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    if (q.x >= size.x || q.y >= size.y) return;
    uint p = uint(q.y * size.x + q.x);
    float v;
    uint f;
    float c;
#if LOAD
    float z = texelFetch(depth_tex, q, 0).r;
    uint id = want_ids ? uint(texelFetch(ids_tex, q, 0).r) : 0u;
    // glass: as if nothing were hit there (the ids keep the glass)
    bool hit = z > 0.0 && !isinf(z) && !isnan(z) && !no_return((id >> 16) & 0xFFu);
    v = hit ? z : 0.0;
    f = hit ? VALID : cause_bit(NO_HIT);
    c = inc_component < 0 ? 1.0 : texelFetch(inc_tex, q, 0)[inc_component];
    ids[p] = id;
    inc[p] = c;
#else
    v = val[p];
    f = flags[p];
    c = inc[p];
#endif
    STEPS
    flags[p] = f;
#if FINISH
    // uint16 mm (rounded half up; 0 = none, > 65.535 m invalid) in the low half of
    // outv[p], the 11-bit raw value round(d_off - 8 d) (2047 = invalid or outside
    // 0..2046) in the high half, the disparity (0 where invalid) in val2
    uint mm = 0u;
    uint raw = 2047u;
    float disp = 0.0;
    if ((f & VALID) != 0u) {
        float zf = FINISH_DISPARITY ? fb / v : v;
        float m = floor(zf * 1000.0 + 0.5);
        if (m >= 1.0 && m <= 65535.0) {
            mm = uint(m);
            disp = FINISH_DISPARITY ? v : fb / v;
            float k = floor(d_off - 8.0 * disp + 0.5);
            if (k >= 0.0 && k <= 2046.0) raw = uint(k);
        }
    }
    outv[p] = mm | (raw << 16);
    val2[p] = disp;
#else
    val[p] = v;
#endif
}
