"""Reading a lightmap at surface points (float64, numpy): the twin of what a real-time pass does with
a G-buffer's UV1 (not yet a kernel: docs/manual.md 'Lightmaps'). A point of a lightmapped object finds
its atlas triangle (the object's triangle whose plane holds it, projected along the triangle's normal:
exact for a mesh, the facet under the point for a meshed sphere), its UV1 from the barycentrics, and
the atlas bilinearly there (texel centres at half-integers, as a GPU's linear filter). The irradiance
at the point: the non-directional atlas as it is, or the L1 SH atlas at the shading normal."""

from __future__ import annotations

import numpy as np

from iblbake.render.lightmaps.bake import sh_irradiance
from iblbake.render.lightmaps.uv import Layout


def atlas_uv(lay: Layout, objects, points, normals=None):
    """(UV1 in texel units (n, 2), found (n,)) of points (n, 3) on objects (n,); with shading normals
    (n, 3), on the side they face (a two-sided surface has a chart a side, each wound to face its side)."""
    uv = np.full((len(points), 2), np.nan)
    for o in np.unique(objects):
        mine = np.flatnonzero(objects == o)
        tri = np.flatnonzero(lay.objects == o)
        if not len(tri) or not len(mine):
            continue
        c = lay.corners[tri]                                       # (t, 3, 3)
        e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
        n = np.cross(e1, e2)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        q = points[mine][:, None] - c[None, :, 0]                 # (p, t, 3)
        dist = np.abs(np.einsum("ptx,tx->pt", q, n))
        q = q - np.einsum("pt,tx->ptx", np.einsum("ptx,tx->pt", q, n), n)
        d00, d01, d11 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
        d20, d21 = np.einsum("ptx,tx->pt", q, e1), np.einsum("ptx,tx->pt", q, e2)
        den = d00 * d11 - d01 * d01
        b1 = (d11 * d20 - d01 * d21) / den
        b2 = (d00 * d21 - d01 * d20) / den
        out = np.maximum(0, -np.minimum(np.minimum(b1, b2), 1 - b1 - b2))    # how far outside
        back = 0.0 if normals is None else np.einsum("px,tx->pt", normals[mine], n) < 0
        best = np.argmin(out * 1e3 + dist + back * 1e6, axis=1)
        p = np.arange(len(mine))
        bb1, bb2 = np.clip(b1[p, best], 0, 1), np.clip(b2[p, best], 0, 1)
        s = np.maximum(bb1 + bb2, 1.0)
        bb1, bb2 = bb1 / s, bb2 / s
        u = lay.uv[tri[best]]
        uv[mine] = (1 - bb1 - bb2)[:, None] * u[:, 0] + bb1[:, None] * u[:, 1] + bb2[:, None] * u[:, 2]
    return uv, np.isfinite(uv[:, 0])


def bilinear(atlas, uv):
    """The atlas (h, w, ...) at texel coordinates uv (n, 2), bilinear, clamped at the edges."""
    h, w = atlas.shape[:2]
    x, y = uv[:, 0] - 0.5, uv[:, 1] - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    shape = (-1,) + (1,) * (atlas.ndim - 2)
    out = 0.0
    for dx, dy, wgt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        out = out + wgt.reshape(shape) * atlas[np.clip(y0 + dy, 0, h - 1), np.clip(x0 + dx, 0, w - 1)]
    return out


def irradiance(lm: dict, objects, points, normals, basis: str = "sh_l1"):
    """(E (n, 3), found (n,)) at points on objects with shading normals, from a baked lightmap
    (bake.bake()'s dict) in `basis` ('irradiance' or 'sh_l1')."""
    uv, found = atlas_uv(lm["layout"], objects, points, normals)
    e = np.zeros((len(points), 3))
    if found.any():
        if basis == "irradiance":
            e[found] = bilinear(lm["irradiance"], uv[found])
        else:
            e[found] = sh_irradiance(bilinear(lm["sh_l1"], uv[found]), normals[found])
    return e, found


def diffuse_frame(sc, arrays, lm: dict, shape, basis: str = "sh_l1"):
    """The lightmap's diffuse term (h, w, 4) of scene sc at its camera (one centred sample a pixel;
    the frame's diffuse weight, (1 - F(NoV)) (1 - metallic) base colour / pi, x E), alpha 1 where a
    lightmapped object is hit:
    the primary hits of the G-buffer's twin (render/twin/gbuffer.py) over the scene's records
    `arrays` (scene/pack.py), read as irradiance() reads them."""
    from iblbake.render.twin.gbuffer import primary
    from iblbake.render.twin.surface import diffuse_weight, surface
    from iblbake.scene.layout import PRIM_KINDS

    h, w = shape
    gb = primary({**sc.data["camera"], "resolution": [w, h], "spp": 1}, arrays)
    obj = np.full(len(gb["hit"]), -1)
    for kind, recs, col in (("sphere", arrays.spheres, 1), ("triangle", arrays.tris, 3), ("plane", arrays.planes, 3)):
        sel = gb["hit"] & (gb["kind"] == PRIM_KINDS[kind])
        if sel.any():
            obj[sel] = np.asarray(recs[gb["index"][sel], 1, col], np.float32).view(np.int32)
    e, found = irradiance(lm, obj, gb["pos"], gb["normal"], basis)
    _v, _n, nov, (base, metallic, _emissive, rough, f0, f90) = surface(gb, arrays)
    out = np.zeros((h * w, 4))
    # the frame's weight (kernels/surface.h diffuse_weight): a specular layer takes its Fresnel share
    # (window_room's clay sphere read x1.13 its reference under city with base colour x E / pi)
    out[gb["hit"], :3] = diffuse_weight(base, metallic, rough, f0, f90, nov) * e[gb["hit"]]
    out[:, 3] = found & gb["hit"]
    return out.reshape(h, w, 4)
