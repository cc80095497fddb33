"""The reference pass's integral (kernels/reference.cl), by quadrature: every texel of the
panorama (piecewise constant), split into s x s parts with exact solid angles, each direction
traced for occlusion unless visibility is off. numpy twin, float64."""

from __future__ import annotations

import numpy as np

from iblbake.core import brdf
from iblbake.core import conventions
from iblbake.bake import prefilter
from iblbake.scene.layout import DELTA_ALPHA
from iblbake.render.twin.gbuffer import occluded, ray_offset
from iblbake.render.twin.surface import diffuse_weight, material_occlusion, surface, to_env




def exact(gb, arrays, effects: dict, env: dict, image, sub: int = 2, chunk: int = 256):
    """What the `reference` pass converges to, by quadrature over the panorama's texels."""
    hit = gb["hit"]
    out = np.zeros((len(hit), 3))
    v, n, nov, (base, metallic, emissive, rough, f0, f90) = surface(gb, arrays)
    alpha = rough ** 2
    hgt, wid = image.shape[:2]
    dirs, omega = prefilter.texel_subsamples(wid, hgt, sub)
    dirs = conventions.rotate_y(dirs.reshape(-1, 3), env["rotation_y"])     # panorama -> world
    omega = omega.reshape(-1)
    radiance = np.repeat(image.reshape(-1, 3).astype(np.float64), sub * sub, axis=0) * env["intensity"]
    res = np.zeros((len(n), 3))
    kd = diffuse_weight(base, metallic, rough, f0, f90, nov)
    delta = alpha < DELTA_ALPHA
    visibility = effects["reference"]["visibility"]
    if visibility:
        origin = ray_offset(gb["pos"][hit], n, gb["dir"][hit], gb["t"][hit])
    for i0 in range(0, len(n), chunk):
        sl = slice(i0, i0 + chunk)
        nol = n[sl] @ dirs.T                                            # (c, dirs)
        w = np.where(nol > 0, nol, 0.0) * omega
        if visibility:
            w = np.where(occluded(origin[sl, None, :], dirs[None], arrays), 0.0, w)
        if effects["diffuse"] == "reference":
            res[sl] += kd[sl] * (w @ radiance)
        if effects["specular"] == "reference" and not delta[sl].all():
            hv = v[sl, None, :] + dirs[None]
            hv /= np.linalg.norm(hv, axis=2, keepdims=True)
            noh = (hv * n[sl, None, :]).sum(2)
            voh = (hv * v[sl, None, :]).sum(2)
            dv = brdf.d_ggx(noh, alpha[sl, None]) * brdf.v_smith_ggx_correlated(nov[sl, None], nol, alpha[sl, None])
            fw = (1 - np.clip(voh, 0, 1)) ** 5                          # Schlick: F0 + (F90 - F0) fw
            a = (dv * w) @ radiance
            bsum = (dv * w * fw) @ radiance
            res[sl] += np.where(delta[sl, None], 0.0, f0[sl] * a + (f90[sl] - f0[sl]) * bsum)
    if effects["specular"] == "reference" and delta.any():
        # a lobe narrower than float32 resolves (the kernel's DELTA_ALPHA) is a mirror: F(NoV) L(R),
        # L read as the kernel reads it (nearest texel)
        r = 2 * nov[delta, None] * n[delta] - v[delta]
        seen = ~occluded(origin[delta], r, arrays) if visibility else np.ones(len(r), bool)
        u, w = conventions.equirect_uv_from_dir(to_env(r, env["rotation_y"]))
        i = np.minimum((u * wid).astype(np.int64), wid - 1)
        j = np.minimum((w * hgt).astype(np.int64), hgt - 1)
        res[delta] += (image[j, i].astype(np.float64) * env["intensity"]
                       * brdf.f_schlick(nov[delta, None], f0[delta], f90[delta])) * seen[:, None]
    out[hit] = res * material_occlusion(gb)[:, None]      # the occlusion map: image-based light only
    return out
