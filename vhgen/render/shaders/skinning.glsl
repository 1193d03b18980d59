// Skinning with exactly 4 influences per vertex, shared by the render and the
// transform-feedback programs so what we measure is what we draw.
// LBS: bones[b] is a rigid 4x4 (composed on the CPU in float64, rounded once to float32).
// DQS (Kavan et al. 2008): dq_real[b], dq_dual[b] are the bone's unit dual quaternion
// (x, y, z, w), blended with signs aligned to the first influence, then normalised.
#ifdef SKINNING_DQS
uniform vec4 dq_real[MAX_BONES];
uniform vec4 dq_dual[MAX_BONES];

vec3 skin_position(vec3 p, ivec4 j, vec4 w) {
    vec4 r0 = dq_real[j.x];
    vec4 br = w.x * r0;
    vec4 bd = w.x * dq_dual[j.x];
    for (int k = 1; k < 4; ++k) {
        float s = dot(dq_real[j[k]], r0) < 0.0 ? -w[k] : w[k];
        br += s * dq_real[j[k]];
        bd += s * dq_dual[j[k]];
    }
    float n = length(br);
    br /= n;
    bd /= n;
    vec3 t = 2.0 * (br.w * bd.xyz - bd.w * br.xyz + cross(br.xyz, bd.xyz));
    return p + 2.0 * cross(br.xyz, cross(br.xyz, p) + br.w * p) + t;
}

// A vector at a vertex turned by the vertex's blended rotation (DQS is affine per vertex:
// skin_position(p + d) = skin_position(p) + skin_vector(d)).
vec3 skin_vector(vec3 d, ivec4 j, vec4 w) {
    vec4 r0 = dq_real[j.x];
    vec4 br = w.x * r0;
    for (int k = 1; k < 4; ++k) {
        br += (dot(dq_real[j[k]], r0) < 0.0 ? -w[k] : w[k]) * dq_real[j[k]];
    }
    br /= length(br);
    return d + 2.0 * cross(br.xyz, cross(br.xyz, d) + br.w * d);
}
#else
uniform mat4 bones[MAX_BONES];

vec3 skin_position(vec3 p, ivec4 j, vec4 w) {
    vec4 h = vec4(p, 1.0);
    vec4 s = w.x * (bones[j.x] * h) + w.y * (bones[j.y] * h)
           + w.z * (bones[j.z] * h) + w.w * (bones[j.w] * h);
    return s.xyz;
}

// A vector at a vertex turned by the blended bone matrices (linear blend skinning is
// linear: skin_position(p + d) = skin_position(p) + skin_vector(d)).
vec3 skin_vector(vec3 d, ivec4 j, vec4 w) {
    return w.x * (mat3(bones[j.x]) * d) + w.y * (mat3(bones[j.y]) * d)
         + w.z * (mat3(bones[j.z]) * d) + w.w * (mat3(bones[j.w]) * d);
}
#endif
