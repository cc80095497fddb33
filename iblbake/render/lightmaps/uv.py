"""A lightmap's second UV set and its texels (docs/manual.md "Lightmaps").

layout(): one atlas over every lightmapped surface of a scene: each mesh object's triangles (welded
by shared corners) charted and packed by xatlas (Young's xatlas, the library trimesh's unwrap uses;
docs/libraries.md), its own TEXCOORD_1 charts kept where the mesh has them (xatlas packs them as they
are, scaled to the density); a finite plane as two triangles; an analytic sphere meshed (SPHERE_SEGMENTS),
its texels' points and normals then put back on the true sphere. Each lit side of a surface is a
chart set of its own (sides(): a wall of no thickness both, a solid its outside), its triangles wound
to face that side (the geometric normal of an atlas triangle is its lit side's). The density is
lightmap.texels_per_unit texels per world unit along each side, with PADDING texels between charts
(the bilinear footprint of the mip levels an engine samples, and room for dilation).

texels(): each texel a triangle claims: the texel's centre where it lies inside the triangle, else
(a texel the triangle only partly covers, at a chart's edge) the nearest point of the triangle to it;
a texel claimed whole by one triangle keeps it, a partial one goes to the nearest triangle (every
triangle's box of texels at once in numpy, CHUNK pairs at a time)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from iblbake.errors import InputError
from iblbake.render.lightmaps import pack

PADDING = 2                  # texels between charts
SPHERE_SEGMENTS = (32, 16)   # a sphere's mesh: around, pole to pole
SPHERE_TEXELS = 16           # a sphere's least texels around its equator (the corridor's sphere, 0.3 in
                             # radius at 4 texels a unit, has 7.5 and read x1.54 its reference)
TEXEL_BYTES = 4 * 4          # the bake's float32 RGBA per texel per basis coefficient set (see bake.bytes_of)


@dataclass
class Layout:
    """An atlas: width x height texels; per triangle its corners in world space (n, 3, 3), shading
    normals (n, 3, 3), object index (n,), its corners in texel units (n, 3, 2) (the texel (i, j)
    covers [i, i+1] x [j, j+1]); spheres: per triangle (centre, radius) of the sphere it meshes,
    radius 0 for a flat triangle; how each object got its UVs (object index -> 'texcoord_1' |
    'xatlas' | 'sphere' | 'plane')."""
    width: int
    height: int
    corners: np.ndarray
    normals: np.ndarray
    objects: np.ndarray
    uv: np.ndarray
    spheres: np.ndarray
    source: dict


def sphere_mesh(center, radius, segments=SPHERE_SEGMENTS):
    """(vertices, faces) of a UV sphere: rings of `segments[0]` around, `segments[1]` bands."""
    na, nb = segments
    th = np.linspace(0, math.pi, nb + 1)
    ph = np.linspace(0, 2 * math.pi, na + 1)[:-1]
    t, p = np.meshgrid(th, ph, indexing="ij")
    v = np.stack([np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)], -1).reshape(-1, 3)
    idx = np.arange((nb + 1) * na).reshape(nb + 1, na)
    a, b = idx[:-1], np.roll(idx[:-1], -1, 1)
    c, d = idx[1:], np.roll(idx[1:], -1, 1)
    faces = np.concatenate([np.stack([a, b, c], -1)[1:].reshape(-1, 3),      # no sliver at the poles
                            np.stack([b, d, c], -1)[:-1].reshape(-1, 3)])
    return np.asarray(center, np.float64) + radius * v, faces


def plane_mesh(plane: dict):
    """(vertices, faces) of a finite plane (scene key plane: point, normal, size)."""
    from iblbake.scene.geometry import plane_frame
    n, t, b = plane_frame(plane["normal"])
    size = plane["size"]
    hw, hd = (size / 2, size / 2) if not isinstance(size, list) else (size[0] / 2, size[1] / 2)
    p = np.asarray(plane["point"], np.float64)
    v = np.array([p - hw * t - hd * b, p + hw * t - hd * b, p + hw * t + hd * b, p - hw * t + hd * b])
    winding = np.dot(np.cross(v[1] - v[0], v[2] - v[0]), n) > 0
    return v, np.array([[0, 1, 2], [0, 2, 3]] if winding else [[0, 2, 1], [0, 3, 2]])


def weld(corners):
    """(vertices, faces) of a flat triangle list (n, 3, 3): corners at one position shared."""
    flat = corners.reshape(-1, 3)
    verts, inverse = np.unique(flat, axis=0, return_inverse=True)
    return verts, inverse.reshape(-1, 3)


def charted(obj: dict) -> bool:
    """Whether a scene object gets a lightmap: a mesh, a sphere or a finite plane (an infinite plane
    has none: it keeps the probes or the panorama's SH), unless `lightmap: false` (a dynamic object)."""
    return obj.get("lightmap", True) and (
        "mesh" in obj or "sphere" in obj or ("plane" in obj and obj["plane"]["size"] is not None))


def sides(scene, tris) -> np.ndarray:
    """Which sides of each mesh triangle are lit surfaces (docs/conventions.md "Sides"): 1 its front
    alone (a single-sided surface; a solid wound outwards, whose back is its inside), -1 its back alone
    (a solid wound inwards), 0 both (a double-sided open surface, or a room the camera is in: a wall
    of no thickness is seen from either side, each its own texels)."""
    from iblbake.scene import materials
    from iblbake.scene.layout import SURFACE_FLAGS
    from iblbake.scene.pack import solid_flags

    records, _offsets = materials.table(scene)
    single = materials.surface_flags(records)[tris.material] & SURFACE_FLAGS["single_sided"]
    full = np.zeros((len(tris), 3, 4), np.float32)      # the packed records' corners and object ids
    full[:, 0, :3], full[:, 1, :3], full[:, 2, :3] = tris.v0, tris.v1, tris.v2
    full[:, 1, 3] = np.asarray(tris.object_id, np.int32).view(np.float32)
    flags = solid_flags(scene, full, np.stack([tris.component, tris.solid], 1), single)
    solid = (flags & SURFACE_FLAGS["solid"]) != 0
    return np.where(solid, np.where(flags & SURFACE_FLAGS["solid_flipped"], -1, 1), np.where(single, 1, 0))


def _both(part, side):
    """A part as its lit sides: itself where its front is lit (side 1 or 0), its back as a part of its
    own (the faces wound the other way, their normals turned) where its back is (side -1 or 0)."""
    oid, how, v, f, uv, sph, nrm = part
    out = [part] if side >= 0 else []
    if side <= 0:
        out.append((oid, how, v, f[:, ::-1], uv, sph, None if nrm is None else -nrm[:, ::-1]))
    return out


def _parts(scene, tris):
    """Each lightmapped surface's (object index, how, vertices, faces, TEXCOORD_1 per vertex or None,
    sphere (centre, radius) or None, shading normals per face corner or None), a side a part (a
    sphere's outside; a finite plane's two sides but where single-sided; a mesh's as sides() says).
    An infinite plane has none (it keeps the probes)."""
    from iblbake.scene import materials

    records, offsets = materials.table(scene)
    out = []
    for oid, o in enumerate(scene.data["objects"]):
        if not charted(o):
            continue
        if "sphere" in o:
            v, f = sphere_mesh(o["sphere"]["center"], o["sphere"]["radius"])
            out.append((oid, "sphere", v, f, None, (o["sphere"]["center"], o["sphere"]["radius"]), None))
        elif "plane" in o:
            out += _both((oid, "plane", *plane_mesh(o["plane"]), None, None, None),
                         1 if not records[offsets[oid]]["double_sided"] else 0)
    side = sides(scene, tris) if len(tris) else np.zeros(0, int)
    for oid in np.unique(tris.object_id):
        if not charted(scene.data["objects"][int(oid)]):
            continue
        for s in (1, -1, 0):
            mine = (tris.object_id == oid) & (side == s)
            if not mine.any():
                continue
            corners = np.stack([tris.v0[mine], tris.v1[mine], tris.v2[mine]], 1)
            uv1 = None if tris.uv is None else tris.uv[mine][..., 2:4]
            if uv1 is not None and np.isfinite(uv1).all():
                # the authored charts: corners kept apart (a seam in TEXCOORD_1 is a seam in the atlas)
                part = (int(oid), "texcoord_1", corners.reshape(-1, 3), np.arange(3 * mine.sum()).reshape(-1, 3),
                        uv1.reshape(-1, 2), None, tris.normals[mine])
            else:
                part = (int(oid), "xatlas", *weld(corners), None, None, tris.normals[mine])
            out += _both(part, s)
    return out


def surface_area(scene, tris) -> float:
    """The area of the surfaces the lightmap charts (world units squared; each lit side once)."""
    return area(_parts(scene, tris))


def area(parts) -> float:
    """The area of _parts' surfaces."""
    return float(sum(0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum()
                     for _o, _h, v, f, _uv, _s, _n in parts))


def check_size(scene, surface: float, density: float, max_texels: int, key: str = "lightmap.texels_per_unit"):
    """Refuse a density whose atlas (estimated: `surface` x density^2 over xatlas' usual 70% use)
    passes max_texels, in one line naming `key`."""
    estimate = int(surface * density ** 2 / 0.7)
    if estimate > max_texels:
        # the density that fits, 2 significant digits rounded down (texels go as its square)
        fits = density * math.sqrt(max_texels / estimate)
        step = 10.0 ** (math.floor(math.log10(fits)) - 1)
        fits = math.floor(fits / step) * step
        raise InputError(f"{scene.source}: {key}: {density:g} texels per unit asks about {estimate} texels "
                         f"(~{estimate * TEXEL_BYTES * 4 / 2**20:.0f} MiB to bake) over the cap of {max_texels} "
                         f"(lightmap.max_texels); give a lower density (about {fits:.2g} fits)")


def layout(scene, tris, density: float, max_texels: int, key: str = "lightmap.texels_per_unit") -> Layout:
    """The scene's atlas at `density` texels per unit (xatlas), refused past max_texels (a one-line
    error naming `key` and the estimate) before anything is packed: the estimate is the surfaces' area
    times density squared, over xatlas' usual 70% use."""
    parts = _parts(scene, tris)
    check_size(scene, area(parts), density, max_texels, key)
    if not parts:
        raise InputError(f"{scene.source}: lightmap: the scene has no mesh, sphere or finite plane to lightmap")
    meshes = []
    for _o, how, v, f, uv, s, _n in parts:
        if s is not None:             # a small sphere charted larger: at least SPHERE_TEXELS around
            v = s[0] + (v - s[0]) * max(1.0, SPHERE_TEXELS / (2 * math.pi * s[1] * density))
        meshes.append((v, f, uv))
    use_uvs = any(p[1] == "texcoord_1" for p in parts)
    w, h, count, packed = pack.charts(meshes, density, PADDING, use_uvs, what=f"{scene.source}: {key}")
    if count != 1:
        raise InputError(f"{scene.source}: {key}: the charts took {count} atlases; give a lower density")
    corners, normals, objs, uvs, sph = [], [], [], [], []
    for i, (oid, how, v, f, _uv, s, part_normals) in enumerate(parts):
        vmap, idx, uv = packed[i]
        idx = idx.reshape(-1, 3)
        c = v[vmap][idx]
        corners.append(c)
        uvs.append(uv[idx].astype(np.float64) * [w, h])
        objs.append(np.full(len(idx), oid))
        nrm = None if part_normals is None else _normals(part_normals, f, vmap[idx])
        if s is not None:
            nrm = (c - np.asarray(s[0])) / s[1]
        if nrm is None:
            g = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
            nrm = np.repeat((g / np.linalg.norm(g, axis=1, keepdims=True))[:, None], 3, 1)
        normals.append(nrm)
        sph.append(np.tile([*(s[0] if s else (0, 0, 0)), s[1] if s else 0.0], (len(idx), 1)))
    source = {p[0]: p[1] for p in parts}
    return Layout(w, h, np.concatenate(corners), np.concatenate(normals), np.concatenate(objs),
                  np.concatenate(uvs), np.concatenate(sph).astype(np.float64), source)


def _normals(normals, faces, got):
    """The shading normals (n, 3, 3) at the corners of a part's atlas triangles, whose vertices in the
    part are `got` (n, 3): xatlas keeps each face in its place, its corners in their order or rotated."""
    match = got[:, :, None] == faces[:, None, :]
    if len(got) != len(faces) or not match.any(2).all():
        raise AssertionError("xatlas returned a triangle the mesh does not have")
    return normals[np.arange(len(got))[:, None], match.argmax(2)]


@dataclass
class Texels:
    """The texels a layout's triangles claim: flat index j * width + i (k,), the triangle (k,), its
    barycentrics at the texel's point (k, 3), the point (k, 3), its shading normal (k, 3), the
    triangle's geometric normal (k, 3), whether the texel's centre lies inside it (k,) and whether it
    is on an analytic sphere (k,: its outside is lightmapped)."""
    index: np.ndarray
    triangle: np.ndarray
    bary: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    geometric: np.ndarray
    inside: np.ndarray
    solid: np.ndarray


def _closest_bary(p, a, b, c):
    """Barycentrics (m, 3) of the point of the 2D triangle abc nearest each of p (m, 2), and the
    distance; a, b, c one triangle's corners (2,) or each point's own triangle's (m, 2)."""
    a, b, c = (np.broadcast_to(x, p.shape) for x in (a, b, c))
    v0, v1, v2 = b - a, c - a, p - a
    den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):         # a triangle of no area in the atlas
        s = (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / den
        t = (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / den
    best = np.stack([1 - s - t, s, t], 1)
    inside = (best >= -1e-9).all(1)
    dist = np.zeros(len(p))
    out = ~inside
    if out.any():                    # the nearest point on the nearest edge
        q, ds, cands = p[out], [], []
        for (i, j), (e0, e1) in zip(((0, 1), (1, 2), (2, 0)), ((a, b), (b, c), (c, a))):
            e0, e = e0[out], e1[out] - e0[out]
            f = np.clip(((q - e0) * e).sum(1) / np.maximum((e * e).sum(1), 1e-30), 0, 1)
            wb = np.zeros((len(q), 3))
            wb[:, i], wb[:, j] = 1 - f, f
            cands.append(wb)
            ds.append(np.linalg.norm(q - (e0 + f[:, None] * e), axis=1))
        k = np.argmin(np.stack(ds), 0)
        best[out] = np.stack(cands)[k, np.arange(len(q))]
        dist[out] = np.stack(ds)[k, np.arange(len(q))]
    return best, dist


CHUNK = 1 << 21       # (triangle, texel) pairs tested at once: bounds the rasterisation's memory


def _pairs(uv, width, height, reach):
    """Every (triangle, texel) pair of the texels in each triangle's bounding box grown by reach,
    triangle by triangle, each box's texels row by row: (triangle (m,), i (m,), j (m,))."""
    lo = np.maximum(np.floor(uv.min(1) - reach).astype(np.int64), 0)
    hi = np.minimum(np.ceil(uv.max(1) + reach).astype(np.int64), [width, height])
    size = np.maximum(hi - lo, 0)
    n = size[:, 0] * size[:, 1]
    tri = np.repeat(np.arange(len(uv)), n)
    local = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    nx = size[tri, 0]
    return tri, lo[tri, 0] + local % nx, lo[tri, 1] + local // nx


def texels(lay: Layout) -> Texels:
    """Every texel a triangle covers (its centre inside) or touches (within half a texel's diagonal):
    every triangle's box of candidate texels at once (numpy), CHUNK pairs at a time."""
    reach = math.sqrt(0.5)
    box = np.ceil(lay.uv.max(1) + reach) - np.floor(lay.uv.min(1) - reach)
    cum = np.cumsum(np.prod(np.maximum(box, 0), 1))
    idx, tri, bary, dist = [], [], [], []
    first = 0
    while first < len(lay.uv):
        last = max(int(np.searchsorted(cum, (cum[first - 1] if first else 0) + CHUNK, "right")), first + 1)
        t, i, j = _pairs(lay.uv[first:last], lay.width, lay.height, reach)
        c = lay.uv[first:last][t]
        w, d = _closest_bary(np.stack([i + 0.5, j + 0.5], 1), c[:, 0], c[:, 1], c[:, 2])
        keep = d < reach
        idx.append((j * lay.width + i)[keep])
        tri.append(t[keep] + first)
        bary.append(w[keep])
        dist.append(d[keep])
        first = last
    idx, tri, bary, dist = map(np.concatenate, (idx, tri, bary, dist))
    order = np.lexsort((dist, idx))                  # per texel the nearest triangle first
    first = np.unique(idx[order], return_index=True)[1]
    pick = order[first]
    idx, tri, bary, inside = idx[pick], tri[pick], bary[pick], dist[pick] == 0
    pos = np.einsum("kc,kcx->kx", bary, lay.corners[tri])
    nrm = np.einsum("kc,kcx->kx", bary, lay.normals[tri])
    c = lay.corners[tri]
    geo = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    geo /= np.linalg.norm(geo, axis=1, keepdims=True)
    on = lay.spheres[tri, 3] > 0                      # a meshed sphere: its texels back on the sphere
    if on.any():
        r = pos[on] - lay.spheres[tri[on], :3]
        nrm[on] = geo[on] = r / np.linalg.norm(r, axis=1, keepdims=True)
        pos[on] = lay.spheres[tri[on], :3] + lay.spheres[tri[on], 3:4] * geo[on]
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    geo = np.where((geo * nrm).sum(1, keepdims=True) < 0, -geo, geo)     # the side the shading normal faces
    return Texels(idx, tri, bary, pos, nrm, geo, inside, on)
