#version 330 core
// Transform feedback: the skinned position of every vertex, read back to measure the
// GPU path against the float64 NumPy reference.
#include "skinning.glsl"

in vec3 in_position;
in ivec4 in_joints;
in vec4 in_weights;

out vec3 out_position;

void main() {
    out_position = skin_position(in_position, in_joints, in_weights);
}
