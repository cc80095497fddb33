"""The split-sum DFG table (numpy twin of kernels/mips.cl `dfg`) and its bilinear lookup."""

from __future__ import annotations


import numpy as np

from iblbake.core import brdf, sampling


def dfg_twin(size: int, n_samples: int, multiscatter: bool = False):
    """numpy twin of kernels/mips.cl:dfg, shape (size, size, 2) indexed [roughness, NoV]."""
    grid = np.arange(size) / (size - 1)
    nov = np.maximum(grid, 1e-4)[None, :]
    r = grid[:, None]
    alpha = r * r
    u = sampling.hammersley(n_samples)
    a = np.zeros((size, size))
    b = np.zeros((size, size))
    vx, vz = np.sqrt(1.0 - nov * nov), nov
    for u0, u1 in u:
        hl = sampling.sample_ggx_half(np.array([u0, u1]), alpha)    # (size, 1, 3)
        hx, hz = hl[..., 0], hl[..., 2]   # v has no y component
        voh = vx * hx + vz * hz
        lz = 2.0 * voh * hz - vz
        nol = np.clip(lz, 0.0, 1.0)
        ok = (nol > 0) & (voh > 0)
        gv = 4.0 * brdf.v_smith_ggx_correlated(nov, nol, alpha) * nol * voh / np.maximum(hz, 1e-30)
        fc = (1.0 - np.clip(voh, 0, 1)) ** 5
        a += np.where(ok, gv * (1 - fc), 0.0)
        b += np.where(ok, gv * fc, 0.0)
    a /= n_samples
    b /= n_samples
    e = np.maximum(a + b, 1.0)   # the exact A + B is <= 1; the QMC estimate can overshoot by ~1e-4
    a, b = a / e, b / e
    out = np.stack([b, a + b] if multiscatter else [a, b], axis=-1)
    return out


def sheen_twin(size: int, n_samples: int):
    """numpy twin of kernels/mips.cl:dfg_sheen, shape (size, size) indexed [roughness, NoV]: the
    sheen albedo E = int D_charlie V_ashikhmin NoL dl, h uniform on the hemisphere (Filament's
    DFV_Charlie_Uniform)."""
    grid = np.arange(size) / (size - 1)
    nov = np.maximum(grid, 1e-4)[None, :]
    alpha = (grid * grid)[:, None]
    vx, vz = np.sqrt(1.0 - nov * nov), nov
    acc = np.zeros((size, size))
    for u0, u1 in sampling.hammersley(n_samples):
        cz = u0
        sz = np.sqrt(max(0.0, 1.0 - cz * cz))
        hx = sz * np.cos(2.0 * np.pi * u1)
        voh = vx * hx + vz * cz
        nol = 2.0 * voh * cz - vz
        ok = (nol > 0) & (voh > 0)
        acc += np.where(ok, brdf.v_ashikhmin(nov, nol) * brdf.d_charlie(cz, alpha) * nol * voh, 0.0)
    return acc * (8.0 * np.pi / n_samples)


def dfg_lookup(table, nov, roughness):
    """Bilinear lookup of a DFG table at (NoV, roughness) on its endpoint-inclusive grid."""
    n = table.shape[0]
    x = np.clip(np.asarray(nov, dtype=np.float64), 0, 1) * (n - 1)
    y = np.clip(np.asarray(roughness, dtype=np.float64), 0, 1) * (n - 1)
    x0 = np.minimum(np.floor(x).astype(int), n - 2)
    y0 = np.minimum(np.floor(y).astype(int), n - 2)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    t = table[y0, x0] * (1 - fx) + table[y0, x0 + 1] * fx
    bt = table[y0 + 1, x0] * (1 - fx) + table[y0 + 1, x0 + 1] * fx
    return t * (1 - fy) + bt * fy
