#version 430
// The dot-gated correlation window (disparity domain), after
// vhgen.sensor.sensor_kernels.correlation_window. Steps (STEP defined by the host):
//   DOTS:    dotval[p] = d where a projector dot lands on valid pixel p (pattern[y,
//            round(x - d) + pad]), -1 elsewhere; the dots at least HALF px from the border are listed as candidates;
//            the splat keys are cleared;
//   ARGS:    the work groups of the next list pass (indirect dispatch: the GPU never
//            waits for the host);
//   ACCEPT:  a candidate is accepted when the dots of its (2 HALF + 1)^2 window, all
//            valid, have more than frac x their count inliers |d - mean| w(i, j) <
//            inlier_px, w = 1 / ((1.2 i)^2 + (1.2 j)^2), w(0, 0) = 1; accepted dots are
//            listed;
//   SCATTER: every accepted dot offers the pixels within SPLAT_R2 px^2 the key
//            (255 - r^2) << 24 | (2^24 - 1 - its pixel index) (atomicMax): the largest
//            weight 1 / (1 + r^2) wins, on a tie the dot first in raster order;
//   SPLAT:   every pixel takes the disparity of its key's dot, and that dot's ids and
//            incidence (what the pixel now measures is that dot's surface); pixels no
//            accepted dot reaches become holes (cause WINDOW) and keep their own.
// Lists keep the costly window test to the dots (about a fifth of the pixels): the list
// order varies from run to run, what is computed for each entry does not.
#if STEP == DOTS || STEP == SPLAT
layout(local_size_x = 8, local_size_y = 8) in;
#else
layout(local_size_x = 64) in;
#endif
#include "sensor.glsl"

layout(std430, binding = 4) buffer Val2 { float val2[]; };
layout(std430, binding = 6) buffer Ids2 { uint ids2[]; };
layout(std430, binding = 7) buffer Inc2 { float inc2[]; };
layout(std430, binding = 8) buffer DotVal { float dotval[]; };  // d on a dot, -1 elsewhere
layout(std430, binding = 9) buffer Candidates { uint cand[]; };
layout(std430, binding = 10) buffer Pattern { uint pattern[]; };  // (H, PW) 0/1
layout(std430, binding = 11) buffer Accepted { uint acc[]; };
layout(std430, binding = 12) buffer Keys { uint keys[]; };
// indirect dispatch arguments of ACCEPT (0-2) and SCATTER (3-5), then the list lengths
layout(std430, binding = 13) buffer Counts { uint args[6]; uint n_cand; uint n_acc; };

uniform int pattern_width;
uniform int pad;
uniform float frac;
uniform float inlier_px;
uniform int which;  // ARGS: 0 candidates, 1 accepted

void main() {
#if STEP == DOTS
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    if (q.x >= size.x || q.y >= size.y) return;
    uint p = uint(q.y * size.x + q.x);
    uint m = 0u;
    if (is_valid(p)) {
        int up = int(floor(float(q.x) - val[p] + 0.5)) + pad;
        if (up >= 0 && up < pattern_width) m = pattern[q.y * pattern_width + up];
    }
    dotval[p] = m != 0u ? val[p] : -1.0;
    keys[p] = 0u;
    if (m != 0u && q.x >= HALF && q.x < size.x - HALF && q.y >= HALF && q.y < size.y - HALF)
        cand[atomicAdd(n_cand, 1u)] = p;
#elif STEP == ARGS
    if (gl_GlobalInvocationID.x != 0u) return;
    uint n = which == 0 ? n_cand : n_acc;
    args[3 * which] = (n + 63u) / 64u;
    args[3 * which + 1] = 1u;
    args[3 * which + 2] = 1u;
#elif STEP == ACCEPT
    uint i = gl_GlobalInvocationID.x;
    if (i >= n_cand) return;
    int p = int(cand[i]);
    // the window's dots' disparities (-1 off the dots), read once
    float win[(2 * HALF + 1) * (2 * HALF + 1)];
    float n = 0.0;
    float sum = 0.0;
    for (int j = -HALF; j <= HALF; ++j) {
        for (int k = -HALF; k <= HALF; ++k) {
            float v = dotval[uint(p + j * size.x + k)];
            win[(j + HALF) * (2 * HALF + 1) + k + HALF] = v;
            float dot_here = v >= 0.0 ? 1.0 : 0.0;
            n += dot_here;
            sum += dot_here * v;
        }
    }
    float mean = sum / n;
    float inl = 0.0;
    for (int j = -HALF; j <= HALF; ++j) {
        for (int k = -HALF; k <= HALF; ++k) {
            float v = win[(j + HALF) * (2 * HALF + 1) + k + HALF];
            float w = (j == 0 && k == 0) ? 1.0 : 1.44 * float(j * j + k * k);
            inl += (v >= 0.0 && abs(v - mean) < inlier_px * w) ? 1.0 : 0.0;
        }
    }
    if (inl > frac * n) acc[atomicAdd(n_acc, 1u)] = uint(p);
#elif STEP == SCATTER
    uint i = gl_GlobalInvocationID.x;
    if (i >= n_acc) return;
    uint p = acc[i];
    int x = int(p) % size.x;
    int y = int(p) / size.x;
    uint rank = 0xFFFFFFu - p;
    for (int j = -SPLAT_R; j <= SPLAT_R; ++j) {
        for (int k = -SPLAT_R; k <= SPLAT_R; ++k) {
            int r2 = j * j + k * k;
            if (float(r2) > SPLAT_R2 || x + k < 0 || x + k >= size.x || y + j < 0
                    || y + j >= size.y) continue;
            atomicMax(keys[uint((y + j) * size.x + x + k)], (uint(255 - r2) << 24) | rank);
        }
    }
#elif STEP == SPLAT
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    if (q.x >= size.x || q.y >= size.y) return;
    uint p = uint(q.y * size.x + q.x);
    uint k = keys[p];
    uint src = k != 0u ? 0xFFFFFFu - (k & 0xFFFFFFu) : p;
    ids2[p] = ids[src];
    inc2[p] = inc[src];
    if (k != 0u) {
        val2[p] = val[src];
        flags[p] |= VALID;
    } else {
        val2[p] = 0.0;
        if (is_valid(p)) flags[p] = (flags[p] & ~VALID) | cause_bit(WINDOW);
    }
#endif
}
