"""Sizes and layouts of the mip chains.

- radiance chain: each level half the size of the one above, down to one row
- prefiltered chain: level k of K has roughness k/(K-1), in one of three layouts, every one
  from the same kernel code path (LAYOUT define):
  equirect 2s x s; cubemap faces +X -X +Y -Y +Z -Z of s x s stacked vertically (s x 6s);
  octahedral s x s with +y at the centre
"""

from __future__ import annotations


import math

import numpy as np

from iblbake.core import conventions


LAYOUT_IDS = {"equirect": 0, "cubemap": 1, "octahedral": 2}


MIN_LEVEL_SIZE = 8
MAX_LEVELS = 32          # a chain of at most this many levels (the command line's --levels too)


def radiance_chain_sizes(width: int, height: int):
    """(w, h) of every level: halving down to one row (and at least one column)."""
    sizes = [(width, height)]
    while sizes[-1][1] > 1:
        w, h = sizes[-1]
        sizes.append((max(1, w // 2), max(1, h // 2)))
    return sizes


def default_base_size(layout: str, src_height: int) -> int:
    """equirect: the source height; cubemap: half the source height (1024x512 -> face 256,
    matching texel density at the equator); octahedral: the source height."""
    return max(1, src_height // 2) if layout == "cubemap" else max(1, src_height)


def prefiltered_sizes(base: int, levels: int | None = None, min_size: int = MIN_LEVEL_SIZE):
    """Size parameter s of each level: base >> k, not below min_size (nor below 1). Default
    number of levels: one per halving from base down to min_size."""
    floor = max(1, min(min_size, base))
    if levels is None:
        levels, s = 1, base
        while s // 2 >= floor:
            s //= 2
            levels += 1
    return [max(floor, base >> k) for k in range(levels)]


# lobe-sized levels: a level's texel no wider than its lobe scale alpha / LOBE_TEXELS (the
# prefiltered function varies on the scale alpha; bilinear lookups between texel centres of a
# coarser level are off by up to 2% against the exact split sum at 3 texels per alpha)
LOBE_TEXELS = 16


def lobe_sizes(base: int, levels: int, min_size: int = MIN_LEVEL_SIZE, texels: float = LOBE_TEXELS):
    """Size s of each level (an equirect level is 2s x s) from its lobe: s >= texels pi / alpha_k
    rows, at most base (the mirror level) and at least min_size."""
    out = []
    for r in level_roughness(levels):
        a = r * r
        out.append(base if a == 0 else int(min(base, max(min(min_size, base), math.ceil(texels * math.pi / a)))))
    return out


def level_roughness(levels: int):
    """r_k = k / (K - 1): level 0 is the mirror, the last is roughness 1."""
    return [0.0] if levels == 1 else [k / (levels - 1) for k in range(levels)]


def layout_shape(layout: str, s: int):
    return {"equirect": (s, 2 * s), "cubemap": (6 * s, s), "octahedral": (s, s)}[layout]


def layout_dirs(layout: str, s: int):
    """Directions of the texel centres of one level, shaped like the stored image (H, W, 3)."""
    if layout == "equirect":
        return conventions.equirect_texel_dirs(2 * s, s)
    if layout == "cubemap":
        return conventions.cube_texel_dirs(s).reshape(6 * s, s, 3)
    return conventions.octahedral_texel_dirs(s)


def layout_solid_angles(layout: str, s: int):
    """Solid angle of each texel of one level (H, W); sums to 4 pi (octahedral: numerically)."""
    if layout == "equirect":
        return conventions.equirect_solid_angles(2 * s, s)
    if layout == "cubemap":
        return np.tile(conventions.cube_texel_solid_angles(s), (6, 1))
    # octahedral: Jacobian of the map by finite differences at texel centres, normalised to 4 pi
    d = conventions.octahedral_texel_dirs(s)
    du = np.gradient(d, axis=1)
    dv = np.gradient(d, axis=0)
    a = np.linalg.norm(np.cross(du, dv), axis=-1)
    return a * (4 * np.pi / a.sum())
