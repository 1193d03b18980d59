// Row scans: a running minimum or maximum along each image row, in one of two layouts
// the host picks (#defines ROW_THREADS, ROW_GROUP and their product ROW_LOCAL; the
// including shader declares layout(local_size_x = ROW_LOCAL)):
// * ROW_THREADS > 1 (GPUs), one row a work group: invocation t owns the stretch
//   [row_x0(), row_x1()) of its row; each reduces its stretch to one value,
//   row_exclusive combines those across the group (Hillis-Steele in shared memory,
//   log2(ROW_THREADS) steps), and each then walks its own stretch from the value of the
//   stretches before it. A row costs its stretch (5 pixels at 640) plus 7 steps: one
//   invocation a row left a GPU 480 threads for the whole image, 0.2-0.3 ms a pass.
// * ROW_THREADS == 1 (software renderers, where barriers cost more than the walk), one
//   invocation a row, ROW_GROUP rows a work group: the stretch is the row.
// min and max of floats are exact, so both give what one invocation walking the row gives.
#if ROW_THREADS > 1
shared float row_part[ROW_THREADS];
#endif

int row_y() {
    return int(gl_WorkGroupID.x) * ROW_GROUP + int(gl_LocalInvocationID.x) / ROW_THREADS;
}

int row_x0() {
    int t = int(gl_LocalInvocationID.x) % ROW_THREADS;  // the invocation within its row
    return min(t * ((size.x + ROW_THREADS - 1) / ROW_THREADS), size.x);
}

int row_x1() {
    return min(row_x0() + (size.x + ROW_THREADS - 1) / ROW_THREADS, size.x);
}

// Combine v of every invocation of the row before this one (backward: after it) with max
// (else min); none where there is nothing before (after).
float row_exclusive(float v, bool backward, bool take_max, float none) {
#if ROW_THREADS == 1
    return none;
#else
    uint t = gl_LocalInvocationID.x;
    row_part[t] = v;
    barrier();
    for (uint d = 1u; d < uint(ROW_THREADS); d <<= 1) {
        float mine = row_part[t];
        float other = none;
        if (backward ? t + d < uint(ROW_THREADS) : t >= d) {
            other = row_part[backward ? t + d : t - d];
        }
        barrier();
        row_part[t] = take_max ? max(mine, other) : min(mine, other);
        barrier();
    }
    float r = none;
    if (backward ? t + 1u < uint(ROW_THREADS) : t >= 1u) {
        r = row_part[backward ? t + 1u : t - 1u];
    }
    barrier();  // every invocation has read before the array is written again
    return r;
#endif
}
