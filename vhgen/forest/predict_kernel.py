"""The compiled inference kernel: per-pixel body-part labels of depth frames.

Every pixel walks every tree with exactly the arithmetic of
:func:`vhgen.forest.features.feature_at` (PCL ``runThroughTree``: the probe position
``x + du * (1000 / d)`` in float64, cast to float32, truncated, clamped into the image),
then the trees' normalised leaf histograms are summed in float32, tree after tree (the
argmax of the average), and the argmax taken (ties to the lowest class; by ``mass``:
background where its sum is at least all parts' together, else the most probable part).
The labels are identical to the slow reference; only the bookkeeping is fast:

* **Packed nodes**, 16 bytes, four per cache line: the four int16 offsets in one int64
  word, the threshold (low 32 bits) and the left child (high 32 bits) in the other.
  A leaf is a node that loops to itself (offsets 0: f = d(x) - d(x) = 0, threshold >= 0:
  always "left" = itself), so the walk has no per-node leaf branch; its threshold field
  holds the leaf's row in the probability table.
* **Probe arithmetic in SIMD**: the four probe coordinates of a node are one <4 x double>
  multiply-add (separate multiply and add, never fused, as the reference rounds), one
  conversion to float32 and to int32, one clamp; on x86 the two linear image indices
  ``v * W + u`` come from one ``pmaddwd`` (exact: coordinates and W fit int16).
* **Lockstep blocks**: one pixel's walk is a chain of dependent loads; _BLOCK independent
  pixels walked level by level fill the pipeline. One tree at a time over all pixels.
* **Vote**: leaf distributions only (not one row per node), padded to a multiple of
  8 classes with -1 so that the sum and maximum vectorise; neighbouring pixels often end
  in the same leaves, so a pixel with the same leaves as the previous one reuses its label.

Measured with ``NUMBA_NUM_THREADS=1 python benchmarks/bench_forest.py`` (see docs/performance.md).
"""

from __future__ import annotations

import platform
from dataclasses import dataclass

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from vhgen.forest.features import BACKGROUND_MM, FOCAL_SCALE

_BLOCK = 32  # pixels walked in lockstep (8..128 measured within 5%: throughput bound)
MAX_SIDE = 32767  # pmaddwd multiplies int16 coordinates by the int16 image width
# pmaddwd is an x86 instruction; elsewhere the generic vector multiply (same result)
USE_PMADDWD = platform.machine().lower() in ("x86_64", "amd64")


def _probe_ir(builder: ir.IRBuilder, packed: ir.Value, xyxy: ir.Value, s: ir.Value,
              w: ir.Value, h: ir.Value, pmaddwd: bool) -> tuple[ir.Value, ir.Value]:
    """IR: linear image indices (i64, i64) of the two probes of a node at one pixel."""
    i32, i64 = ir.IntType(32), ir.IntType(64)
    i16x4, i32x4 = ir.VectorType(ir.IntType(16), 4), ir.VectorType(i32, 4)
    f64x4, f32x4 = ir.VectorType(ir.DoubleType(), 4), ir.VectorType(ir.FloatType(), 4)
    off = builder.sitofp(builder.bitcast(packed, i16x4), f64x4)  # du1 dv1 du2 dv2
    sv = ir.Constant(f64x4, None)
    for k in range(4):
        sv = builder.insert_element(sv, s, ir.Constant(i32, k))
    # x + du * scale in float64 (no fused multiply-add: plain fmul and fadd round twice,
    # as the reference does), then float32, then truncation toward zero
    pos = builder.fadd(xyxy, builder.fmul(off, sv))
    iv = builder.fptosi(builder.fptrunc(pos, f32x4), i32x4)
    w32, h32 = builder.trunc(w, i32), builder.trunc(h, i32)
    one = ir.Constant(i32, 1)
    hi, mul = ir.Constant(i32x4, None), ir.Constant(i32x4, None)
    for k in range(4):
        hi = builder.insert_element(hi, builder.sub(w32 if k % 2 == 0 else h32, one),
                                    ir.Constant(i32, k))
        mul = builder.insert_element(mul, one if k % 2 == 0 else w32, ir.Constant(i32, k))
    zero = ir.Constant(i32x4, [0, 0, 0, 0])
    iv = builder.select(builder.icmp_signed(">", iv, zero), iv, zero)
    iv = builder.select(builder.icmp_signed("<", iv, hi), iv, hi)  # u1 v1 u2 v2
    if pmaddwd:
        i16x8 = ir.VectorType(ir.IntType(16), 8)
        mod = builder.module
        pack = cgutils.get_or_insert_function(
            mod, ir.FunctionType(i16x8, [i32x4, i32x4]), "llvm.x86.sse2.packssdw.128")
        madd = cgutils.get_or_insert_function(
            mod, ir.FunctionType(i32x4, [i16x8, i16x8]), "llvm.x86.sse2.pmadd.wd")
        # int32 -> int16 with saturation is exact here: 0 <= coordinate < 32768
        r = builder.call(madd, [builder.call(pack, [iv, iv]), builder.call(pack, [mul, mul])])
        a = builder.extract_element(r, ir.Constant(i32, 0))  # u1 + v1 * W
        b = builder.extract_element(r, ir.Constant(i32, 1))  # u2 + v2 * W
    else:
        lin = builder.mul(iv, mul)
        e = [builder.extract_element(lin, ir.Constant(i32, k)) for k in range(4)]
        a, b = builder.add(e[0], e[1]), builder.add(e[2], e[3])
    return builder.zext(a, i64), builder.zext(b, i64)  # non-negative


def _make_probe(pmaddwd: bool):
    @intrinsic
    def probe(typingctx, packed, xyxy, p, s, w, h):
        """(i1, i2) uint64 linear indices into the (H, W) image of the probes of the node
        with packed offsets ``packed`` at pixel ``p``: ``xyxy[p]`` = (x, y, x, y) float64,
        ``s`` = 1000 / d(x) float64."""
        sig = types.UniTuple(types.uint64, 2)(types.int64, xyxy, types.uint64, types.float64,
                                              types.int64, types.int64)

        def codegen(context, builder, signature, args):
            packed_v, xyxy_v, p_v, s_v, w_v, h_v = args
            ary = context.make_array(signature.args[1])(context, builder, xyxy_v)
            f64x4 = ir.VectorType(ir.DoubleType(), 4)
            ptr = builder.gep(ary.data, [builder.mul(p_v, ir.Constant(ir.IntType(64), 4))])
            row = builder.load(builder.bitcast(ptr, f64x4.as_pointer()), align=8)
            a, b = _probe_ir(builder, packed_v, row, s_v, w_v, h_v, pmaddwd)
            return context.make_tuple(builder, signature.return_type, [a, b])

        return sig, codegen

    return probe


_probe = _make_probe(USE_PMADDWD)
_probe_generic = _make_probe(False)
_probe_pmaddwd = _make_probe(True) if USE_PMADDWD else _probe_generic


@numba.njit(cache=True)
def probe_indices(packed: np.ndarray, xyxy: np.ndarray, scale: np.ndarray, w: int, h: int,
                  which: int) -> np.ndarray:
    """Test hook: (N, 2) probe indices of node ``packed[i]`` at pixel ``xyxy[i]``;
    ``which`` 0 = the generic vector code, 1 = pmaddwd (x86; else generic too)."""
    out = np.empty((packed.shape[0], 2), np.uint64)
    for i in range(packed.shape[0]):
        p = np.uint64(i)
        if which == 0:
            a, b = _probe_generic(packed[i], xyxy, p, scale[i], w, h)
        else:
            a, b = _probe_pmaddwd(packed[i], xyxy, p, scale[i], w, h)
        out[i, 0] = a
        out[i, 1] = b
    return out


@dataclass(frozen=True)
class PackedForest:
    """A forest laid out for :func:`predict_frame` (see module docstring).

    nodes : (2N,) int64 packed nodes in the forest's node order: node i is
        ``nodes[2i]`` (offsets) and ``nodes[2i + 1]`` (threshold or leaf row | next << 32).
    roots, levels : (T,) int64 root node and number of levels (longest path) per tree.
    prob : (L, C8) float32 normalised class histogram of each leaf; C8 = C rounded up to a
        multiple of 8, the padding columns -1.
    num_classes : C.
    """

    nodes: np.ndarray
    roots: np.ndarray
    levels: np.ndarray
    prob: np.ndarray
    num_classes: int


def tree_levels(left: np.ndarray, root: int) -> int:
    """Length of the longest path from ``root`` to a leaf it reaches (left: (N,) children,
    -1 = leaf). Walked, not read from ``depth``: a truncated forest keeps deeper nodes
    that no pixel reaches."""
    frontier = np.array([root], np.int64)
    level = seen = 0
    while True:
        inner = frontier[left[frontier] >= 0]
        if len(inner) == 0:
            return level
        seen += len(inner)
        if seen > len(left):  # a tree visits each split node once
            raise ValueError("the forest's child links are not a tree (a cycle)")
        frontier = np.concatenate([left[inner], left[inner] + 1])
        level += 1


def pack_forest(offsets: np.ndarray, thresh: np.ndarray, left: np.ndarray, counts: np.ndarray,
                roots: np.ndarray) -> PackedForest:
    """Pack the arrays of a :class:`vhgen.forest.trees.Forest` (same meanings and dtypes)."""
    left = np.asarray(left, np.int64)
    n = len(left)
    leaf = left < 0
    leaves = np.flatnonzero(leaf)
    off = np.ascontiguousarray(offsets, dtype=np.int16).copy()
    off[leaf] = 0
    low = np.asarray(thresh, np.int64).copy()
    low[leaves] = np.arange(len(leaves))
    nxt = np.where(leaf, np.arange(n), left)
    nodes = np.empty((n, 2), np.int64)
    nodes[:, 0] = off.view(np.int64).ravel()  # little endian: du1 in the low 16 bits
    nodes[:, 1] = (low & 0xFFFFFFFF) | (nxt << 32)
    roots = np.ascontiguousarray(roots, dtype=np.int64)
    levels = np.array([tree_levels(left, int(r)) for r in roots], np.int64)
    c = counts.shape[1]
    prob = np.full((len(leaves), -(-c // 8) * 8), -1.0, np.float32)
    for a in range(0, len(leaves), 1 << 16):  # in chunks: PCL trees have 2^20 leaves
        lc = counts[leaves[a:a + (1 << 16)]]
        # the same float32 arithmetic as Forest.probabilities(), on the leaves only
        tot = np.maximum(lc.sum(axis=1, keepdims=True), 1).astype(np.float32)
        prob[a:a + len(lc), :c] = lc.astype(np.float32) / tot
    return PackedForest(nodes=nodes.ravel(), roots=roots, levels=levels, prob=prob, num_classes=c)


@numba.njit(cache=True)
def _walk_tree(flat, w, h, nodes, root, levels, xyxy, scale, node):
    """Leaf node of every pixel in one tree, pixels in lockstep blocks (see module doc)."""
    npix = node.shape[0]
    for b0 in range(0, npix, _BLOCK):
        b1 = min(b0 + _BLOCK, npix)
        for p in range(b0, b1):
            node[p] = root
        for _ in range(levels):
            changed = np.uint64(0)
            for q in range(b0, b1):
                p = np.uint64(q)  # unsigned: no negative-index wraparound code
                n = node[p]
                tl = nodes[np.uint64(2) * n + np.uint64(1)]
                i1, i2 = _probe(nodes[np.uint64(2) * n], xyxy, p, scale[p], w, h)
                f = np.int32(flat[i1]) - np.int32(flat[i2])
                lft = np.uint64(tl >> 32)
                nxt = lft + np.uint64(1) if f > np.int32(tl) else lft
                changed |= nxt ^ n
                node[p] = nxt
            if changed == 0:  # every pixel of the block sits on a leaf
                break


@numba.njit(cache=True)
def predict_frame(img, nodes, roots, levels, prob, out, mass=False):
    """Labels of one frame (serial).

    img : (H, W) uint16 prepared depth (0 already BACKGROUND_MM), H, W <= 32767.
    nodes, roots, levels, prob : a :class:`PackedForest`.
    out : (H, W) uint8, written: 0 on background, else the argmax class.
    mass : the person decision by mass: a pixel is background when the background's
        summed probability is at least that of all parts together (summed in float32,
        class after class), else its most probable part (first maximum among the parts).
    """
    h, w = img.shape
    flat = img.ravel()
    oflat = out.ravel()
    nt = roots.shape[0]
    cp = prob.shape[1]
    pix = np.empty(h * w, np.int64)
    xyxy = np.empty((h * w, 4), np.float64)
    scale = np.empty(h * w, np.float64)
    npix = 0
    for y in range(h):
        for x in range(w):
            d = img[y, x]
            if d == BACKGROUND_MM:
                out[y, x] = 0
            else:
                pix[npix] = y * w + x
                xyxy[npix, 0] = x
                xyxy[npix, 1] = y
                xyxy[npix, 2] = x
                xyxy[npix, 3] = y
                scale[npix] = FOCAL_SCALE / np.float64(d)
                npix += 1
    leaf = np.empty((nt, npix), np.uint64)
    for t in range(nt):
        _walk_tree(flat, w, h, nodes, np.uint64(roots[t]), levels[t], xyxy, scale, leaf[t])
    acc = np.empty(cp, np.float32)
    bits = acc.view(np.int32)
    prev = np.full(nt, np.uint64(0xFFFFFFFFFFFFFFFF))
    best = 0
    for q in range(npix):
        p = np.uint64(q)
        same = True
        for t in range(nt):
            lt = leaf[t, p]
            if lt != prev[t]:
                same = False
                prev[t] = lt
        if not same:
            r = np.uint64(nodes[np.uint64(2) * leaf[0, p] + np.uint64(1)] & 0xFFFFFFFF)
            for k in range(cp):
                acc[k] = prob[r, k]
            for t in range(1, nt):  # the reference's order: ((p0 + p1) + p2) ...
                r = np.uint64(nodes[np.uint64(2) * leaf[t, p] + np.uint64(1)] & 0xFFFFFFFF)
                for k in range(cp):
                    acc[k] += prob[r, k]
            # class sums are >= +0 and the padding < 0: the float order is the order of
            # the int32 bit patterns, whose maximum vectorises; first maximum = argmax
            # two loops, not one from a variable first class: a constant start keeps the
            # argmax path as fast as before (measured: 4-9% slower with one loop)
            if mass:
                parts = np.float32(0.0)
                for k in range(1, cp):
                    if acc[k] > 0:  # the padding columns are negative
                        parts += acc[k]
                if acc[0] >= parts:
                    best = 0
                else:
                    m = bits[1]
                    for k in range(2, cp):
                        m = max(m, bits[k])
                    best = 1
                    while bits[best] != m:
                        best += 1
            else:
                m = bits[0]
                for k in range(1, cp):
                    m = max(m, bits[k])
                best = 0
                while bits[best] != m:
                    best += 1
        oflat[pix[p]] = best


@numba.njit(parallel=True, cache=True)
def predict_batch(imgs, nodes, roots, levels, prob, out, mass=False):
    """:func:`predict_frame` over (N, H, W) frames, frames in parallel (numba threads)."""
    for i in numba.prange(imgs.shape[0]):
        predict_frame(imgs[i], nodes, roots, levels, prob, out[i], mass)
