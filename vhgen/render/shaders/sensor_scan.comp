#version 430
// Occlusion bands along rows (disparity domain): with the other viewpoint at +x (right),
// a pixel is hidden iff some pixel to its right has a smaller u - s d (a nearer surface
// blocks the line of sight), a reverse running minimum; at -x, the mirror image. The
// projector's shadow (s = 1, cause SHADOW) and the IR camera's occlusion in a registered
// image (s = |offset| / baseline, cause REGISTRATION). row_scan.glsl: where a row has
// several invocations, each takes the minimum (maximum) over its stretch, the row's
// invocations combine them, and each walks its stretch from the pixels beyond it.
#include "sensor.glsl"
#include "row_scan.glsl"
layout(local_size_x = ROW_LOCAL) in;

uniform float scale;
uniform bool right;
uniform uint cause;

void main() {
    int y = row_y();
    if (y >= size.y) return;  // a whole group where rows have several invocations
    uint row = uint(y * size.x);
    int x0 = row_x0(), x1 = row_x1();
    if (right) {
        float run = 1.0 / 0.0;
#if ROW_THREADS > 1
        for (int x = x0; x < x1; ++x) {
            uint p = row + uint(x);
            if (is_valid(p)) run = min(run, float(x) - scale * val[p]);
        }
#endif
        run = row_exclusive(run, true, false, 1.0 / 0.0);
        for (int x = x1 - 1; x >= x0; --x) {
            uint p = row + uint(x);
            if (!is_valid(p)) continue;
            float up = float(x) - scale * val[p];
            if (up > run) remove_pixel(p, cause); else run = up;
        }
    } else {
        float run = -1.0 / 0.0;
#if ROW_THREADS > 1
        for (int x = x0; x < x1; ++x) {
            uint p = row + uint(x);
            if (is_valid(p)) run = max(run, float(x) + scale * val[p]);
        }
#endif
        run = row_exclusive(run, false, true, -1.0 / 0.0);
        for (int x = x0; x < x1; ++x) {
            uint p = row + uint(x);
            if (!is_valid(p)) continue;
            float up = float(x) + scale * val[p];
            if (up < run) remove_pixel(p, cause); else run = up;
        }
    }
}
