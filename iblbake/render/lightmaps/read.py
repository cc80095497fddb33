"""Reading a lightmap at surface points (float64, numpy): the twin of the frame's reading
(kernels/lightmap.h, `effects.diffuse: lightmap`). A point of a lightmapped object finds its atlas
triangle (of the object's, the one it lies inside, or least outside: a point projected along the
triangle's normal onto its plane, a sphere's along its radius, the inverse of the bake putting a
meshed sphere's texels back on the sphere), its UV1 from the barycentrics, and the atlas bilinearly
there (texel centres at half-integers, as a GPU's linear filter; clamped at the edges): each of the four
texels' irradiance at the shading normal (clamped at 0), blended. A texel holds `basis`: the
irradiance as it is, the L1 SH (its irradiance at the normal), or a basis of the probes' registry
(core/bases/probes.py PROBE_BASES: its own float64 irradiance, bases.irradiance)."""

from __future__ import annotations

import numpy as np

from iblbake.errors import InputError
from iblbake.render.lightmaps import bases
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
        q = points[mine][:, None] - c[None, :, 0]                 # (p, t, 3)
        sphere = lay.spheres[tri, 3] > 0
        if sphere.any():              # along the radius: where the ray from the centre meets the facet
            centre = lay.spheres[tri[0], :3]
            d = points[mine] - centre                                               # (p, 3)
            with np.errstate(divide="ignore", invalid="ignore"):
                s = np.einsum("tx,tx->t", n, c[:, 0] - centre)[None] / np.einsum("tx,px->pt", n, d)
            s = np.where(s > 0, s, np.nan)                       # not the facets behind the centre
            q = centre + s[..., None] * d[:, None] - c[None, :, 0]
            dist = np.abs(s - 1) * np.linalg.norm(d, axis=1)[:, None]
        else:                         # along the normal
            nn = n / np.linalg.norm(n, axis=1, keepdims=True)
            h = np.einsum("ptx,tx->pt", q, nn)
            q = q - np.einsum("pt,tx->ptx", h, nn)
            dist = np.abs(h)
        d00, d01, d11 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
        d20, d21 = np.einsum("ptx,tx->pt", q, e1), np.einsum("ptx,tx->pt", q, e2)
        den = d00 * d11 - d01 * d01
        b1 = (d11 * d20 - d01 * d21) / den
        b2 = (d00 * d21 - d01 * d20) / den
        out = np.maximum(0, -np.minimum(np.minimum(b1, b2), 1 - b1 - b2))    # how far outside
        # inside (or least outside) first, then the nearest plane: a point of a room's floor lies
        # inside a wall's triangle projected along the wall's normal too; a chart facing away from
        # the normal last (a two-sided surface's other side)
        back = 0.0 if normals is None else np.einsum("px,tx->pt", normals[mine], n) < 0
        rank = np.where(np.isfinite(out), out * 1e3 + dist + back * 1e6, np.inf)
        best = np.argmin(rank, axis=1)
        p = np.arange(len(mine))
        bb1, bb2 = np.clip(b1[p, best], 0, 1), np.clip(b2[p, best], 0, 1)
        s = np.maximum(bb1 + bb2, 1.0)
        bb1, bb2 = bb1 / s, bb2 / s
        u = lay.uv[tri[best]]
        uv[mine] = (1 - bb1 - bb2)[:, None] * u[:, 0] + bb1[:, None] * u[:, 1] + bb2[:, None] * u[:, 2]
    return uv, np.isfinite(uv[:, 0])


def bilinear_taps(shape, uv):
    """The four texels (flat indices (n, 4)) around texel coordinates uv (n, 2) and their bilinear
    weights (n, 4): centres at half-integers, clamped at the edges."""
    h, w = shape
    x, y = uv[:, 0] - 0.5, uv[:, 1] - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    taps, weights = [], []
    for dx, dy, wgt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        taps.append(np.clip(y0 + dy, 0, h - 1) * w + np.clip(x0 + dx, 0, w - 1))
        weights.append(wgt)
    return np.stack(taps, 1), np.stack(weights, 1)


def bilinear(atlas, uv):
    """The atlas (h, w, ...) at texel coordinates uv (n, 2), bilinear, clamped at the edges."""
    taps, weights = bilinear_taps(atlas.shape[:2], uv)
    flat = atlas.reshape(-1, *atlas.shape[2:])
    shape = (-1,) + (1,) * (atlas.ndim - 2)
    return sum(weights[:, k].reshape(shape) * flat[taps[:, k]] for k in range(4))


def texel_irradiance(lm: dict, basis: str, texels, normals, opts: dict):
    """The irradiance (n, 3) of atlas texels (flat indices (n,)) at unit normals (n, 3), clamped at 0."""
    if basis == "irradiance":
        return np.maximum(0.0, lm["irradiance"].reshape(-1, 3)[texels])
    h, w = lm["layout"].height, lm["layout"].width
    coeffs = np.asarray(lm[basis], np.float64).reshape(h * w, -1, 3)[texels]
    return bases.irradiance(basis, coeffs, normals, opts)


def irradiance(lm: dict, objects, points, normals, basis: str | None = None, opts: dict | None = None):
    """(E (n, 3), found (n,)) at points on objects with shading normals, from a baked lightmap
    (bake.bake()'s dict) read as `basis`: 'irradiance' (every bake holds it) or the bake's own basis
    (lm['basis'], the default; its options lm['options'] unless `opts`), on the side the normals face."""
    basis = basis or lm["basis"]
    if basis != "irradiance" and basis not in lm:
        raise InputError(f"lightmap.basis: this lightmap holds {lm['basis']!r}, not {basis!r}; bake it with "
                         f"lightmap.basis: {basis}")
    opts = lm["options"] if opts is None else opts
    uv, found = atlas_uv(lm["layout"], objects, points, normals)
    e = np.zeros((len(points), 3))
    if found.any():
        taps, weights = bilinear_taps((lm["layout"].height, lm["layout"].width), uv[found])
        e[found] = sum(weights[:, k, None] * texel_irradiance(lm, basis, taps[:, k], normals[found], opts)
                       for k in range(4))
    return e, found


def specular(lm: dict, objects, points, normals, axes, lam_w):
    """(the radiance (n, 3) along the warped GGX lobes about world directions axes (n, 3) of
    sharpness lam_w (n,), found (n,)) at points on objects with shading normals, from the bake's
    second set for the lobe (lm['specular'], lm['specular_options']; `specular: lightmap`): each of
    the four texels around the UV1 its basis's weighted sum clamped at 0 (core/bases
    specular_radiance), blended bilinearly (kernels/lightmap.h lightmap_specular)."""
    from iblbake.core.bases.probes import PROBE_BASES
    if "specular" not in lm:
        raise InputError("lightmap: this lightmap holds no set for the specular lobe; bake it for a frame of "
                         "effects.specular: lightmap")
    lay, opts = lm["layout"], lm["specular_options"]
    uv, found = atlas_uv(lay, objects, points, normals)
    li = np.zeros((len(points), 3))
    if found.any():
        taps, weights = bilinear_taps((lay.height, lay.width), uv[found])
        s = PROBE_BASES[lm["basis"]].m.specular_weights(axes[found], lam_w[found], opts)        # (m, floats)
        sets = np.asarray(lm["specular"], np.float64).reshape(lay.height * lay.width, -1, 3)
        li[found] = sum(weights[:, k, None] * np.maximum(0.0, np.einsum("mf,mfc->mc", s, sets[taps[:, k]]))
                        for k in range(4))
    return li, found


def hit_objects(gb, arrays):
    """The object index of each sample of a twin G-buffer (render/twin/gbuffer.py), -1 where it misses."""
    from iblbake.scene.layout import PRIM_KINDS
    obj = np.full(len(gb["hit"]), -1)
    for kind, recs, col in (("sphere", arrays.spheres, 1), ("triangle", arrays.tris, 3), ("plane", arrays.planes, 3)):
        sel = gb["hit"] & (gb["kind"] == PRIM_KINDS[kind])
        if sel.any():
            obj[sel] = np.asarray(recs[gb["index"][sel], 1, col], np.float32).view(np.int32)
    return obj


def diffuse_frame(sc, arrays, lm: dict, shape, basis: str | None = None):
    """The lightmap's diffuse term (h, w, 4) of scene sc at its camera (one centred sample a pixel;
    the frame's diffuse weight, (1 - F(NoV)) (1 - metallic) base colour / pi, x E), alpha 1 where a
    lightmapped object is hit: the primary hits of the G-buffer's twin (render/twin/gbuffer.py) over
    the scene's records `arrays` (scene/pack.py), read as irradiance() reads them."""
    from iblbake.render.twin.gbuffer import primary
    from iblbake.render.twin.surface import diffuse_weight, surface

    h, w = shape
    gb = primary({**sc.data["camera"], "resolution": [w, h], "spp": 1}, arrays)
    obj = hit_objects(gb, arrays)
    e, found = irradiance(lm, obj, gb["pos"], gb["normal"], basis)
    _v, _n, nov, (base, metallic, _emissive, rough, f0, f90) = surface(gb, arrays)
    out = np.zeros((h * w, 4))
    # the frame's weight (kernels/surface.h diffuse_weight): a specular layer takes its Fresnel share
    # (window_room's clay sphere read x1.13 its reference under city with base colour x E / pi)
    out[gb["hit"], :3] = diffuse_weight(base, metallic, rough, f0, f90, nov) * e[gb["hit"]]
    out[:, 3] = found & gb["hit"]
    return out.reshape(h, w, 4)
