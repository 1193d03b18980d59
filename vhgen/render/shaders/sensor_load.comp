#version 430
// The frame's rendered textures into the state: planar depth (NaN, inf, <= 0 = no hit),
// the packed ids (stored as floats by the renderer) and the incidence.
layout(local_size_x = 8, local_size_y = 8) in;
#include "sensor.glsl"

uniform sampler2D depth_tex;   // .r planar depth (m)
uniform sampler2D ids_tex;     // .r packed ids as a float
uniform sampler2D inc_tex;     // incidence in component inc_component
uniform int inc_component;     // 0 or 1; -1: no incidence (1 everywhere)
uniform bool want_ids;

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    if (q.x >= size.x || q.y >= size.y) return;
    uint p = uint(q.y * size.x + q.x);
    float z = texelFetch(depth_tex, q, 0).r;
    bool hit = z > 0.0 && !isinf(z) && !isnan(z);
    val[p] = hit ? z : 0.0;
    flags[p] = hit ? VALID : cause_bit(NO_HIT);
    ids[p] = want_ids ? uint(texelFetch(ids_tex, q, 0).r) : 0u;
    inc[p] = inc_component < 0 ? 1.0 : texelFetch(inc_tex, q, 0)[inc_component];
}
