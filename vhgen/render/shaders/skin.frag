#version 330 core
// Two targets. 0: r = planar depth in metres (R32F; RG32F with the incidence, |cos| of
// the angle between surface and viewing ray, in g when WANT_INCIDENCE). 1: the pixel's ids packed as part label | instance << 8 |
// scene class << 16, stored as a float (R32F; exact, as it is < 2^24). Clear value 0 =
// no hit. Labels come from a per-triangle texture indexed by gl_PrimitiveID (+ the
// draw's first triangle: a mesh may be drawn in runs with different culling), so they are
// never interpolated or blended across a part boundary. For a person the texel's r is the
// body part and its g the triangle's scene class, 0 for the draw's (the uniform
// draw_class); a triangle of its own class and no part (a carried thing that is not the
// person) has no instance either. For static geometry (labels_are_classes = 1) r is the
// triangle's scene class and the part is 0.
// One packed channel instead of three float channels: fewer bytes written per fragment
// and read back per frame, and no packing on the CPU.
uniform usampler2D face_labels;  // RG8UI, row-major, LABEL_TEX_WIDTH triangles per row
uniform int labels_are_classes;
uniform uint instance_id;
uniform uint draw_class;
uniform int prim_offset;  // first triangle of this draw call in the label texture
#ifdef BACKGROUND_DEPTH
// A real depth frame the people are composited into (R32F planar metres, 0 = no
// measurement; texel (u, v) is image pixel (u, v)): a fragment at or behind the real
// surface of its pixel is discarded, so a nearer real surface hides a person exactly. The
// test compares the same float32 planar depth this shader writes to target 0, not a
// window-space depth buffer value (24-bit, non-linear in z).
uniform sampler2D background_depth;
#endif

in float v_depth;
in vec3 v_cam;
layout(location = 0) out vec4 out_depth_incidence;
layout(location = 1) out float out_ids;

void main() {
#ifdef BACKGROUND_DEPTH
    float real = texelFetch(background_depth, ivec2(gl_FragCoord.xy), 0).r;
    if (real > 0.0 && v_depth >= real) discard;
#endif
    int id = gl_PrimitiveID + prim_offset;
    uvec2 t = texelFetch(face_labels, ivec2(id % LABEL_TEX_WIDTH, id / LABEL_TEX_WIDTH), 0).rg;
    uint ids;
    if (labels_are_classes != 0) {
        ids = t.r << 16u;
    } else {
        uint cls = t.g != 0u ? t.g : draw_class;
        uint instance = (t.g != 0u && t.r == 0u) ? 0u : instance_id;
        ids = t.r | (instance << 8u) | (cls << 16u);
    }
    out_ids = float(ids);
#ifdef WANT_INCIDENCE
    // |cos| of the angle between the flat face normal and this pixel's viewing ray (v_cam
    // at the fragment centre lies on the ray through the pixel centre)
    vec3 n = normalize(cross(dFdx(v_cam), dFdy(v_cam)));
    out_depth_incidence = vec4(v_depth, abs(dot(n, normalize(v_cam))), 0.0, 0.0);
#else
    out_depth_incidence = vec4(v_depth, 0.0, 0.0, 0.0);
#endif
}
