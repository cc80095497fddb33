"""Scene geometry for the renderer: analytic spheres and planes, meshes (trimesh), and a BVH.

Meshes are flattened to one triangle list (every mesh of a scene, world space, float64 on the
host, float32 on the device) with three shading normals per triangle. The BVH is built on the host
with numpy, one tree level at a time (each node split where the binned surface area heuristic
is lowest, over its primitives kept sorted by centroid on each axis), and traversed in
kernels/scene.h.
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
# equal bins of a node's centroid extent per axis, between which the heuristic weighs cuts
SAH_BINS = 32
# corners whose vertex normal turns more than this from the face normal use the face normal
# (keeps a cube's edges sharp when its corners are shared vertices)
CREASE_COS = math.cos(math.radians(45.0))


@dataclass
class Triangles:
    v0: np.ndarray                # (n, 3) float64 corners, world space (shared corners stay
    v1: np.ndarray                # bit-identical, which the watertight ray test relies on)
    v2: np.ndarray
    normals: np.ndarray           # (n, 3, 3) shading normal per corner, unit
    material: np.ndarray          # (n,) int32: a record of the scene's material table
    object_id: np.ndarray         # (n,) int32
    stats: list = field(default_factory=list)   # per mesh: path, triangles, dropped, smooth
    uv: np.ndarray | None = None          # (n, 3, 4) per corner (u0, v0, u1, v1), NaN where the mesh has none
    tangents: np.ndarray | None = None    # (n, 3, 4) per corner (tangent, w)
    uv_density: np.ndarray | None = None  # (n, 2) 0.5 log2(UV area / world area) of each set

    def __len__(self):
        return len(self.v0)

    @property
    def e1(self):
        return self.v1 - self.v0

    @property
    def e2(self):
        return self.v2 - self.v0


@dataclass
class MeshData:
    """A mesh file's triangles in its own space: per vertex positions, normals, texture
    coordinates (glTF's convention: v down the image) and tangents (NaN rows where the file has
    none), and per face the file's material (-1: none, or the glTF default material)."""
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    uv: list
    tangents: np.ndarray
    face_material: np.ndarray
    smooth: bool


def _rotation_xyz(deg):
    rx, ry, rz = np.radians(deg)
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    mx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    my = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    mz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return mz @ my @ mx      # x first, then y, then z


def load_mesh(spec: dict, where: str) -> MeshData:
    """A mesh file, checked: glTF/GLB through iblbake.scene.gltf (materials, both texture
    coordinate sets, tangents), the rest through trimesh (geometry and TEXCOORD_0)."""
    path = Path(spec["path"])
    if not path.is_file():
        raise InputError(f"{where}: mesh {path} not found")
    if path.suffix.lower() in (".gltf", ".glb"):
        parts = _gltf_parts(path, where)
    else:
        parts = _trimesh_parts(path, where)
    if not parts:
        raise InputError(f"{where}: mesh {path} has no triangles")
    vs, fs, ns, uvs, ts, ms = [], [], [], [[], []], [], []
    base = 0
    smooth = spec.get("smooth", "auto") != "off"
    for v, f, n, uv, tan, mat in parts:
        if f.ndim != 2 or f.shape[1] != 3:
            raise InputError(f"{where}: mesh {path}: faces are not triangles (shape {f.shape})")
        bad_idx = (f < 0) | (f >= len(v))
        if bad_idx.any():
            k = int(np.argmax(bad_idx.any(axis=1)))
            raise InputError(f"{where}: mesh {path}: face {k} indexes vertex {int(f[k][bad_idx[k]][0])} "
                             f"but the mesh has {len(v)} vertices; the file is corrupt")
        bad = ~np.isfinite(v).all(axis=1)
        if bad.any():
            k = int(np.argmax(bad))
            raise InputError(f"{where}: mesh {path}: vertex {k} is {v[k].tolist()} (not finite; "
                             f"{int(bad.sum())} such vertices); fix or re-export the mesh")
        nanrows = lambda w: np.full((len(v), w), np.nan)
        vs.append(v)
        fs.append(f.astype(np.int64) + base)
        ns.append(n if n is not None and smooth else nanrows(3))
        for k in range(2):
            uvs[k].append(uv[k] if uv[k] is not None else nanrows(2))
        ts.append(tan if tan is not None else nanrows(4))
        ms.append(np.broadcast_to(np.asarray(mat, np.int64), (len(f),)))
        base += len(v)
    normals = np.concatenate(ns)
    return MeshData(np.concatenate(vs), np.concatenate(fs), normals, [np.concatenate(u) for u in uvs],
                    np.concatenate(ts), np.concatenate(ms), bool(np.isfinite(normals).all(axis=1).any()))


def _gltf_parts(path: Path, where: str) -> list:
    from iblbake.scene import gltf

    try:
        prims = gltf.read(path, where).primitives()
    except InputError:
        raise
    except MemoryError:
        raise InputError(f"{where}: mesh {path} claims more data than fits in memory; the file is "
                         f"corrupt or far too large") from None
    except (AttributeError, TypeError, KeyError, ValueError, IndexError, OverflowError, RecursionError) as e:
        text = " ".join(str(e).split())[:120] or type(e).__name__
        raise InputError(f"{where}: mesh {path} cannot be read ({type(e).__name__}: {text}); check the file "
                         f"(OBJ, PLY, STL, GLB/glTF)") from None
    return [(p.positions, p.faces, p.normals, p.texcoords, p.tangents, p.material) for p in prims if len(p.faces)]


def _trimesh_parts(path: Path, where: str) -> list:
    import trimesh

    # trimesh logs format warnings itself; ours are one line per problem, so keep it quiet
    logging.getLogger("trimesh").setLevel(logging.CRITICAL)
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):   # NaN vertices are reported by load_mesh
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
    out = []
    for g, transform in _mesh_parts(loaded):
        if not len(g.faces):
            continue
        v = np.asarray(g.vertices, dtype=np.float64)
        m = transform[:3, :3]
        with np.errstate(all="ignore"):
            v = v @ m.T + transform[:3, 3]
        n = _vertex_normals(g)
        if n is not None and abs(np.linalg.det(m)) > 1e-300:
            n = n @ np.linalg.inv(m)                      # normals transform with the inverse transpose
        uv = getattr(g.visual, "uv", None)
        if uv is not None and np.shape(uv) == (len(v), 2):
            uv = np.asarray(uv, np.float64) * [1.0, -1.0] + [0.0, 1.0]   # OpenGL's v up -> glTF's v down
        else:
            uv = None
        out.append((v, np.asarray(g.faces), n, [uv, None], None, -1))
    return out


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


def transform_matrix(spec: dict):
    scale = spec.get("scale", 1.0)
    s = np.diag(np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,)))
    return _rotation_xyz(spec.get("rotate", [0, 0, 0])) @ s, np.asarray(spec.get("translate", [0, 0, 0]), np.float64)


def build_triangles(objects: list, offsets: dict, source: str, file_materials: dict | None = None,
                    attributes: bool = False) -> Triangles:
    """Every mesh object of the scene as one world-space triangle list. offsets[object index] is
    the material record of the object's scene material, or, for an object in file_materials
    (object index -> how many materials its file has), the first of its file's records (the glTF
    default material after them, for primitives without one). With `attributes` (a scene whose
    materials read textures) each corner's texture coordinates and tangent too."""
    from iblbake.scene import tangents as tangent_space

    file_materials = file_materials or {}
    parts, stats = [], []
    for oid, obj in enumerate(objects):
        if "mesh" not in obj:
            continue
        spec = obj["mesh"]
        where = f"{source}: objects.{oid}.mesh"
        mesh = load_mesh(spec, where)
        v, f = mesh.vertices, mesh.faces
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
        # normals transform with the inverse transpose; rows the file lacks stay NaN
        with np.errstate(all="ignore"):
            nw = mesh.normals @ np.linalg.inv(m)
            ln = np.linalg.norm(nw, axis=1, keepdims=True)
        ok = np.isfinite(nw).all(1, keepdims=True) & (ln > 1e-20)
        nw = np.where(ok, nw / np.where(ok, ln, 1.0), 0.0)
        corner, corner_ok = nw[f], ok[f][..., 0]            # (n, 3, 3), (n, 3)
        # missing, zero-length or creased corners fall back to the face normal; flipped ones follow it
        d = np.einsum("nkc,nc->nk", corner, face_n)
        use_face = ((np.abs(d) < CREASE_COS) | ~corner_ok)[..., None]
        corner = np.where(d[..., None] < 0, -corner, corner)
        corner = np.where(use_face, face_n[:, None, :], corner)
        smooth = mesh.smooth and bool(corner_ok.any())
        n_keep = int(keep.sum())
        if n_keep == 0:
            raise InputError(f"{where}: mesh {spec['path']}: all {len(f)} triangles are degenerate "
                             f"(zero area); nothing to render")
        if oid in file_materials:
            mat = offsets[oid] + np.where(mesh.face_material >= 0, mesh.face_material, file_materials[oid] - 1)
        else:
            mat = np.full(len(f), offsets[oid], np.int64)
        uv = np.concatenate([mesh.uv[0][f], mesh.uv[1][f]], axis=2)          # (n, 3, 4)
        if attributes:
            tan = tangent_space.corner_tangents(vw, f, corner, mesh.uv[0], mesh.tangents, m)
            density = np.stack([tangent_space.uv_density(tri, uv[..., 2 * k:2 * k + 2]) for k in range(2)], axis=1)
        else:
            tan, density = np.zeros((len(f), 3, 4)), np.zeros((len(f), 2))
        parts.append((tri[keep, 0], tri[keep, 1], tri[keep, 2], corner[keep], mat[keep].astype(np.int32),
                      np.full(n_keep, oid, np.int32), uv[keep], tan[keep], density[keep]))
        stats.append({"object": oid, "path": spec["path"], "triangles": n_keep,
                      "dropped_degenerate": int(len(f) - n_keep), "smooth_normals": smooth,
                      "texcoords": [bool(np.isfinite(u).all(axis=1).any()) for u in mesh.uv],
                      "tangents": "file" if np.isfinite(mesh.tangents).all(axis=1).all() else "generated"})
    if not parts:
        z = np.zeros((0, 3))
        return Triangles(z, z, z, np.zeros((0, 3, 3)), np.zeros(0, np.int32), np.zeros(0, np.int32), stats,
                         np.zeros((0, 3, 4)), np.zeros((0, 3, 4)), np.zeros((0, 2)))
    cols = list(zip(*parts))
    return Triangles(*(np.concatenate(c) for c in cols[:6]), stats=stats, uv=np.concatenate(cols[6]),
                     tangents=np.concatenate(cols[7]), uv_density=np.concatenate(cols[8]))


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
