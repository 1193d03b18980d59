#version 430
// The speckle filter: 4-connected components of valid pixels by union-find with atomics
// (Playne & Hawick, "A new algorithm for parallel connected-component labelling on
// GPUs", IEEE TPDS 2018: the "union find" variant; a fixed number of passes, no
// iteration), then each component's area; components of at most max_area pixels become
// holes (cause SPECKLE). STEP defined by the host:
//   ROWS:     one invocation per row: label[p] = the first pixel of p's run of valid
//             pixels in the row, NONE on invalid pixels (the rows' unions, for free);
//   MERGE:    a valid pixel with a valid pixel above joins the two trees, unless its left
//             neighbour and the one above that are valid too (the same two runs are then
//             already joined there): the larger root is pointed at the smaller one
//             (atomicMin, retried until it holds), so every tree's root is its
//             component's smallest pixel;
//   COUNT:    every label replaced by its root, and area[root] += 1;
//   REMOVE:   pixels of small components become holes.
#if STEP == ROWS
layout(local_size_x = 32) in;
#else
layout(local_size_x = 8, local_size_y = 8) in;
#endif
#include "sensor.glsl"

layout(std430, binding = 8) coherent buffer Label { uint label[]; };
layout(std430, binding = 9) buffer Area { uint area[]; };

uniform uint max_area;
const uint NONE = 0xFFFFFFFFu;

uint find_root(uint x) {
    uint l = label[x];
    while (l != x) {
        x = l;
        l = label[x];
    }
    return x;
}

void join(uint a, uint b) {
    bool done = false;
    while (!done) {
        a = find_root(a);
        b = find_root(b);
        if (a < b) {
            uint old = atomicMin(label[b], a);
            done = old == b;
            b = old;
        } else if (b < a) {
            uint old = atomicMin(label[a], b);
            done = old == a;
            a = old;
        } else {
            done = true;
        }
    }
}

void main() {
#if STEP == ROWS
    int y = int(gl_GlobalInvocationID.x);
    if (y >= size.y) return;
    uint start = NONE;
    for (int x = 0; x < size.x; ++x) {
        uint p = uint(y * size.x + x);
        if (is_valid(p)) {
            if (start == NONE) start = p;
        } else {
            start = NONE;
        }
        label[p] = start;
    }
#else
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    if (q.x >= size.x || q.y >= size.y) return;
    uint p = uint(q.y * size.x + q.x);
#endif
#if STEP == MERGE
    uint w = uint(size.x);
    if (q.y == 0 || !is_valid(p) || !is_valid(p - w)) return;
    if (q.x > 0 && is_valid(p - 1u) && is_valid(p - 1u - w)) return;
    join(p, p - w);
#elif STEP == COUNT
    // the trees are final: every pixel finds its root, keeps it and counts itself there
    if (label[p] == NONE) return;
    uint r = find_root(p);
    label[p] = r;
    atomicAdd(area[r], 1u);
#elif STEP == REMOVE
    uint l = label[p];
    if (l != NONE && area[l] <= max_area) remove_pixel(p, SPECKLE);
#endif
}
