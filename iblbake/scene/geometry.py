"""Scene geometry for the renderer: analytic spheres and planes, and meshes (trimesh, glTF).

Meshes are flattened to one triangle list (every mesh of a scene, world space, float64 on the
host, float32 on the device) with three shading normals per triangle. Their BVH: scene/bvh.py.
"""

from __future__ import annotations

import logging
import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iblbake.errors import InputError

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
    component: np.ndarray | None = None   # (n,) int32: its connected component (shared edges), scene-wide
    solid: np.ndarray | None = None       # (n,) int32: 0 open, 1 a closed component wound outwards, -1 inwards

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
    if not os.path.exists(path):          # not Path.exists: a name too long raised OSError
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

    from iblbake.io import reads
    try:        # trimesh reads what it is given whole: a device or a FIFO would never end
        reads.check_file(path, reads.mesh_bytes(), "a mesh", reads.MESH_HINT)
    except InputError as e:
        raise InputError(f"{where}: mesh {e}") from None

    # trimesh logs format warnings itself; ours are one line per problem, so keep it quiet
    logging.getLogger("trimesh").setLevel(logging.CRITICAL)
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):   # NaN vertices are reported by load_mesh
            warnings.simplefilter("ignore")
            # not force="mesh": that concatenation drops the normals stored in the file. No other
            # file is read: an OBJ's material library and a PLY's texture (the scene's materials
            # shade these meshes) could name anything (docs/manual.md, paths a scene may name)
            loaded = trimesh.load(str(path), process=False, skip_materials=True)
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
                         np.zeros((0, 3, 4)), np.zeros((0, 3, 4)), np.zeros((0, 2)), np.zeros(0, np.int32),
                         np.zeros(0, np.int32))
    cols = list(zip(*parts))
    tris = Triangles(*(np.concatenate(c) for c in cols[:6]), stats=stats, uv=np.concatenate(cols[6]),
                     tangents=np.concatenate(cols[7]), uv_density=np.concatenate(cols[8]))
    # closed components, each object's own (two objects' faces never weld into one solid)
    tris.component, tris.solid = np.zeros(len(tris), np.int32), np.zeros(len(tris), np.int32)
    base = 0
    for st in stats:
        sel = np.nonzero(tris.object_id == st["object"])[0]
        comp, solid = closed_components(tris.v0[sel], tris.v1[sel], tris.v2[sel])
        tris.component[sel], tris.solid[sel] = comp + base, solid
        base += int(comp.max()) + 1 if len(comp) else 0
        st["components"] = int(len(np.unique(comp)))
        st["closed_components"] = int(len(np.unique(comp[solid != 0])))
    return tris


def closed_components(v0, v1, v2):
    """(component (n,) int32, solid (n,) int32) of triangles given by their corners: faces sharing an
    edge (corners welded where bit-identical) form a component; a component is closed when every
    edge of it is shared by exactly two of its faces wound against each other (watertight and
    consistently wound, trimesh's is_watertight and is_winding_consistent), and its solid is then
    the sign of its enclosed volume (divergence theorem: +1 wound outwards, -1 inwards; 0 open).
    A closed component bounds a solid whatever its sides (docs/conventions.md "Sides")."""
    n = len(v0)
    if n == 0:
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    corners = np.stack([v0, v1, v2], 1).reshape(-1, 3)
    by = np.lexsort(corners.T[::-1])                     # weld: one id per distinct position
    s = corners[by]
    vid = np.empty(len(by), np.int64)
    vid[by] = np.cumsum(np.r_[True, (s[1:] != s[:-1]).any(1)]) - 1
    vid = vid.reshape(n, 3)
    a = vid.reshape(-1)
    b = vid[:, [1, 2, 0]].reshape(-1)
    face = np.repeat(np.arange(n), 3)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo.astype(np.int64) * (int(vid.max()) + 1) + hi
    order = np.argsort(key, kind="stable")
    ks, fs = key[order], face[order]
    first = np.r_[True, ks[1:] != ks[:-1]]
    group = np.cumsum(first) - 1
    count = np.bincount(group)
    # union of the faces around each shared edge: pointer jumping to the smallest face id
    parent = np.arange(n)
    f1, f2 = fs[~first], fs[np.nonzero(~first)[0] - 1]
    while len(f1):
        r1, r2 = parent[f1], parent[f2]
        diff = r1 != r2
        if not diff.any():
            break
        np.minimum.at(parent, np.maximum(r1, r2)[diff], np.minimum(r1, r2)[diff])
        while True:
            jumped = parent[parent]
            if np.array_equal(jumped, parent):
                break
            parent = jumped
    _, comp = np.unique(parent, return_inverse=True)
    # an edge is manifold and consistently wound where two faces share it and their directed
    # edges are opposite: (a, b) in one, (b, a) in the other
    forward = (a < b)[order]
    good_edge = (count == 2) & (np.bincount(group, weights=forward) == 1)
    bad_face = np.zeros(n, bool)
    bad_face[fs[~good_edge[group]]] = True
    ncomp = int(comp.max()) + 1
    open_comp = np.bincount(comp, weights=bad_face, minlength=ncomp) > 0
    volume = np.bincount(comp, weights=np.einsum("ij,ij->i", v0, np.cross(v1, v2)), minlength=ncomp)
    solid = np.where(open_comp | (volume == 0), 0, np.sign(volume)).astype(np.int32)
    return comp.astype(np.int32), solid[comp]


def inside_closed(point, v0, v1, v2, component, solid) -> set:
    """The closed components (of closed_components) that enclose `point`: a ray from it crosses
    their surface an odd number of times (Moller-Trumbore in float64, along a direction no edge of
    an axis-aligned mesh lies in)."""
    sel = np.nonzero(solid != 0)[0]
    if not len(sel):
        return set()
    d = np.array([0.5773502691896258, 0.5773502691896258, 0.5773502691896258]) + [1e-3, -2e-3, 3e-3]
    d /= np.linalg.norm(d)
    o = np.asarray(point, np.float64)
    a, e1, e2 = v0[sel], v1[sel] - v0[sel], v2[sel] - v0[sel]
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", p, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        sv = o - a
        u = np.einsum("ij,ij->i", sv, p) * inv
        q = np.cross(sv, e1)
        v = (q @ d) * inv
        t = np.einsum("ij,ij->i", q, e2) * inv
    crossed = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    hits = np.bincount(component[sel][crossed], minlength=int(component.max()) + 1)
    return {int(c) for c in np.nonzero(hits % 2 == 1)[0]}


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
