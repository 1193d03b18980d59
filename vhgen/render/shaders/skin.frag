#version 330 core
// One RGBA32F target: r = planar depth in metres, g = the triangle's part label,
// b = the person instance (0 = none), a = the scene class. Clear value 0 = no hit.
// Labels come from a per-triangle texture indexed by gl_PrimitiveID, so they are never
// interpolated or blended across a part boundary. For a person the texel is the body
// part and the class is the uniform draw_class; for static geometry
// (labels_are_classes = 1) the texel is the triangle's scene class and the part is 0.
uniform usampler2D face_labels;  // R8UI, row-major, LABEL_TEX_WIDTH triangles per row
uniform int labels_are_classes;
uniform float instance_id;
uniform float draw_class;

in float v_depth;
in vec3 v_cam;
layout(location = 0) out vec4 out_depth_label;
#ifdef WANT_NORMALS
// flat face normal in the camera frame, turned to face the camera
layout(location = 1) out vec4 out_normal;
#endif

void main() {
    int id = gl_PrimitiveID;
    float t = float(texelFetch(face_labels, ivec2(id % LABEL_TEX_WIDTH, id / LABEL_TEX_WIDTH),
                               0).r);
    if (labels_are_classes != 0) {
        out_depth_label = vec4(v_depth, 0.0, 0.0, t);
    } else {
        out_depth_label = vec4(v_depth, t, instance_id, draw_class);
    }
#ifdef WANT_NORMALS
    vec3 n = normalize(cross(dFdx(v_cam), dFdy(v_cam)));
    out_normal = vec4(dot(n, v_cam) > 0.0 ? -n : n, 0.0);
#endif
}
