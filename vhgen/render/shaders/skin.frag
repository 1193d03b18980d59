#version 330 core
// One RG32F target: r = planar depth in metres, g = the triangle's part label.
// The label comes from a per-triangle texture indexed by gl_PrimitiveID, so it is never
// interpolated or blended across a part boundary. Clear value (0, 0) = no hit.
uniform usampler2D face_labels;  // R8UI, row-major, LABEL_TEX_WIDTH triangles per row

in float v_depth;
in vec3 v_cam;
layout(location = 0) out vec2 out_depth_label;
#ifdef WANT_NORMALS
// flat face normal in the camera frame, turned to face the camera
layout(location = 1) out vec4 out_normal;
#endif

void main() {
    int id = gl_PrimitiveID;
    uint label = texelFetch(face_labels, ivec2(id % LABEL_TEX_WIDTH, id / LABEL_TEX_WIDTH), 0).r;
    out_depth_label = vec2(v_depth, float(label));
#ifdef WANT_NORMALS
    vec3 n = normalize(cross(dFdx(v_cam), dFdy(v_cam)));
    out_normal = vec4(dot(n, v_cam) > 0.0 ? -n : n, 0.0);
#endif
}
