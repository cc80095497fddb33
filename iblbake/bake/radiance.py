"""The radiance mip chain (exact solid-angle-weighted box filter) and trilinear lookups in it:
the numpy twins of kernels/mips.cl `downsample` and kernels/envmap.h `chain_lookup`."""

from __future__ import annotations

import math

import numpy as np

from iblbake.core import conventions
from iblbake.bake import layouts


def _overlap_matrix(n_dst: int, n_src: int, polar: bool):
    """A[d, s] = measure of the overlap of destination cell d and source cell s on [0, 1]
    (polar: measured in cos(pi v), i.e. solid angle per unit azimuth)."""
    e_src = np.arange(n_src + 1) / n_src
    e_dst = np.arange(n_dst + 1) / n_dst
    lo = np.maximum(e_dst[:-1, None], e_src[None, :-1])
    hi = np.minimum(e_dst[1:, None], e_src[None, 1:])
    if polar:
        mid = np.minimum(lo + hi, 2.0 - lo - hi)
        w = 2.0 * np.sin(0.5 * np.pi * mid) * np.sin(0.5 * np.pi * np.maximum(hi - lo, 0.0))
    else:
        w = hi - lo
    return np.where(hi > lo, w, 0.0)


def downsample_twin(src, dw: int, dh: int):
    """numpy twin of kernels/mips.cl:downsample (float64)."""
    src = np.asarray(src, dtype=np.float64)
    sh, sw = src.shape[:2]
    rows = _overlap_matrix(dh, sh, polar=True)
    cols = _overlap_matrix(dw, sw, polar=False)
    # columns first, then rows: two small contractions (a single three-operand einsum is a
    # 4-deep loop, minutes at 1024x512)
    num = np.einsum("pj,jqc->pqc", rows, np.einsum("qi,jic->jqc", cols, src, optimize=True), optimize=True)
    den = rows.sum(1)[:, None] * cols.sum(1)[None, :]
    return num / den[..., None]


def radiance_chain_twin(image):
    chain = [np.asarray(image, dtype=np.float64)]
    for w, h in layouts.radiance_chain_sizes(image.shape[1], image.shape[0])[1:]:
        chain.append(downsample_twin(chain[-1], w, h))
    return chain


def solid_angle_mean(image, layout: str = "equirect", s: int | None = None):
    """Mean radiance weighted by texel solid angle (per channel)."""
    image = np.asarray(image, dtype=np.float64)
    if layout == "equirect":
        wgt = conventions.equirect_solid_angles(image.shape[1], image.shape[0])
    else:
        wgt = layouts.layout_solid_angles(layout, s)
    return (image * wgt[..., None]).sum((0, 1)) / wgt.sum()


def texel_solid_angle_at(chain0_w: int, chain0_h: int, dirs):
    """Solid angle density of level-0 equirect texels at each direction's latitude,
    (2 pi / W)(pi / H) sin(theta), floored at the polar row centre (continuous in the direction,
    so that the level choice does not jump at row boundaries)."""
    st = np.sqrt(np.maximum(0.0, 1.0 - np.asarray(dirs)[..., 1] ** 2))
    st = np.maximum(st, math.sin(0.5 * math.pi / chain0_h))
    return (2.0 * math.pi / chain0_w) * (math.pi / chain0_h) * st


def chain_lookup_twin(chain, dirs, lod):
    """numpy twin of chain_lookup: trilinear in the radiance chain."""
    u, v = conventions.equirect_uv_from_dir(dirs)
    # +-inf clamp to the ends; NaN (the 0/0 pdf of a delta lobe) reads level 0
    lod = np.asarray(lod, np.float64)
    lod = np.clip(np.where(np.isnan(lod), 0.0, lod), 0.0, len(chain) - 1)
    l0 = np.floor(lod).astype(np.int64)
    f = (lod - l0)[..., None]
    out = np.zeros(dirs.shape[:-1] + (chain[0].shape[-1],))
    for k in np.unique(l0):
        m = l0 == k
        a = conventions.bilinear_equirect(chain[k], u[m], v[m])
        b = conventions.bilinear_equirect(chain[min(k + 1, len(chain) - 1)], u[m], v[m])
        out[m] = a * (1 - f[m]) + b * f[m]
    return out


def to_rgba(image):
    image = np.asarray(image, dtype=np.float32)
    out = np.zeros(image.shape[:2] + (4,), np.float32)
    out[..., :3] = image[..., :3]
    return out
