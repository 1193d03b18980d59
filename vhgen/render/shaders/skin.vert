#version 330 core
// Linear blend skinning with a fixed number (4) of influences per vertex.
// bones[b] = world_to_camera * M_b, composed on the CPU in float64 and rounded once to
// float32, so camera-space positions stay accurate far from the world origin.
uniform mat4 bones[MAX_BONES];
uniform mat4 projection;

in vec3 in_position;
in ivec4 in_joints;
in vec4 in_weights;

out float v_depth;

void main() {
    vec4 p = vec4(in_position, 1.0);
    vec4 cam = in_weights.x * (bones[in_joints.x] * p)
             + in_weights.y * (bones[in_joints.y] * p)
             + in_weights.z * (bones[in_joints.z] * p)
             + in_weights.w * (bones[in_joints.w] * p);
    v_depth = cam.z;  // planar depth, perspective-correctly interpolated
    gl_Position = projection * vec4(cam.xyz, 1.0);
}
