"""Ray-traced ambient occlusion (kernels/ao.cl). numpy twin, float64."""

from __future__ import annotations

import numpy as np

from iblbake.core import conventions
from iblbake.core import sampling
from iblbake.scene import layout
from iblbake.render.twin.gbuffer import occluded, ray_offset
from iblbake.render.twin.surface import facing_normal


def ambient_occlusion(gb, arrays, effects: dict):
    """Twin of kernels/ao.cl: per G-buffer sample (misses 1) the fraction of ao_samples
    cosine-weighted rays with no hit closer than ao_radius."""
    hit = gb["hit"]
    out = np.ones(len(hit))
    v = -gb["dir"][hit]
    n = facing_normal(gb["normal"][hit], v)
    origin = ray_offset(gb["pos"][hit], n, gb["dir"][hit], gb["t"][hit])
    t, b = conventions.tangent_frame(n)
    sid = np.flatnonzero(hit)
    seed = effects["reference"]["seed"] ^ layout.RANDOM_STREAMS["ao"]
    k_n = effects["ao_samples"]
    open_ = np.zeros(len(sid))
    for k in range(k_n):
        l = sampling.sample_cosine_hemisphere(sampling.Sampler(seed, sid, k).next_2d())
        d = t * l[:, 0:1] + b * l[:, 1:2] + n * l[:, 2:3]
        open_ += ~occluded(origin, d, arrays, effects["ao_radius"])
    out[hit] = open_ / k_n
    return out
