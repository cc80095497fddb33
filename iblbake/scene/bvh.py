"""The BVH over a scene's triangles, built on the host with numpy one tree level at a time: each
node split where the binned surface area heuristic is lowest, over its primitives kept sorted by
centroid on each axis; traversed in kernels/scene.h."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from iblbake.scene.layout import BVH_STACK, FLOAT4S

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
    wide: np.ndarray       # (wide nodes, 8, 4) float32: the tree a CPU's kernels traverse (widen)
    leaves: np.ndarray     # (leaves, 2) int64: each wide leaf's first primitive and count
    wide_depth: int

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
    wide, leaves, wide_depth = widen(nodes)
    return BVH(nodes, order, time.perf_counter() - t0, depth + 1, wide, leaves, wide_depth)


# children of a node of the traversed tree: the binary tree's grandchildren, four boxes tested at
# once as float4 lanes (a "QBVH": Dammertz, Hanika and Keller 2008; Embree's BVH4), and the
# triangles of a leaf, up to four, tested at once the same way
WIDTH = 4


def widen(nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The binary tree `nodes` (build_bvh's, children adjacent) collapsed two levels into one:
    each node of the wide tree holds up to four children (a binary node's grandchildren, or its
    child where that is a leaf), in records of 8 float4 (kernels/layout.h BVH4_NODE): the four
    children's min x, min y, min z, max x, max y, max z (one float4 each, a lane per child), their
    codes (int bits: a node's index, or -1 - the float4 offset of a leaf's record, which follow the
    nodes: device_tree), and padding to 128 bytes (two cache lines). An empty child's box is
    (+inf, -inf), which no ray meets. Built one level at a time, breadth first; returns the node
    records, the leaves' (first primitive, count) in the order of their records, and the depth."""
    ints = nodes.view(np.int32)
    first, count = ints[:, 3].astype(np.int64), ints[:, 7].astype(np.int64)
    inner = count == 0
    if count.max() > WIDTH:
        raise ValueError(f"a leaf of more than {WIDTH} primitives does not fit a wide leaf's record")

    def expand(n):      # (N, WIDTH) binary nodes under each of n: grandchildren, or a leaf child
        c0 = first[n]
        cols = []
        for c in (c0, c0 + 1):
            cols += [np.where(inner[c], first[c], c), np.where(inner[c], first[c] + 1, -1)]
        return np.stack(cols, axis=1)

    levels = [expand(np.array([0])) if inner[0] else np.array([[0, -1, -1, -1]])]
    while True:
        s = levels[-1].reshape(-1)
        nxt = s[(s >= 0) & inner[np.maximum(s, 0)]]
        if not len(nxt):
            break
        levels.append(expand(nxt))
    slots = np.concatenate(levels)
    total = len(slots)
    if (WIDTH - 1) * len(levels) + 1 > BVH_STACK:     # a node pushes at most WIDTH entries and pops one
        raise ValueError(f"BVH of {len(levels)} wide levels exceeds the traversal stack ({BVH_STACK})")
    # the nodes are numbered in the order their slots appear (breadth first), the leaves likewise
    flat = slots.reshape(-1)
    present = flat >= 0
    is_node = present & inner[np.maximum(flat, 0)]
    leaf = present & ~is_node
    code = np.full(len(flat), -1, np.int64)
    code[is_node] = 1 + np.arange(int(is_node.sum()))
    code[leaf] = -1 - (total * FLOAT4S["BVH4_NODE"] + FLOAT4S["BVH4_LEAF"] * np.arange(int(leaf.sum())))
    lo = np.where(present[:, None], nodes[np.maximum(flat, 0), 0:3], np.inf).reshape(total, WIDTH, 3)
    hi = np.where(present[:, None], nodes[np.maximum(flat, 0), 4:7], -np.inf).reshape(total, WIDTH, 3)
    out = np.zeros((total, FLOAT4S["BVH4_NODE"], 4), np.float32)
    out[:, 0:3] = lo.transpose(0, 2, 1)
    out[:, 3:6] = hi.transpose(0, 2, 1)
    out.view(np.int32)[:, 6] = code.reshape(total, WIDTH)
    return out, np.stack([first[flat[leaf]], count[flat[leaf]]], axis=1), len(levels)


def check_trees(nodes: np.ndarray, wide: np.ndarray, triangles: int, wide_nodes: int) -> None:
    """A ValueError where trees read back (build_bvh's nodes, device_tree's records of `wide_nodes`
    wide nodes over `triangles` triangles) would send a traversal outside its arrays or round a
    loop: a child not numbered after its parent (both builders number breadth first, so a loop
    cannot pass), a leaf's record or run of triangles out of range, an empty wide lane whose box a
    ray could meet (its code would be read as a leaf), or a wide tree deeper than the traversal's
    stack. Other boxes are not checked: a wrong box gives a wrong picture, not a wild read."""
    if not (nodes.dtype == np.float32 and nodes.ndim == 2 and nodes.shape[1] == 8
            and wide.dtype == np.float32 and wide.ndim == 2 and wide.shape[1] == 4):
        raise ValueError("BVH arrays of the wrong type or shape")
    if triangles == 0:
        return
    ints = nodes.view(np.int32)
    a, c = ints[:, 3].astype(np.int64), ints[:, 7].astype(np.int64)
    inner = c == 0                     # children a and a + 1; a leaf's triangles a .. a + c - 1
    own = np.arange(len(nodes))
    if not len(nodes) or (inner & ((a <= own) | (a + 1 >= len(nodes)))).any():
        raise ValueError("a binary BVH node's child numbered before it or past the nodes")
    if (~inner & ((c < 0) | (c > WIDTH) | (a < 0) | (a + c > triangles))).any():
        raise ValueError("a binary BVH leaf's triangles out of range")
    node_rows, leaf_rows = FLOAT4S["BVH4_NODE"], FLOAT4S["BVH4_LEAF"]
    rows = wide_nodes * node_rows
    if wide_nodes < 1 or len(wide) < rows or (len(wide) - rows) % leaf_rows:
        raise ValueError("a wide BVH whose records do not match its node count")
    records = wide[:rows].reshape(wide_nodes, node_rows, 4)
    codes = records.view(np.int32)[:, 6].astype(np.int64)              # (node, lane)
    off = -1 - codes                   # a leaf's record (codes < -1); -1 an empty lane
    parent = np.arange(wide_nodes)[:, None]
    bad_node = (codes >= 0) & ((codes <= parent) | (codes >= wide_nodes))
    bad_leaf = (codes < -1) & ((off < rows) | ((off - rows) % leaf_rows != 0) | (off + leaf_rows > len(wide)))
    empty = codes == -1
    open_box = ~((records[:, 0:3] == np.inf).all(1) & (records[:, 3:6] == -np.inf).all(1))   # per lane
    if bad_node.any():
        raise ValueError("a wide BVH node's child numbered before it or past the nodes")
    if bad_leaf.any():
        raise ValueError("a wide BVH leaf code off its records")
    if (empty & open_box).any():
        raise ValueError("an empty wide BVH lane with a box a ray could meet")
    runs = wide[rows:].reshape(-1, leaf_rows, 4).view(np.int32)[:, 9, :2].astype(np.int64)
    if ((runs[:, 0] < 0) | (runs[:, 1] < 1) | (runs[:, 1] > WIDTH) | (runs.sum(1) > triangles)).any():
        raise ValueError("a wide BVH leaf's triangles out of range")
    level, depth = np.array([0]), 0    # the wide traversal's stack holds (WIDTH - 1) a level + 1
    while len(level):
        depth += 1
        if (WIDTH - 1) * depth + 1 > BVH_STACK:
            raise ValueError(f"a wide BVH deeper than the traversal's stack ({BVH_STACK})")
        level = codes[level][codes[level] >= 0]


def device_tree(bvh: BVH, v0: np.ndarray, v1: np.ndarray, v2: np.ndarray) -> np.ndarray:
    """The (m, 4) float32 records kernels/scene.h traverses: the wide nodes, then per leaf (in
    bvh.leaves' order) its triangles' corners by coordinate, a lane per triangle (kernels/layout.h
    BVH4_LEAF: v0 x, y, z, v1 x, y, z, v2 x, y, z; a missing triangle's lanes all zero, a degenerate
    triangle no ray meets) and (first, count, -, -) as int bits. v0, v1, v2: the corners in the
    BVH's primitive order (bvh.order applied)."""
    first, count = bvh.leaves[:, 0], bvh.leaves[:, 1]
    lanes = np.arange(WIDTH)
    k = np.minimum(first[:, None] + lanes, len(v0) - 1)
    here = lanes < count[:, None]
    leaf = np.zeros((len(first), FLOAT4S["BVH4_LEAF"], 4), np.float32)
    for c, v in enumerate((v0, v1, v2)):
        leaf[:, 3 * c:3 * c + 3] = np.where(here[..., None], v[k], 0).transpose(0, 2, 1)
    leaf.view(np.int32)[:, 9, 0], leaf.view(np.int32)[:, 9, 1] = first, count
    return np.concatenate([bvh.wide.reshape(-1, 4), leaf.reshape(-1, 4)])
