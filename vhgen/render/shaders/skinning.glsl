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

// A point and a vector at it skinned alike: the vector turns with the blended rotation
// (DQS is affine per vertex, so pos + dir is where p + d would be skinned to).
void skin_offset(vec3 p, vec3 d, ivec4 j, vec4 w, out vec3 pos, out vec3 dir) {
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
    pos = p + 2.0 * cross(br.xyz, cross(br.xyz, p) + br.w * p) + t;
    dir = d + 2.0 * cross(br.xyz, cross(br.xyz, d) + br.w * d);
}
#else
uniform mat4 bones[MAX_BONES];

vec3 skin_position(vec3 p, ivec4 j, vec4 w) {
    vec4 h = vec4(p, 1.0);
    vec4 s = w.x * (bones[j.x] * h) + w.y * (bones[j.y] * h)
           + w.z * (bones[j.z] * h) + w.w * (bones[j.w] * h);
    return s.xyz;
}

// A point and a vector at it skinned alike (pos + dir is where p + d is skinned to).
void skin_offset(vec3 p, vec3 d, ivec4 j, vec4 w, out vec3 pos, out vec3 dir) {
    mat4 m = w.x * bones[j.x] + w.y * bones[j.y] + w.z * bones[j.z] + w.w * bones[j.w];
    pos = (m * vec4(p, 1.0)).xyz;
    dir = mat3(m) * d;
}
#endif
