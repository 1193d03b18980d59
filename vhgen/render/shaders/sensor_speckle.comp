#version 430
// The speckle filter: 4-connected components of valid pixels by union-find with atomics
// (Playne & Hawick, "A new algorithm for parallel connected-component labelling on
// GPUs", IEEE TPDS 2018: the "union find" variant; a fixed number of passes, no
// iteration), then each component's area; components of at most max_area pixels become
// holes (cause SPECKLE). STEP defined by the host:
//   ROWS:     a row scan (row_scan.glsl): label[p] = the first pixel of
//             p's run of valid pixels in the row, NONE on invalid pixels (the rows'
//             unions, for free): one past the last invalid pixel before p, a running
//             maximum;
//   MERGE:    a valid pixel with a valid pixel above joins the two trees, unless its left
//             neighbour and the one above that are valid too (the same two runs are then
//             already joined there): the larger root is pointed at the smaller one
//             (atomicMin, retried until it holds), so every tree's root is its
//             component's smallest pixel;
//   COUNT:    every label replaced by its root, and area[root] += 1;
//   REMOVE:   pixels of small components become holes.
#include "sensor.glsl"
#if STEP == ROWS
#include "row_scan.glsl"
layout(local_size_x = ROW_LOCAL) in;
#else
layout(local_size_x = 8, local_size_y = 8) in;
#endif

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
    int y = row_y();
    if (y >= size.y) return;  // a whole group where rows have several invocations
    uint row = uint(y * size.x);
    int x0 = row_x0(), x1 = row_x1();
    float last = -1.0;  // the last invalid pixel of the stretch (exact as a float)
#if ROW_THREADS > 1
    for (int x = x0; x < x1; ++x) {
        if (!is_valid(row + uint(x))) last = float(x);
    }
#endif
    int gap = int(row_exclusive(last, false, true, -1.0));  // the last one before it
    for (int x = x0; x < x1; ++x) {
        uint p = row + uint(x);
        if (is_valid(p)) {
            label[p] = row + uint(gap + 1);
        } else {
            gap = x;
            label[p] = NONE;
        }
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
