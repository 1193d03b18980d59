#version 430
// The speckle filter: 4-connected components of valid pixels by label equivalence
// (Playne & Hawick, "A new algorithm for parallel connected-component labelling on GPUs",
// IEEE TPDS 2018), then each component's area; components of at most max_area pixels
// become holes (cause SPECKLE). STEP defined by the host:
//   INIT:     label[p] = p on valid pixels, NONE elsewhere;
//   SCAN:     a pixel whose neighbours hold a smaller label lowers its root's label to it
//             (atomicMin) and reports a change; repeated with RESOLVE until none does;
//   RESOLVE:  every label replaced by its root's (labels only ever fall, so the chain
//             ends at a root);
//   COUNT:    area[root] += 1;
//   REMOVE:   pixels of small components become holes.
layout(local_size_x = 8, local_size_y = 8) in;
#include "sensor.glsl"

layout(std430, binding = 8) buffer Label { uint label[]; };
layout(std430, binding = 9) buffer Area { uint area[]; };
layout(std430, binding = 11) buffer Changed { uint changed; };

uniform uint max_area;
const uint NONE = 0xFFFFFFFFu;

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    if (q.x >= size.x || q.y >= size.y) return;
    uint p = uint(q.y * size.x + q.x);
#if STEP == INIT
    label[p] = is_valid(p) ? p : NONE;
#elif STEP == SCAN
    uint l = label[p];
    if (l == NONE) return;
    uint m = l;
    if (q.x > 0) m = min(m, label[p - 1u]);
    if (q.x < size.x - 1) m = min(m, label[p + 1u]);
    if (q.y > 0) m = min(m, label[p - uint(size.x)]);
    if (q.y < size.y - 1) m = min(m, label[p + uint(size.x)]);
    if (m < l) {
        atomicMin(label[l], m);
        changed = 1u;
    }
#elif STEP == RESOLVE
    uint l = label[p];
    if (l == NONE) return;
    uint r = label[l];
    while (r != l) {
        l = r;
        r = label[l];
    }
    label[p] = l;
#elif STEP == COUNT
    uint l = label[p];
    if (l != NONE) atomicAdd(area[l], 1u);
#elif STEP == REMOVE
    uint l = label[p];
    if (l != NONE && area[l] <= max_area) remove_pixel(p, SPECKLE);
#endif
}
