#version 330 core
// Skinned vertices in camera space (OpenCV axes); the bones already include
// world_to_camera, so positions stay accurate far from the world origin.
#include "skinning.glsl"
uniform mat4 projection;

in vec3 in_position;
in ivec4 in_joints;
in vec4 in_weights;
#ifdef GARMENTS
// A dressed body (vhgen.body.contact, whose dressed_positions computes the same):
// in_position is the skin, in_offset.xyz how far the garment over it lies out (rest
// pose), in_offset.w its contact bits (1, 2: the left, right hand may press it; 4: the
// legs push it out). Near a hand's palm the garment is pressed towards the skin, no
// further than the hand's underside: a hand resting on a coat lies on it, not inside it.
// A hand is a swept ellipse: the segment press_a -> press_b (camera space), half
// thickness press_a.w across the palm and press_b.w times that across its width
// (press_lateral). A leg bone is a tapered capsule push_a -> push_b of radius push_a.w
// at a, push_b.w at b: cloth inside it is moved out to its surface (plus CLOTH_MARGIN),
// unless a hand presses it.
in vec4 in_offset;
uniform vec4 press_a[2];
uniform vec4 press_b[2];
uniform vec3 press_lateral[2];
uniform vec4 push_a[4];
uniform vec4 push_b[4];

vec3 push_out(vec3 p, int k) {
    vec3 a = push_a[k].xyz;
    vec3 ab = push_b[k].xyz - a;
    float s = clamp(dot(p - a, ab) / max(dot(ab, ab), 1e-12), 0.0, 1.0);
    vec3 c = a + s * ab;
    vec3 q = p - c;
    float d = length(q);
    float r = mix(push_a[k].w, push_b[k].w, s) + CLOTH_MARGIN;
    return d < r ? c + q * (r / max(d, 1e-6)) : p;
}

float hand_distance(vec3 p, int k) {
    vec3 a = press_a[k].xyz;
    vec3 ab = press_b[k].xyz - a;
    float s = clamp(dot(p - a, ab) / max(dot(ab, ab), 1e-12), 0.0, 1.0);
    vec3 q = p - (a + s * ab);
    float across = dot(q, press_lateral[k]);
    vec3 normal = q - across * press_lateral[k];
    return sqrt(dot(normal, normal) + across * across / (press_b[k].w * press_b[k].w));
}
#endif

out float v_depth;
out vec3 v_cam;

void main() {
#ifdef GARMENTS
    vec3 cam;
    vec3 off;
    skin_offset(in_position, in_offset.xyz, in_joints, in_weights, cam, off);
    float t = length(in_offset.xyz);
    int bits = int(in_offset.w + 0.5);
    float s = 1.0;
    if (t > 0.0) {
        for (int k = 0; k < 2; ++k) {
            if ((bits & (1 << k)) != 0) {
                s = min(s, clamp((hand_distance(cam, k) - press_a[k].w) / t, 0.0, 1.0));
            }
        }
        cam += s * off;
    }
    if ((bits & 4) != 0 && s >= 1.0) {  // a hand pressing the cloth keeps it in
        for (int k = 0; k < 4; ++k) {
            cam = push_out(cam, k);
        }
    }
#else
    vec3 cam = skin_position(in_position, in_joints, in_weights);
#endif
    v_depth = cam.z;  // planar depth, perspective-correctly interpolated
    v_cam = cam;
    gl_Position = projection * vec4(cam, 1.0);
}
