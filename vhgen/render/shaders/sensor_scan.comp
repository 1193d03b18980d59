#version 430
// Occlusion bands along rows (disparity domain), one invocation per row: with the other
// viewpoint at +x (right), a pixel is hidden iff some pixel to its right has a smaller
// u - s d (a nearer surface blocks the line of sight), a reverse running minimum; at -x,
// the mirror image. The projector's shadow (s = 1, cause SHADOW) and the IR camera's
// occlusion in a registered image (s = |offset| / baseline, cause REGISTRATION).
layout(local_size_x = 32) in;
#include "sensor.glsl"

uniform float scale;
uniform bool right;
uniform uint cause;

void main() {
    int y = int(gl_GlobalInvocationID.x);
    if (y >= size.y) return;
    uint row = uint(y * size.x);
    if (right) {
        float run = 1.0 / 0.0;
        for (int x = size.x - 1; x >= 0; --x) {
            uint p = row + uint(x);
            if (!is_valid(p)) continue;
            float up = float(x) - scale * val[p];
            if (up > run) remove_pixel(p, cause); else run = up;
        }
    } else {
        float run = -1.0 / 0.0;
        for (int x = 0; x < size.x; ++x) {
            uint p = row + uint(x);
            if (!is_valid(p)) continue;
            float up = float(x) + scale * val[p];
            if (up < run) remove_pixel(p, cause); else run = up;
        }
    }
}
