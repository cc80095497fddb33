"""The GGX-prefiltered chain's numpy twins and oracle: filtered importance sampling (twin of
kernels/mips.cl `prefilter`), the deterministic convolution (twin of `convolve`), and the float64
brute force over every source texel with exact solid angles. The spectral method is spectral.py."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from iblbake.core import brdf, conventions, sampling
from iblbake.bake import radiance


# `convolve` reads a chain level with texels this many times smaller than the lobe's angular scale
TEXELS_PER_LOBE = 12.0  # measured at face 256 on city, r = 0.5: 6 -> 1.05%, 12 -> 0.20%, 24 -> 0.04%


@dataclass
class SampleSet:
    """Accepted reflected directions of one roughness in the local frame (z = n = v), with
    log2 of each one's solid angle 1 / (N pdf(l)); float32 rows for the kernel."""
    rows: np.ndarray   # (M, 4): l.x, l.y, l.z (= NoL), log2(Omega_s)
    total: int         # N, the Hammersley count (M <= N accepted)


def ggx_sample_set(alpha: float, n: int) -> SampleSet:
    """N Hammersley points warped to GGX half-vectors, reflected about h with v = n:
    l = 2 (n.h) h - n; pdf(l) = D(h) NoH / (4 VoH) = D(h) / 4 (NoH = VoH when v = n)."""
    h = sampling.sample_ggx_half(sampling.hammersley(n), alpha)
    noh = h[:, 2]
    l = 2.0 * noh[:, None] * h - np.array([0.0, 0.0, 1.0])
    keep = l[:, 2] > 0
    pdf = sampling.pdf_ggx_reflected(noh, noh, alpha)
    log2_omega = -np.log2(n * np.maximum(pdf, 1e-30))
    rows = np.concatenate([l, log2_omega[:, None]], axis=1)[keep]
    return SampleSet(rows.astype(np.float32), n)


def prefilter_twin(chain, dirs, roughness: float, n_samples: int, lod_bias: float = 0.0,
                        fis: bool = True):
    """numpy twin of kernels/mips.cl:prefilter at output directions dirs (..., 3), float64."""
    dirs = np.asarray(dirs, dtype=np.float64)
    flat = dirs.reshape(-1, 3)
    if roughness == 0.0:
        return radiance.chain_lookup_twin(chain, flat, np.zeros(len(flat))).reshape(dirs.shape[:-1] + (-1,))
    s = ggx_sample_set(roughness * roughness, n_samples).rows.astype(np.float64)
    t, b = conventions.tangent_frame(flat)
    h0, w0 = chain[0].shape[:2]
    acc = np.zeros((len(flat), chain[0].shape[-1]))
    wsum = np.zeros(len(flat))
    for lx, ly, lz, log2_om in s:
        l = t * lx + b * ly + flat * lz
        l /= np.linalg.norm(l, axis=-1, keepdims=True)
        lod = (0.5 * (log2_om - np.log2(radiance.texel_solid_angle_at(w0, h0, l))) + lod_bias) if fis else np.zeros(len(l))
        acc += lz * radiance.chain_lookup_twin(chain, l, lod)
        wsum += lz
    return (acc / wsum[:, None]).reshape(dirs.shape[:-1] + (-1,))


def texel_subsamples(w: int, h: int, s: int):
    """Directions and exact solid angles of an s x s subdivision of every texel, grouped by texel:
    shapes (h*w, s*s, 3) and (h*w, s*s)."""
    d = conventions.equirect_texel_dirs(w * s, h * s).reshape(h, s, w, s, 3)
    om = conventions.equirect_solid_angles(w * s, h * s).reshape(h, s, w, s)
    return (d.transpose(0, 2, 1, 3, 4).reshape(h * w, s * s, 3),
            om.transpose(0, 2, 1, 3).reshape(h * w, s * s))


def prefilter_bruteforce(source, dirs, roughness: float, chunk: int | None = None, max_sub: int | None = None,
                         max_parts: float = 4e6, ndf: str = "ggx"):
    """The ground truth of a prefiltered texel: the integral over the sphere of the source (piecewise
    constant over its texels) against the lobe, sum L(w) D(h) NoL dOmega / sum D(h) NoL dOmega with
    h = normalize(n + w), NoL = n.w > 0 (the limit of Karis' NoL-weighted estimator, N = V = R).
    Every source texel takes part; each is split into s x s parts with exact solid angles, parts no
    wider than a quarter of the lobe's scale alpha nor than 0.05 rad (the midpoint rule on a wide
    lobe), s capped at max_sub (default: at most max_parts parts in all). float64.
    Roughness 0 is the mirror: the source read bilinearly at n. `ndf` charlie: the sheen lobe
    D_charlie(h) NoL instead (its ring just inside the horizon is as narrow as alpha)."""
    source = np.asarray(source, dtype=np.float64)
    dirs = np.asarray(dirs, dtype=np.float64)
    flat = dirs.reshape(-1, 3)
    if roughness == 0.0 and ndf == "ggx":
        u, v = conventions.equirect_uv_from_dir(flat)
        return conventions.bilinear_equirect(source, u, v).reshape(dirs.shape[:-1] + (-1,))
    h, w = source.shape[:2]
    alpha = roughness * roughness
    if max_sub is None:
        max_sub = max(1, int(math.sqrt(max_parts / (h * w))))
    sub = int(min(max_sub, max(1, math.ceil((math.pi / h) / min(0.25 * alpha, 0.05)))))
    src_dirs, d_omega = texel_subsamples(w, h, sub)
    values = source.reshape(-1, source.shape[-1])
    chunk = chunk or max(1, min(64, int(2e7 // (h * w * sub * sub))))
    out = np.empty((len(flat), values.shape[-1]))
    for i0 in range(0, len(flat), chunk):
        n = flat[i0:i0 + chunk]
        nol = np.einsum("cd,tsd->cts", n, src_dirs)              # (c, texels, parts)
        noh = np.sqrt(np.maximum(0.5 * (1.0 + nol), 0.0))         # n.h with h = (n + w)/|n + w|
        d = brdf.d_ggx(noh, alpha) if ndf == "ggx" else brdf.d_charlie(noh, alpha)
        wgt = (np.where(nol > 0, d * nol, 0.0) * d_omega).sum(-1)  # (c, texels)
        out[i0:i0 + chunk] = (wgt @ values) / wgt.sum(1, keepdims=True)
    return out.reshape(dirs.shape[:-1] + (-1,))


def lobe_cutoff(alpha: float, fraction: float = 1e-4) -> float:
    """cos of the angle between n and w beyond which D(h) NoL < fraction * its peak (capped at the
    horizon). D(theta_h)/D(0) = alpha^4 / (cos^2 theta_h (alpha^2 - 1) + 1)^2."""
    a2 = alpha * alpha
    target = a2 / math.sqrt(fraction)            # cos^2(th)(a2 - 1) + 1 at the cut
    if target >= 1.0:
        return 0.0
    cos2 = (target - 1.0) / (a2 - 1.0)
    theta_h = math.acos(math.sqrt(min(1.0, max(0.0, cos2))))
    return max(0.0, math.cos(min(2.0 * theta_h, math.pi / 2)))


def convolve_level_choice(chain_sizes, alpha: float, texels_per_lobe: float = TEXELS_PER_LOBE,
                          min_rows: int = 32):
    """(chain level index, sub-texel split): the coarsest level whose texels are texels_per_lobe
    times smaller than the lobe's angular scale (about 2 alpha in reflected directions) and that
    has at least min_rows rows; where even level 0 is too coarse, its texels are split s x s."""
    scale = 2.0 * alpha
    best = 0
    for k, (w, h) in enumerate(chain_sizes):
        if math.pi / h <= scale / texels_per_lobe and h >= min(min_rows, chain_sizes[0][1]):
            best = k
    h0 = chain_sizes[0][1]
    sub = 1 if best > 0 else max(1, math.ceil((math.pi / h0) * texels_per_lobe / scale))
    return best, sub


def convolve_cost(chain_sizes, out_texels: int, alpha: float, texels_per_lobe: float = TEXELS_PER_LOBE) -> float:
    """Approximate weight evaluations of `convolve` for one level."""
    k, sub = convolve_level_choice(chain_sizes, alpha, texels_per_lobe)
    w, h = chain_sizes[k]
    cells = w * h * sub * sub
    cone = 2.0 * math.pi * (1.0 - lobe_cutoff(alpha))
    return out_texels * min(cells, cone * cells / (4 * math.pi) + 4 * h * sub)


def column_sin_cos(w: int):
    phi = 2.0 * np.pi * (0.5 - (np.arange(w) + 0.5) / w)
    return np.stack([np.sin(phi), np.cos(phi)], axis=-1)


def convolve_twin(chain, dirs, roughness: float, texels_per_lobe: float = TEXELS_PER_LOBE):
    """numpy twin of kernels/mips.cl:convolve (all texels, the same level, split and cone cut)."""
    alpha = roughness * roughness
    sizes = [(c.shape[1], c.shape[0]) for c in chain]
    k, sub = convolve_level_choice(sizes, alpha, texels_per_lobe)
    lvl = np.asarray(chain[k], np.float64)
    h, w = lvl.shape[:2]
    src, om = texel_subsamples(w, h, sub)
    src, om = src.reshape(-1, 3), om.reshape(-1)
    vals = np.repeat(lvl.reshape(-1, lvl.shape[-1]), sub * sub, axis=0)
    cut = lobe_cutoff(alpha)
    flat = np.asarray(dirs, np.float64).reshape(-1, 3)
    out = np.empty((len(flat), vals.shape[-1]))
    rows = twin_chunk(len(om))
    for i0 in range(0, len(flat), rows):
        c = flat[i0:i0 + rows] @ src.T
        wgt = np.where(c > cut, brdf.d_ggx(np.sqrt(0.5 * (1 + np.maximum(c, -1))), alpha) * c, 0.0) * om
        out[i0:i0 + rows] = (wgt @ vals) / wgt.sum(1, keepdims=True)
    return out.reshape(np.shape(dirs)[:-1] + (-1,))


# convolve_twin's host memory: per source cell its direction, solid angle and value (and
# texel_subsamples's copies of them while they are made), and per cell of a chunk of output
# texels the few float64 temporaries of the weights; the chunk is sized to TWIN_CHUNK_BYTES
TWIN_BYTES_PER_CELL = 136
TWIN_CHUNK_TEMPORARIES = 6
TWIN_CHUNK_BYTES = 1 << 27


def twin_chunk(cells: int) -> int:
    """Output texels a step of convolve_twin weighs at once: at most 128, at least 1."""
    return int(max(1, min(128, TWIN_CHUNK_BYTES // (8 * TWIN_CHUNK_TEMPORARIES * max(cells, 1)))))


def convolve_twin_bytes(chain_sizes, alpha: float, texels_per_lobe: float = TEXELS_PER_LOBE) -> int:
    """Host bytes convolve_twin takes for one level (the sub-texel grid sharp lobes need)."""
    k, sub = convolve_level_choice(chain_sizes, alpha, texels_per_lobe)
    w, h = chain_sizes[k]
    cells = w * h * sub * sub
    return TWIN_BYTES_PER_CELL * cells + 8 * TWIN_CHUNK_TEMPORARIES * cells * twin_chunk(cells)
