"""The reference pass's integral (kernels/paths/reference.cl), by quadrature: every texel of the
panorama (piecewise constant), split into s x s parts with exact solid angles, each direction
traced for occlusion unless visibility is off. numpy twin, float64."""

from __future__ import annotations

import numpy as np

from iblbake.core import bsdf
from iblbake.core import conventions
from iblbake.bake import prefilter
from iblbake.render.twin.gbuffer import occluded, ray_offset
from iblbake.render.twin.surface import diffuse_weight, material_occlusion, surface, to_env


def exact(gb, arrays, effects: dict, env: dict, image, sub: int = 2, chunk: int = 256):
    """What the `reference` pass converges to, by quadrature over the panorama's texels: the
    paths' BSDF (core/bsdf.py, kernels/bsdf.h) of the terms asked for at every direction."""
    hit = gb["hit"]
    out = np.zeros((len(hit), 3))
    v, n, nov, (base, metallic, emissive, rough, f0, f90) = surface(gb, arrays)
    mt = bsdf.Material(f0, f90, rough ** 2, diffuse_weight(base, metallic, rough, f0, f90, nov))
    diffuse, specular = effects["diffuse"] == "reference", effects["specular"] == "reference"
    hgt, wid = image.shape[:2]
    dirs, omega = prefilter.texel_subsamples(wid, hgt, sub)
    dirs = conventions.rotate_y(dirs.reshape(-1, 3), env["rotation_y"])     # panorama -> world
    omega = omega.reshape(-1)
    radiance = np.repeat(image.reshape(-1, 3).astype(np.float64), sub * sub, axis=0) * env["intensity"]
    res = np.zeros((len(n), 3))
    visibility = effects["reference"]["visibility"]
    if visibility:
        origin = ray_offset(gb["pos"][hit], n, gb["dir"][hit], gb["t"][hit])
    chunk = max(1, min(chunk, 2 ** 21 // len(dirs)))       # (chunk, directions, 3) arrays of 48 MiB at most
    for i0 in range(0, len(n), chunk):
        sl = slice(i0, i0 + chunk)
        col = lambda a: a[sl, None]       # noqa: E731  vertices (c, 1) against directions (d,)
        f, _ = bsdf.evaluate(bsdf.Material(*(col(x) for x in mt)), col(v), col(n), col(nov), dirs, 0.5,
                             diffuse, specular)
        w = np.broadcast_to(omega, f.shape[:2])
        if visibility:
            w = np.where(occluded(origin[sl, None, :], dirs[None], arrays), 0.0, w)
        res[sl] += np.einsum("cdk,cd,dk->ck", f, w, radiance)
    delta = mt.alpha < bsdf.DELTA_ALPHA
    if specular and delta.any():
        # a mirror's delta lobe, which no texel's direction meets: its one direction R, weight
        # F(NoV), L read as the kernel reads it (nearest texel)
        md = bsdf.Material(*(x[delta] for x in mt))
        wgt, r, _ = bsdf.sample(md, v[delta], n[delta], nov[delta], 1.0, False, True, 0.0, np.zeros((delta.sum(), 2)))
        seen = ~occluded(origin[delta], r, arrays) if visibility else np.ones(len(r), bool)
        u, w = conventions.equirect_uv_from_dir(to_env(r, env["rotation_y"]))
        i = np.minimum((u * wid).astype(np.int64), wid - 1)
        j = np.minimum((w * hgt).astype(np.int64), hgt - 1)
        res[delta] += image[j, i, :3].astype(np.float64) * env["intensity"] * wgt * seen[:, None]
    out[hit] = res * material_occlusion(gb)[:, None]      # the occlusion map: image-based light only
    return out
