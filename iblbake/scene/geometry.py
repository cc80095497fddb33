"""Scene geometry for the renderer: analytic spheres and planes, meshes (trimesh), and a BVH.

Meshes are flattened to one triangle list (every mesh of a scene, world space, float64 on the
host, float32 on the device) with three shading normals per triangle. The BVH is built on the host
with numpy, one tree level at a time (each node split where the surface area heuristic is
lowest over every position of its primitives sorted by centroid on each axis: per level three
segmented sorts and prefix/suffix bounds of all primitives), and traversed in kernels/scene.h.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iblbake.errors import InputError

LEAF_SIZE = 4
# levels split by the surface area heuristic; deeper ones at the object median, so a tree's depth
# stays within the kernels' traversal stack (64) whatever the mesh
SAH_DEPTH = 32
# corners whose vertex normal turns more than this from the face normal use the face normal
# (keeps a cube's edges sharp when its corners are shared vertices)
CREASE_COS = math.cos(math.radians(45.0))


@dataclass
class Triangles:
    v0: np.ndarray                # (n, 3) float64 corners, world space (shared corners stay
    v1: np.ndarray                # bit-identical, which the watertight ray test relies on)
    v2: np.ndarray
    normals: np.ndarray           # (n, 3, 3) shading normal per corner, unit
    material: np.ndarray          # (n,) int32
    object_id: np.ndarray         # (n,) int32
    stats: list = field(default_factory=list)   # per mesh: path, triangles, dropped, smooth

    def __len__(self):
        return len(self.v0)

    @property
    def e1(self):
        return self.v1 - self.v0

    @property
    def e2(self):
        return self.v2 - self.v0


def _rotation_xyz(deg):
    rx, ry, rz = np.radians(deg)
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    mx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    my = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    mz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return mz @ my @ mx      # x first, then y, then z


def load_mesh(spec: dict, where: str):
    """(vertices (n,3), faces (m,3), vertex normals or None) of a mesh file, checked."""
    import trimesh

    path = Path(spec["path"])
    if not path.is_file():
        raise InputError(f"{where}: mesh {path} not found")
    _refuse_draco(path, where)
    # trimesh logs format warnings itself; ours are one line per problem, so keep it quiet
    logging.getLogger("trimesh").setLevel(logging.CRITICAL)
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):   # NaN vertices are reported below
            warnings.simplefilter("ignore")
            # not force="mesh": that concatenation drops the normals stored in the file
            loaded = trimesh.load(str(path), process=False)
    except MemoryError:
        raise InputError(f"{where}: mesh {path} claims more data than fits in memory; the file is "
                         f"corrupt or far too large") from None
    except Exception as e:   # trimesh raises many kinds on malformed files
        text = " ".join(str(e).split())[:160] or type(e).__name__
        raise InputError(f"{where}: mesh {path} cannot be read ({text}); check the file "
                         f"(OBJ, PLY, STL, GLB/glTF)") from None
    parts = [p for p in _mesh_parts(loaded) if len(p[0].faces)]
    if not parts:
        raise InputError(f"{where}: mesh {path} has no triangles")
    vs, fs, ns = [], [], []
    base = 0
    for g, transform in parts:
        v = np.asarray(g.vertices, dtype=np.float64)
        f = np.asarray(g.faces)
        if f.ndim != 2 or f.shape[1] != 3:
            raise InputError(f"{where}: mesh {path}: faces are not triangles (shape {f.shape})")
        bad_idx = (f < 0) | (f >= len(v))
        if bad_idx.any():
            k = int(np.argmax(bad_idx.any(axis=1)))
            raise InputError(f"{where}: mesh {path}: face {k} indexes vertex {int(f[k][bad_idx[k]][0])} "
                             f"but the mesh has {len(v)} vertices; the file is corrupt")
        m = transform[:3, :3]
        with np.errstate(all="ignore"):
            v = v @ m.T + transform[:3, 3]
        bad = ~np.isfinite(v).all(axis=1)
        if bad.any():
            k = int(np.argmax(bad))
            raise InputError(f"{where}: mesh {path}: vertex {k} is {v[k].tolist()} (not finite; "
                             f"{int(bad.sum())} such vertices); fix or re-export the mesh")
        n = None
        if spec.get("smooth", "auto") != "off":
            n = _vertex_normals(g)
            if n is not None and abs(np.linalg.det(m)) > 1e-300:
                n = n @ np.linalg.inv(m)          # normals transform with the inverse transpose
        vs.append(v)
        fs.append(f.astype(np.int64) + base)
        ns.append(n)
        base += len(v)
    normals = np.concatenate(ns) if all(n is not None for n in ns) else None
    return np.concatenate(vs), np.concatenate(fs), normals


def _mesh_parts(loaded):
    """(triangle mesh, 4x4 world transform) for every mesh in what trimesh.load returned."""
    import trimesh

    if isinstance(loaded, trimesh.Trimesh):
        return [(loaded, np.eye(4))]
    if isinstance(loaded, trimesh.Scene):
        out = []
        for node in loaded.graph.nodes_geometry:
            transform, name = loaded.graph[node]
            g = loaded.geometry.get(name)
            if isinstance(g, trimesh.Trimesh):
                out.append((g, np.asarray(transform, dtype=np.float64)))
        return out
    return []                                      # point clouds, paths: nothing to render


def _vertex_normals(g):
    """The normals stored in the file (trimesh keeps them in its cache), else trimesh's
    area-weighted ones."""
    stored = getattr(getattr(g, "_cache", None), "cache", {}).get("vertex_normals")
    if stored is not None and np.shape(stored) == np.shape(g.vertices):
        return np.asarray(stored, dtype=np.float64)
    try:
        with np.errstate(all="ignore"):
            return np.asarray(g.vertex_normals, dtype=np.float64)
    except Exception:   # a mesh trimesh cannot compute normals for: face normals are used
        return None


def _refuse_draco(path: Path, where: str):
    """Draco-compressed glTF decodes to zeros without the optional DracoPy: say so instead."""
    if path.suffix.lower() not in (".gltf", ".glb"):
        return
    with open(path, "rb") as f:
        head = f.read(1 << 20)
    if b"KHR_draco_mesh_compression" in head:
        raise InputError(f"{where}: mesh {path} uses Draco compression (KHR_draco_mesh_compression), "
                         f"which iblbake does not decode; export it uncompressed")


def transform_matrix(spec: dict):
    scale = spec.get("scale", 1.0)
    s = np.diag(np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,)))
    return _rotation_xyz(spec.get("rotate", [0, 0, 0])) @ s, np.asarray(spec.get("translate", [0, 0, 0]), np.float64)


def build_triangles(objects: list, material_index: dict, source: str) -> Triangles:
    """Every mesh object of the scene as one world-space triangle list."""
    parts, stats = [], []
    for oid, obj in enumerate(objects):
        if "mesh" not in obj:
            continue
        spec = obj["mesh"]
        where = f"{source}: objects.{oid}.mesh"
        v, f, vn = load_mesh(spec, where)
        m, t = transform_matrix(spec)
        vw = v @ m.T + t
        tri = vw[f]                                     # (n, 3, 3)
        e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        cross = np.cross(e1, e2)
        area2 = np.linalg.norm(cross, axis=1)
        scale2 = (e1 ** 2).sum(1) + (e2 ** 2).sum(1)
        keep = np.isfinite(area2) & (area2 > 1e-10 * scale2) & (scale2 > 0)
        face_n = np.zeros_like(cross)
        face_n[keep] = cross[keep] / area2[keep, None]
        if vn is not None and len(vn) == len(v):
            # normals transform with the inverse transpose
            nw = vn @ np.linalg.inv(m)
            ln = np.linalg.norm(nw, axis=1, keepdims=True)
            ok = np.isfinite(nw).all(1, keepdims=True) & (ln > 1e-20)
            nw = np.where(ok, nw / np.where(ok, ln, 1.0), 0.0)
            corner = nw[f]                              # (n, 3, 3)
            # zero-length or creased corners fall back to the face normal; flipped ones follow it
            d = np.einsum("nkc,nc->nk", corner, face_n)
            use_face = (np.abs(d) < CREASE_COS)[..., None]
            corner = np.where(d[..., None] < 0, -corner, corner)
            corner = np.where(use_face, face_n[:, None, :], corner)
            smooth = True
        else:
            corner = np.repeat(face_n[:, None, :], 3, axis=1)
            smooth = False
        n_keep = int(keep.sum())
        if n_keep == 0:
            raise InputError(f"{where}: mesh {spec['path']}: all {len(f)} triangles are degenerate "
                             f"(zero area); nothing to render")
        parts.append((tri[keep, 0], tri[keep, 1], tri[keep, 2], corner[keep],
                      np.full(n_keep, material_index[obj["material"]], np.int32), np.full(n_keep, oid, np.int32)))
        stats.append({"object": oid, "path": spec["path"], "triangles": n_keep,
                      "dropped_degenerate": int(len(f) - n_keep), "smooth_normals": smooth})
    if not parts:
        z = np.zeros((0, 3))
        return Triangles(z, z, z, np.zeros((0, 3, 3)), np.zeros(0, np.int32), np.zeros(0, np.int32), stats)
    cols = list(zip(*parts))
    return Triangles(*(np.concatenate(c) for c in cols), stats=stats)


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


def _segmented_running_max(x, seg, span):
    """np.maximum.accumulate restarted at each segment of the sorted segment ids seg: every value
    is lifted by its segment's index times span (more than the values' range), so an earlier
    segment never reaches a later one."""
    off = seg.astype(np.float64)[:, None] * span
    return np.maximum.accumulate(x + off, axis=0) - off


def _half_areas(lo, hi):
    e = hi - lo
    return e[:, 0] * e[:, 1] + e[:, 1] * e[:, 2] + e[:, 2] * e[:, 0]


def _sah_splits(lo, hi, centroid, prims, seg, s_ct, axis_order):
    """Per segment the axis and the count left of its best split (the surface area heuristic:
    left count x left area + right count x right area, over every cut of the primitives sorted
    on that axis), and per axis the sorted primitives."""
    nseg = len(s_ct)
    first = np.cumsum(s_ct) - s_ct                  # segment starts within prims
    rank = np.arange(len(prims)) - np.repeat(first, s_ct)
    span = 2.0 * float(np.max(np.abs(np.concatenate([lo[prims], hi[prims]])))) + 1.0
    best_cost = np.full(nseg, np.inf)
    best_axis = np.zeros(nseg, np.int64)
    best_left = s_ct // 2
    sorted_prims = []
    for a in range(3):
        p = prims[axis_order[a]]
        sorted_prims.append(p)
        l, h = lo[p], hi[p]
        left = _half_areas(-_segmented_running_max(-l, seg, span), _segmented_running_max(h, seg, span))
        rseg = (nseg - 1 - seg)[::-1]
        right = _half_areas(-_segmented_running_max(-l[::-1], rseg, span),
                            _segmented_running_max(h[::-1], rseg, span))[::-1]
        # cut after rank i: left holds i + 1 primitives (prefix i), right the rest (suffix i + 1)
        n_left = rank + 1
        cost = np.full(len(p), np.inf)
        inner = n_left < np.repeat(s_ct, s_ct)
        idx = np.flatnonzero(inner)
        cost[idx] = left[idx] * n_left[idx] + right[idx + 1] * (np.repeat(s_ct, s_ct)[idx] - n_left[idx])
        seg_min = np.minimum.reduceat(cost, first)
        at = np.flatnonzero(cost == seg_min[seg])
        at = at[np.unique(seg[at], return_index=True)[1]]   # the first best cut of each segment
        better = seg_min < best_cost
        best_cost[better] = seg_min[better]
        best_axis[better] = a
        best_left[seg[at][better[seg[at]]]] = n_left[at][better[seg[at]]]
    return best_axis, best_left, sorted_prims


def build_bvh(lo: np.ndarray, hi: np.ndarray, leaf_size: int = LEAF_SIZE) -> BVH:
    """SAH BVH over primitive bounds lo, hi (n, 3), built level by level (nodes of more than
    leaf_size primitives split; beyond SAH_DEPTH levels at the object median, which bounds the
    depth the kernels' traversal stacks hold)."""
    t0 = time.perf_counter()
    n = len(lo)
    centroid = 0.5 * (lo + hi)
    order = np.arange(n, dtype=np.int64)
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
            seg = np.repeat(np.arange(len(s_st)), s_ct)
            pos = np.repeat(s_st - (np.cumsum(s_ct) - s_ct), s_ct) + np.arange(s_ct.sum())
            prims = order[pos]
            cmin = _segment_reduce(np.minimum, centroid[prims], np.cumsum(s_ct) - s_ct, s_ct)
            cmax = _segment_reduce(np.maximum, centroid[prims], np.cumsum(s_ct) - s_ct, s_ct)
            ext = np.maximum(cmax - cmin, 1e-300)
            # segmented sort per axis: segment index + centroid scaled into [0, 0.5] within its segment
            axis_order = [np.argsort(seg + 0.5 * ((centroid[prims, a] - cmin[seg, a]) / ext[seg, a]), kind="stable")
                          for a in range(3)]
            if depth < SAH_DEPTH:
                axis, half, sorted_prims = _sah_splits(lo, hi, centroid, prims, seg, s_ct, axis_order)
            else:
                axis, half = np.argmax(cmax - cmin, axis=1), s_ct // 2
                sorted_prims = [prims[o] for o in axis_order]
            order[pos] = np.choose(axis[seg], sorted_prims)
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


def triangle_bounds(tris: Triangles):
    p0, p1, p2 = tris.v0, tris.v1, tris.v2
    lo = np.minimum(np.minimum(p0, p1), p2)
    hi = np.maximum(np.maximum(p0, p1), p2)
    # float32 rounding on the device: widen each box by a relative ulp margin
    pad = 1e-6 * np.maximum(np.abs(lo), np.abs(hi)) + 1e-30
    return lo - pad, hi + pad


def plane_frame(normal):
    """Unit normal, and the in-plane axes a finite plane's width and depth follow:
    for a floor (normal +-y) width runs along x and depth along z."""
    n = np.asarray(normal, np.float64)
    n = n / np.linalg.norm(n)
    if abs(n[1]) > 0.999:
        t = np.array([1.0, 0.0, 0.0])
    else:
        t = np.cross(n, [0.0, 1.0, 0.0])
        t /= np.linalg.norm(t)
    b = np.cross(t, n)
    return n, t, b
