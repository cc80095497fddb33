"""The rays' projection (render/probes): each probe's traced rays into RTXGI's atlases (octahedral
irradiance tiles with their 1-texel borders, the distance moments), or into L2 SH irradiance, or
into a directional basis's radiance coefficients (core/bases/probes.py PROBE_BASES)."""

from __future__ import annotations

import numpy as np

from iblbake.core.bases.probes import PROBE_BASES
from iblbake.render.probes.grid import Grid
from iblbake.render.twin import probes as twin

BACKFACE_BLEND_LIMIT = 0.1       # a probe with this share of back-face rays blends no irradiance
MAX_DISTANCE = 1.5               # probeMaxRayDistance: 1.5 |spacing|, what a miss counts as


def with_borders(tiles: np.ndarray) -> np.ndarray:
    """Tiles (probes, n, n, c) with RTXGI's 1-texel octahedral border (ProbeBorderUpdateCS): each
    edge row and column the neighbouring interior one reversed, each corner the opposite interior
    corner, so that bilinear reads wrap across the octahedron's folds."""
    p, n = tiles.shape[:2]
    out = np.zeros((p, n + 2, n + 2, tiles.shape[3]), tiles.dtype)
    out[:, 1:-1, 1:-1] = tiles
    out[:, 0, 1:-1] = tiles[:, 0, ::-1]
    out[:, -1, 1:-1] = tiles[:, -1, ::-1]
    out[:, 1:-1, 0] = tiles[:, ::-1, 0]
    out[:, 1:-1, -1] = tiles[:, ::-1, -1]
    out[:, 0, 0], out[:, 0, -1] = tiles[:, -1, -1], tiles[:, -1, 0]
    out[:, -1, 0], out[:, -1, -1] = tiles[:, 0, -1], tiles[:, 0, 0]
    return out


def atlas(tiles: np.ndarray, counts) -> np.ndarray:
    """Bordered tiles (probes, t, t, c) laid out as RTXGI's atlas (DDGIGetProbeUV, y up)."""
    nx, ny, nz = counts
    t, c = tiles.shape[1], tiles.shape[3]
    # probe index gy nx nz + gz nx + gx: tiles as (gy, gz, gx); atlas rows gz, columns gy nx + gx
    return np.ascontiguousarray(tiles.reshape(ny, nz, nx, t, t, c).transpose(1, 3, 0, 2, 4, 5)
                                .reshape(nz * t, ny * nx * t, c))


def project(radiance, t, dirs, grid: Grid, settings: dict):
    """(irradiance, distance atlas) of every probe from its rays (DDGIProbeBlendingCS, to the mean
    over all rays): probe_values laid out as the volume stores them."""
    irr, moments = probe_values(radiance, t, dirs, grid.spacing, settings)
    return layout(irr, moments, grid, settings)


def layout(irr, moments, grid: Grid, settings: dict):
    """(irradiance, distance atlas) from probe_values' per-probe arrays: a basis with an atlas and
    the moments as RTXGI's bordered atlases, a directional basis's coefficients as they are."""
    if PROBE_BASES[settings["irradiance"]].atlas:
        irr = atlas(with_borders(irr), grid.counts)
    return irr, atlas(with_borders(moments), grid.counts)


def probe_values(radiance, t, dirs, spacing, settings: dict):
    """(irradiance, moments) of each probe from its rays, radiance (probes, rays, 3), t (probes,
    rays), dirs (rays, 3), every probe with the same directions. Irradiance at a texel's direction
    (probes, n, n, 3): pi times the cosine-weighted mean radiance
    of the rays that met no back face (RTXGI stores that over 2 pi and multiplies it back when
    sampling); a probe with BACKFACE_BLEND_LIMIT of back faces blends none. SH: the least-squares
    L2 fit of those rays' radiance (a field in the span, a uniform sky, is exact), convolved with
    the clamped cosine. Distance moments (probes, nd, nd, 2): weights cos^distance_exponent, the mean of min(|t|,
    1.5 |spacing|) and of its square over every ray (RTXGI halves both; the moments here are the
    means the Chebyshev test reads). A directional basis (core/bases/probes.py): its own project_rays
    on the same rays, back-face rays black: (probes, floats, 3) radiance coefficients."""
    p, r = t.shape
    front = (t >= 0).astype(np.float64)
    blends = (1 - front).mean(1) < BACKFACE_BLEND_LIMIT
    lit = radiance * front[..., None]
    lit_rows = lit.transpose(0, 2, 1).reshape(p * 3, r)            # one GEMM for every probe and colour
    basis = PROBE_BASES[settings["irradiance"]]
    if not basis.atlas:              # the basis's own fit on the rays (core/bases/probes.py), back faces black
        irr = basis.project_rays(lit, front, blends, dirs, basis.options(settings))
    else:
        n = settings["irradiance_texels"]
        w = np.maximum(0.0, twin.texel_directions(n) @ dirs.T)      # (texels, rays)
        num = (lit_rows @ w.T).reshape(p, 3, n * n).transpose(0, 2, 1)
        den = front @ w.T
        with np.errstate(invalid="ignore", divide="ignore"):
            e = np.where(den[..., None] > 0, np.pi * num / np.where(den > 0, den, 1)[..., None], 0.0)
        e[~blends] = 0.0
        # irradiance is >= 0: the panorama's tiny negative texels (environment.negative: keep) reach a
        # few rays, and read back a negative texel would fail the volume's check
        irr = np.maximum(e, 0.0).reshape(p, n, n, 3)
    nd = settings["distance_texels"]
    wd = np.maximum(0.0, twin.texel_directions(nd) @ dirs.T) ** settings["distance_exponent"]
    d = np.minimum(np.abs(t), MAX_DISTANCE * float(np.linalg.norm(spacing)))
    wsum = wd.sum(1)
    moments = np.stack([d @ wd.T, (d * d) @ wd.T], -1) / np.where(wsum > 0, wsum, 1)[None, :, None]
    return irr, moments.reshape(p, nd, nd, 2)
