"""Dilation (render/probes): the off probes' irradiance filled from the active ones around them, as
Unity's Adaptive Probe Volumes dilate valid probes into invalid ones, so that an engine sampling the
exported atlases without the states (probe_data's alpha) reads no black probe inside geometry nor a
sky leaked through a wall. The frames here skip off probes (kernels/probes.h): dilation changes what
an engine reads, not what iblbake renders."""

from __future__ import annotations

import itertools

import numpy as np

from iblbake.render.probes.project import atlas

NEIGHBOURS = np.array([d for d in itertools.product((-1, 0, 1), repeat=3) if any(d)])


def dilate_values(values, off, counts):
    """values (probes, ...) by probe index with the `off` probes' rows replaced, pass by pass, by
    their filled neighbours' mean (the 26 around, each weighted by its inverse square distance in
    cells: Unity's squared-distance weighting): the first pass reads the active probes only, each
    later one those filled before it too, until every off probe with an active probe in reach is
    filled (one with none keeps its values)."""
    from iblbake.render.twin import probes as twin

    out = np.array(values, np.float64, copy=True)
    filled = ~np.asarray(off, bool)
    if filled.all() or not filled.any():
        return out
    counts = np.asarray(counts)
    coords = twin.probe_coords(np.arange(len(out)), counts)
    weights = 1.0 / (NEIGHBOURS ** 2).sum(1)
    while True:
        todo = np.nonzero(~filled)[0]
        total = np.zeros((len(todo),) + out.shape[1:])
        wsum = np.zeros(len(todo))
        for d, w in zip(NEIGHBOURS, weights):
            c = coords[todo] + d
            ok = ((c >= 0) & (c < counts)).all(1)
            j = twin.probe_index(np.where(ok[:, None], c, 0), counts)
            use = ok & filled[j]
            total[use] += w * out[j[use]]
            wsum[use] += w
        got = wsum > 0
        if not got.any():
            return out
        out[todo[got]] = total[got] / wsum[got].reshape((-1,) + (1,) * (out.ndim - 1))
        filled[todo[got]] = True


def tiles_of(image, counts, texels: int):
    """An atlas's bordered tiles (probes, t, t, c) by probe index: the inverse of project.atlas."""
    nx, ny, nz = counts
    t = texels + 2
    return image.reshape(nz, t, ny, nx, t, -1).transpose(2, 0, 3, 1, 4, 5).reshape(nx * ny * nz, t, t, -1)


def dilate(irradiance, off, counts, representation: str, texels: int):
    """The volume's irradiance (an atlas of bordered tiles, or (probes, k, 3) coefficients, as its
    basis stores it: core/bases/probes.py) with the off probes' dilated (dilate_values), in its own
    dtype."""
    from iblbake.core.bases.probes import PROBE_BASES
    irr = np.asarray(irradiance)
    if not PROBE_BASES[representation].atlas:
        return dilate_values(irr, off, counts).astype(irr.dtype)
    tiles = dilate_values(tiles_of(irr, counts, texels), off, counts)
    return atlas(tiles, counts).astype(irr.dtype)
