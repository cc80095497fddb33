"""The G-buffer (kernels/gbuffer.cl, kernels/scene.h): primary rays by brute force (every ray
against every sphere, plane and triangle), any-hit occlusion, and the surface coordinates of
textured hits (texture coordinates, tangents, footprints; cut-outs and single-sided surfaces). numpy twin, float64."""

from __future__ import annotations

import math

import numpy as np

from iblbake.core import conventions
from iblbake.scene.layout import PRIM_KINDS
from iblbake.scene.pack import camera_vectors, pixel_jitter

SPHERE, PLANE, TRIANGLE = (PRIM_KINDS[k] for k in ("sphere", "plane", "triangle"))


def _sphere_t(o, d, sp):
    """Nearest t > 0 of rays o + t d with sphere record sp (inf where none)."""
    lo, hi = _sphere_roots(o, d, sp)
    return np.where(lo > 0, lo, np.where(hi > 0, hi, np.inf))


def _plane_t(o, d, pl):
    p0, nrm, tt, bb = pl[0, :3], pl[1, :3], pl[2, :3], pl[3, :3]
    den = d @ nrm
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((p0 - o) @ nrm) / den
        q = o + t[..., None] * d - p0
    inside = (np.abs(q @ tt) <= pl[2, 3]) & (np.abs(q @ bb) <= pl[3, 3])
    return np.where((np.abs(den) >= 1e-20) & (t > 0) & inside, t, np.inf)


def _triangle_t(o, d, tri):
    """(t, u, v) of rays with one triangle record (Moller-Trumbore, float64)."""
    v0 = tri[0, :3]
    e1, e2 = tri[1, :3] - v0, tri[2, :3] - v0
    p = np.cross(d, e2)
    det = p @ e1
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        sv = o - v0
        u = (sv * p).sum(-1) * inv
        qv = np.cross(sv, e1)
        v = (d * qv).sum(-1) * inv
        t = (qv @ e2) * inv
    ok = (det != 0) & (u >= 0) & (u <= 1) & (v >= 0) & (u + v <= 1) & (t > 0)
    return np.where(ok, t, np.inf), u, v


def occluded(o, d, arrays, tmax=np.inf):
    """Any hit along o + t d, 0 < t < tmax (twin of kernels/scene.h occluded, occluded_to): a
    boolean per ray."""
    hit = np.zeros(np.broadcast_shapes(o.shape, d.shape)[:-1], bool)
    for sp in arrays.spheres.astype(np.float64):
        hit |= _sphere_t(o, d, sp) < tmax
    for pl in arrays.planes.astype(np.float64):
        hit |= _plane_t(o, d, pl) < tmax
    for tri in arrays.tris.astype(np.float64):
        hit |= _triangle_t(o, d, tri)[0] < tmax
    return hit


def ray_offset(p, n, d, t):
    """Twin of kernels/scene.h ray_offset: off the surface, towards the viewer, relative to |p| + t."""
    eps = 1e-5 * (np.abs(p).max(-1) + t)
    return p + eps[..., None] * (n - d)


def _sphere_roots(o, d, sp):
    """Both roots t0 <= t1 of rays with a sphere (inf where it is missed): the stable quadratic."""
    c, r = sp[0, :3], sp[0, 3]
    f = o - c
    b = -(f * d).sum(-1)
    perp = f + b[..., None] * d
    disc = r * r - (perp ** 2).sum(-1)
    q = b + np.copysign(np.sqrt(np.maximum(disc, 0)), b)
    cc = (f ** 2).sum(-1) - r * r
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = np.where(q != 0, cc / q, 0.0)
    lo, hi = np.minimum(t0, q), np.maximum(t0, q)
    miss = disc < 0
    return np.where(miss, np.inf, lo), np.where(miss, np.inf, hi)


def primary(cam: dict, arrays, tex=None):
    """Hit records per sample (pixel-major, spp-minor, like the kernel): position, distance,
    shading normal towards the viewer, material, and what was hit (kind: layout.PRIM_KINDS, sphere, plane or
    triangle; its index; a triangle's barycentrics of v1, v2). With `tex` (textures()) a material's
    cut-outs and back faces are not hit, as kernels/scene.h surface_present."""
    w, h = cam["resolution"]
    spp = cam["spp"]
    pos, fwd, right, up, ortho = camera_vectors(cam)
    jit = pixel_jitter(spp)
    px = np.arange(w * h * spp)
    s, pix = px % spp, px // spp
    sx = 2.0 * ((pix % w) + jit[s, 0]) / w - 1.0
    sy = 1.0 - 2.0 * ((pix // w) + jit[s, 1]) / h
    if ortho:
        o = pos + sx[:, None] * right + sy[:, None] * up
        d = np.broadcast_to(fwd, o.shape).copy()
    else:
        d = fwd + sx[:, None] * right + sy[:, None] * up
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        o = np.broadcast_to(pos, d.shape).copy()
    n = len(d)
    t_best = np.full(n, np.inf)
    ng = np.zeros((n, 3))
    ns = np.zeros((n, 3))
    mat = np.full(n, -1)
    kind, index, bary = np.zeros(n, np.int64), np.full(n, -1), np.zeros((n, 2))
    ints = lambda a: np.asarray(a, np.float32).view(np.int32)
    present = (lambda k, i, t, b: _present(k, i, o, d, t, b, arrays, tex)) if tex is not None else None
    for i, sp in enumerate(arrays.spheres.astype(np.float64)):
        t0, t1 = _sphere_roots(o, d, sp)
        t = np.where(t0 > 0, t0, t1)
        if present is not None:            # the near side cut out or a back face: the far side
            t = np.where(present(1, i, np.where(np.isfinite(t), t, 0), None) | ~np.isfinite(t), t,
                         np.where(t1 > t, t1, np.inf))
            t = np.where(np.isfinite(t) & present(1, i, np.where(np.isfinite(t), t, 0), None), t, np.inf)
        t = np.where(t > 0, t, np.inf)
        better = t < t_best
        t_best[better] = t[better]
        c, r = sp[0, :3], sp[0, 3]
        nn = (o[better] + t[better, None] * d[better] - c) / r
        ng[better] = ns[better] = nn / np.linalg.norm(nn, axis=1, keepdims=True)
        mat[better] = ints(sp[1, 0])
        kind[better], index[better] = SPHERE, i
    for i, pl in enumerate(arrays.planes.astype(np.float64)):
        t = _plane_t(o, d, pl)
        if present is not None:
            t = np.where(np.isfinite(t) & present(2, i, np.where(np.isfinite(t), t, 0), None), t, np.inf)
        better = t < t_best
        t_best[better] = t[better]
        ng[better] = ns[better] = pl[1, :3]
        mat[better] = ints(pl[0, 3])
        kind[better], index[better] = PLANE, i
    tris = arrays.tris.astype(np.float64)
    for k in range(len(tris)):
        t, u, v = _triangle_t(o, d, tris[k])
        if present is not None:
            fin = np.isfinite(t)
            t = np.where(fin & present(3, k, np.where(fin, t, 0), np.stack([u, v], 1)), t, np.inf)
        better = t < t_best
        if not better.any():
            continue
        t_best[better] = t[better]
        v0 = tris[k, 0, :3]
        fn = np.cross(tris[k, 1, :3] - v0, tris[k, 2, :3] - v0)
        fn /= np.linalg.norm(fn)
        b0 = 1 - u[better] - v[better]
        sn = b0[:, None] * tris[k, 3, :3] + u[better, None] * tris[k, 4, :3] + v[better, None] * tris[k, 5, :3]
        ln = np.linalg.norm(sn, axis=1, keepdims=True)
        sn = np.where(ln > 1e-12, sn / np.maximum(ln, 1e-300), fn)
        sn = np.where((sn @ fn)[:, None] < 0, -sn, sn)
        ng[better] = fn
        ns[better] = sn
        mat[better] = ints(tris[k, 0, 3])
        kind[better], index[better] = TRIANGLE, k
        bary[better] = np.stack([u[better], v[better]], 1)
    hit = np.isfinite(t_best)
    flip = ((ng * d).sum(1) > 0)[:, None]
    ng_front = ng.copy()
    ng = np.where(flip, -ng, ng)
    ns_front = ns.copy()
    ns = np.where(flip, -ns, ns)
    return {"hit": hit, "t": t_best, "pos": o + np.where(hit, t_best, 0)[:, None] * d, "normal": ns,
            "material": mat, "dir": d, "kind": kind, "index": index, "bary": bary, "flip": flip[:, 0],
            "geometric": ng, "front_normal": ns_front, "front_geometric": ng_front}

def textures(scene, arrays):
    """What the kernels read of the scene's textures: {"set": TextureSet, "slots", "mat_maps"},
    decoded and filtered by the same host code the renderer uses."""
    from iblbake.scene import materials, textures as scene_textures

    ts, slots = materials.load_textures(arrays.records, scene.source)
    _texels, levels, info = ts.arrays()
    return {"set": ts, "slots": slots, "mat_maps": materials.device_arrays(
        arrays.records, slots, scene_textures.sizes(levels, info))[1].astype(np.float64)}


def _hit_material(kind, index, p, arrays):
    """(material, front geometric normal) per ray of one primitive."""
    ints = lambda a: np.asarray(a, np.float32).view(np.int32)
    if kind == SPHERE:
        sp = arrays.spheres[index].astype(np.float64)
        g = (p - sp[0, :3]) / sp[0, 3]
        return int(ints(arrays.spheres[index, 1, 0])), g / np.linalg.norm(g, axis=-1, keepdims=True)
    if kind == PLANE:
        return int(ints(arrays.planes[index, 0, 3])), np.broadcast_to(arrays.planes[index, 1, :3].astype(np.float64), p.shape)
    tri = arrays.tris[index].astype(np.float64)
    fn = np.cross(tri[1, :3] - tri[0, :3], tri[2, :3] - tri[0, :3])
    return int(ints(arrays.tris[index, 0, 3])), np.broadcast_to(fn / np.linalg.norm(fn), p.shape)


def hit_texcoords(kind, index, p, bary, arrays):
    """(u0, v0, u1, v1) per ray of one primitive (kernels/scene.h hit_texcoords)."""
    if kind == SPHERE:
        sp = arrays.spheres[index].astype(np.float64)
        nl = (p - sp[0, :3]) / sp[0, 3]
        u, v = conventions.equirect_uv_from_dir(nl)
        return np.stack([u, v, u, v], 1)
    if kind == PLANE:
        pl = arrays.planes[index].astype(np.float64)
        q = p - pl[0, :3]
        a, b = q @ pl[2, :3], q @ pl[3, :3]
        u = a if np.isinf(pl[2, 3]) else 0.5 + 0.5 * a / pl[2, 3]
        v = -b if np.isinf(pl[3, 3]) else 0.5 - 0.5 * b / pl[3, 3]
        return np.stack([u, v, u, v], 1)
    at = arrays.tri_attr[index].astype(np.float64)
    b1, b2 = bary[:, 0:1], bary[:, 1:2]
    return (1 - b1 - b2) * at[0] + b1 * at[1] + b2 * at[2]


def _slot(tex, m, kind):
    """(texture, UV set, KHR_texture_transform's 2 x 3 rows, mip level offset) of a material's map
    slot (kernels/texture.h map_slot, map_uv, map_lod)."""
    from iblbake.scene.layout import MAP_KINDS
    k = MAP_KINDS.index(kind)
    rows = tex["mat_maps"][m, 2 + 3 * k:5 + 3 * k]
    texture = int(np.asarray(rows[0, 3], np.float32).view(np.int32))
    texcoord = int(np.asarray(rows[1, 3], np.float32).view(np.int32))
    return texture, texcoord, rows[:2, :3], rows[2, 0]


def map_uv(rows, texcoord, uv01):
    uv = uv01[:, 2:4] if texcoord == 1 else uv01[:, 0:2]
    return uv @ rows[:, :2].T + rows[:, 2]


def _present(kind, index, o, d, t, bary, arrays, tex):
    """Whether each ray's candidate hit on one primitive is there (kernels/scene.h surface_present)."""
    from iblbake.scene import textures as scene_textures

    p = o + t[:, None] * d
    m, g = _hit_material(kind, index, p, arrays)
    mm = tex["mat_maps"][m]
    ok = np.ones(len(t), bool)
    if mm[1, 0] > 0.5:
        ok &= (g * d).sum(1) <= 0
    if mm[0, 1] >= 0:
        alpha = np.full(len(t), mm[0, 0])
        texture, texcoord, rows, _lod = _slot(tex, m, "base_color")
        if texture >= 0:
            uv = map_uv(rows, texcoord, hit_texcoords(kind, index, p, bary, arrays))
            alpha = alpha * scene_textures.sample(tex["set"].textures[texture], uv, np.zeros(len(t)))[:, 3]
        ok &= alpha >= mm[0, 1]
    return ok


def gbuffer_coords(gb, arrays, cam):
    """The texture coordinates, tangent (w: the bitangent's side, negated with the tangent on a
    back face) and footprint level of each set at every hit (kernels/gbuffer.cl hit_tangent)."""
    hit = gb["hit"]
    n = len(hit)
    uv, tan, lod = np.zeros((n, 4)), np.zeros((n, 4)), np.zeros((n, 2))
    _pos, _fwd, _right, up, ortho = camera_vectors(cam)
    pixel = 2 * np.linalg.norm(up) / (cam["resolution"][1] * math.sqrt(cam["spp"]))
    for kind in (SPHERE, PLANE, TRIANGLE):
        for index in np.unique(gb["index"][hit & (gb["kind"] == kind)]):
            sel = hit & (gb["kind"] == kind) & (gb["index"] == index)
            p, ns, bary = gb["pos"][sel], gb["front_normal"][sel], gb["bary"][sel]
            uv[sel] = hit_texcoords(kind, index, p, bary, arrays)
            if kind == SPHERE:
                sp = arrays.spheres[index].astype(np.float64)
                nl = (p - sp[0, :3]) / sp[0, 3]
                t = np.stack([-nl[:, 2], np.zeros(len(p)), nl[:, 0]], 1)
                w = -np.ones(len(p))
                st = np.maximum(np.sqrt(np.maximum(0, 1 - nl[:, 1] ** 2)), 1e-4)
                dens = np.repeat((-0.5 * np.log2(2 * np.pi ** 2 * sp[0, 3] ** 2 * st))[:, None], 2, 1)
            elif kind == PLANE:
                pl = arrays.planes[index].astype(np.float64)
                t = np.broadcast_to(pl[2, :3], p.shape).copy()
                w = -np.ones(len(p))
                dd = (0.0 if np.isinf(pl[2, 3]) else -np.log2(2 * pl[2, 3])) + \
                     (0.0 if np.isinf(pl[3, 3]) else -np.log2(2 * pl[3, 3]))
                dens = np.full((len(p), 2), 0.5 * dd)
            else:
                at = arrays.tri_attr[index].astype(np.float64)
                b1, b2 = bary[:, 0:1], bary[:, 1:2]
                t = ((1 - b1 - b2) * at[3] + b1 * at[4] + b2 * at[5])[:, :3]
                w = np.full(len(p), -1.0 if at[3, 3] < 0 else 1.0)
                dens = np.broadcast_to(at[6, :2], (len(p), 2))
            t = t - ns * (ns * t).sum(1, keepdims=True)
            lt = np.linalg.norm(t, axis=1, keepdims=True)
            frame = conventions.tangent_frame(ns)[0]
            t = np.where(lt > 1e-12, t / np.maximum(lt, 1e-300), frame)
            flip = gb["flip"][sel][:, None]
            tan[sel] = np.concatenate([np.where(flip, -t, t), np.where(flip[:, 0], -w, w)[:, None]], 1)
            cone = pixel if ortho else pixel * gb["t"][sel]
            cos = np.abs((gb["front_geometric"][sel] * gb["dir"][sel]).sum(1))
            lod[sel] = np.log2(cone / np.maximum(cos, 1e-6))[:, None] + dens
    gb.update(uv=uv, tangent=tan, lod=lod)
    return gb
