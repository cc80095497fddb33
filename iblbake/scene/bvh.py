"""The BVH over a scene's triangles, built on the host with numpy one tree level at a time: each
node split where the binned surface area heuristic is lowest, over its primitives kept sorted by
centroid on each axis; traversed in kernels/scene.h."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

LEAF_SIZE = 4
# levels split by the surface area heuristic; deeper ones at the object median, so a tree's depth
# stays within the kernels' traversal stack (64) whatever the mesh
SAH_DEPTH = 32
# equal bins of a node's centroid extent per axis, between which the heuristic weighs cuts
SAH_BINS = 32


@dataclass
class BVH:
    nodes: np.ndarray      # (nodes, 8) float32: bmin xyz, left/first (int bits), bmax xyz, count (int bits)
    order: np.ndarray      # primitive permutation (leaves hold contiguous runs of it)
    build_s: float
    depth: int

    @property
    def node_count(self):
        return len(self.nodes)


def _segment_reduce(ufunc, values, starts, counts):
    """ufunc.reduce over values[start:start+count] for each segment (segments may leave gaps)."""
    pad = np.concatenate([values, values[:1]], axis=0)
    idx = np.empty(2 * len(starts), dtype=np.int64)
    idx[0::2] = starts
    idx[1::2] = starts + counts
    return ufunc.reduceat(pad, idx, axis=0)[0::2]


def _half_areas(lo, hi):
    e = hi - lo
    return e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0]


def _sah_cost(lo, hi, c, p, seg, s_ct, first):
    """Per segment of p (primitives sorted by their centroids c on one axis, segments of s_ct
    from first) the lowest surface area heuristic cost (left count x left area + right count x
    right area) over the cuts between SAH_BINS equal bins of its centroids' extent (binned SAH,
    Wald 2007), and the left count of the first cut that reaches it. The sorted primitives of a
    bin are a run: each run is reduced once (reduceat), then bounds accumulate over runs."""
    nseg = len(s_ct)
    cmin = c[first][seg]
    ext = c[first + s_ct - 1][seg] - cmin
    b = np.minimum((SAH_BINS * (c - cmin) / np.where(ext > 0, ext, 1)).astype(np.int64), SAH_BINS - 1)
    key = seg * SAH_BINS + b
    run0 = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]]))    # first primitive of each run
    run_seg = seg[run0]
    runs = np.bincount(run_seg, minlength=nseg)
    j = np.arange(len(run0)) - np.repeat(np.cumsum(runs) - runs, runs)
    width = int(runs.max())
    blo, bhi = np.full((nseg, width, 3), np.inf, lo.dtype), np.full((nseg, width, 3), -np.inf, lo.dtype)
    blo[run_seg, j] = np.minimum.reduceat(lo[p], run0)
    bhi[run_seg, j] = np.maximum.reduceat(hi[p], run0)
    n_left = np.zeros((nseg, width), np.int64)          # primitives left of the cut after run k
    n_left[run_seg, j] = np.concatenate([run0[1:], [len(p)]]) - first[run_seg]
    left = _half_areas(np.minimum.accumulate(blo, axis=1), np.maximum.accumulate(bhi, axis=1))
    right = _half_areas(np.minimum.accumulate(blo[:, ::-1], axis=1)[:, ::-1],
                        np.maximum.accumulate(bhi[:, ::-1], axis=1)[:, ::-1])
    valid = np.arange(width)[None, :] < (runs - 1)[:, None]
    with np.errstate(invalid="ignore"):
        cost = left * n_left + np.concatenate([right[:, 1:], right[:, :1]], axis=1) * (s_ct[:, None] - n_left)
    cost = np.where(valid, cost, np.inf)
    k = np.argmin(cost, axis=1)
    best, n = cost[np.arange(nseg), k], n_left[np.arange(nseg), k]
    # a segment whose centroids fall in one bin (or coincide) has no cut: the median, at infinite cost
    return best, np.where(runs > 1, n, s_ct // 2)


def build_bvh(lo: np.ndarray, hi: np.ndarray, leaf_size: int = LEAF_SIZE) -> BVH:
    """SAH BVH over primitive bounds lo, hi (n, 3), built level by level: every node of more
    than leaf_size primitives splits at the cut of lowest surface area heuristic cost over its
    primitives sorted by centroid on each axis (beyond SAH_DEPTH levels at the object median of
    its widest axis, which bounds the depth the kernels' traversal stacks hold). The primitives
    are sorted once per axis; a split partitions each axis's order stably, so every node's run
    stays sorted on all three without sorting again."""
    t0 = time.perf_counter()
    n = len(lo)
    centroid = 0.5 * (lo + hi)
    by_axis = [np.argsort(centroid[:, a], kind="stable") for a in range(3)]
    goes_left = np.zeros(n, bool)
    lo32, hi32 = lo.astype(np.float32), hi.astype(np.float32)      # costs need no more (half the traffic)
    # node records, BFS order; children of a node are adjacent (left, left + 1)
    starts = [np.array([0], np.int64)]
    counts = [np.array([n], np.int64)]
    firsts = []      # per level: left child index (interior) or -1
    level_starts = np.array([0], np.int64)
    level_counts = np.array([n], np.int64)
    next_index = 1
    depth = 0
    while True:
        split = level_counts > leaf_size
        left = np.full(len(level_starts), -1, np.int64)
        if split.any():
            s_st, s_ct = level_starts[split], level_counts[split]
            first = np.cumsum(s_ct) - s_ct                         # segment starts within pos
            seg = np.repeat(np.arange(len(s_st)), s_ct)
            pos = np.repeat(s_st - first, s_ct) + np.arange(s_ct.sum())
            sorted_prims = [by_axis[a][pos] for a in range(3)]
            if depth < SAH_DEPTH:
                costs = [_sah_cost(lo32, hi32, centroid[sorted_prims[a], a], sorted_prims[a], seg, s_ct, first)
                         for a in range(3)]
                axis = np.argmin(np.stack([c[0] for c in costs]), axis=0)
                half = np.choose(axis, [c[1] for c in costs])
            else:
                ext = np.stack([centroid[by_axis[a][s_st + s_ct - 1], a] - centroid[by_axis[a][s_st], a]
                                for a in range(3)])
                axis, half = np.argmax(ext, axis=0), s_ct // 2
            start, n_left = np.repeat(s_st, s_ct), np.repeat(half, s_ct)
            goes_left[np.choose(axis[seg], sorted_prims)] = pos - start < n_left
            for a in range(3):      # stable partition of each order: lefts, then rights, per segment
                prims = sorted_prims[a]
                f = goes_left[prims]
                cl, cr = np.concatenate([[0], np.cumsum(f)]), np.concatenate([[0], np.cumsum(~f)])
                k = np.arange(len(prims))
                to = start + np.where(f, cl[k] - cl[first][seg], n_left + cr[k] - cr[first][seg])
                by_axis[a][to] = prims
            child_st = np.stack([s_st, s_st + half], axis=1).reshape(-1)
            child_ct = np.stack([half, s_ct - half], axis=1).reshape(-1)
            left[split] = next_index + 2 * np.arange(len(s_st))
            next_index += 2 * len(s_st)
        firsts.append(left)
        if not split.any():
            break
        level_starts, level_counts = child_st, child_ct
        starts.append(level_starts)
        counts.append(level_counts)
        depth += 1
    order = by_axis[0]
    st = np.concatenate(starts)
    ct = np.concatenate(counts)
    left = np.concatenate(firsts)
    bmin = _segment_reduce(np.minimum, lo[order], st, ct)
    bmax = _segment_reduce(np.maximum, hi[order], st, ct)
    nodes = np.zeros((len(st), 8), np.float32)
    nodes[:, 0:3] = bmin
    nodes[:, 4:7] = bmax
    ints = nodes.view(np.int32)
    interior = left >= 0
    ints[:, 3] = np.where(interior, left, st)
    ints[:, 7] = np.where(interior, 0, ct)
    return BVH(nodes, order, time.perf_counter() - t0, depth + 1)
