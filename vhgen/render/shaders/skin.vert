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
// in_position is the garment's vertex, in_offset.xyz how far it lies out from the skin
// under it (rest pose), in_offset.w its contact bits (1, 2: the left, right hand may
// press it; 4: the legs push it out). Near a hand's palm the garment is pressed towards
// the skin, no further than the hand's underside: a hand resting on a coat lies on it,
// not inside it. A hand is a swept ellipse: the segment press_a -> press_b (camera
// space), half thickness press_a.w across the palm and press_b.w times that across its
// width (press_lateral); press_reach bounds, for a cheap first test, where it can press
// (centre, radius). A leg bone is a tapered capsule push_a -> push_b of radius push_a.w
// at a, push_b.w at b: cloth inside it is moved out to its surface (plus CLOTH_MARGIN),
// unless a hand presses it. Only vertices near a hand pay for more than the skinning.
in vec4 in_offset;
uniform vec4 press_a[2];
uniform vec4 press_b[2];
uniform vec3 press_lateral[2];
uniform vec4 press_reach[2];
uniform vec4 push_a[4];
uniform vec4 push_b[4];

float hand_distance(vec3 p, int k) {
    vec3 a = press_a[k].xyz;
    vec3 ab = press_b[k].xyz - a;
    float s = clamp(dot(p - a, ab) / max(dot(ab, ab), 1e-12), 0.0, 1.0);
    vec3 q = p - (a + s * ab);
    float across = dot(q, press_lateral[k]);
    vec3 normal = q - across * press_lateral[k];
    return sqrt(dot(normal, normal) + across * across / (press_b[k].w * press_b[k].w));
}

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
#endif

out float v_depth;
out vec3 v_cam;

void main() {
    vec3 cam = skin_position(in_position, in_joints, in_weights);
#ifdef GARMENTS
    // The branches are written as loops that run at most once: llvmpipe runs both sides
    // of an if for a group of vertices, but leaves a loop as soon as no vertex of the
    // group is in it, so vertices far from the hands and off the loose cloth (nearly all)
    // pay only for these tests.
    int bits = int(in_offset.w + 0.5);
    float scale = 1.0;
    float t = length(in_offset.xyz);
    bool near = false;
    for (int k = 0; k < 2; ++k) {
        // the skin under it is within 2t of it (|skin_vector(d)| <= |d|): a hand further
        // than its reach + 2t cannot press it
        vec3 c = cam - press_reach[k].xyz;
        float reach = press_reach[k].w + 2.0 * t;
        near = near || (t > 0.0 && (bits & (1 << k)) != 0 && dot(c, c) < reach * reach);
    }
    for (int once = near ? 0 : 1; once < 1; ++once) {
        vec3 off = skin_vector(in_offset.xyz, in_joints, in_weights);
        vec3 skin = cam - off;
        for (int k = 0; k < 2; ++k) {
            if ((bits & (1 << k)) != 0) {
                scale = min(scale, clamp((hand_distance(skin, k) - press_a[k].w) / t,
                                         0.0, 1.0));
            }
        }
        cam = skin + scale * off;
    }
    // a hand pressing the cloth keeps it in
    for (int once = (bits & 4) != 0 && scale >= 1.0 ? 0 : 1; once < 1; ++once) {
        for (int k = 0; k < 4; ++k) {
            cam = push_out(cam, k);
        }
    }
#endif
    v_depth = cam.z;  // planar depth, perspective-correctly interpolated
    v_cam = cam;
    gl_Position = projection * vec4(cam, 1.0);
}
