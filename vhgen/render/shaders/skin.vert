#version 330 core
// Skinned vertices in camera space (OpenCV axes); the bones already include
// world_to_camera, so positions stay accurate far from the world origin.
#include "skinning.glsl"
uniform mat4 projection;

in vec3 in_position;
in ivec4 in_joints;
in vec4 in_weights;

out float v_depth;
out vec3 v_cam;

void main() {
    vec3 cam = skin_position(in_position, in_joints, in_weights);
    v_depth = cam.z;  // planar depth, perspective-correctly interpolated
    v_cam = cam;
    gl_Position = projection * vec4(cam, 1.0);
}
