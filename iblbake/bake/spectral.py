"""The prefiltered chain as a spherical convolution, computed in the spherical-harmonic domain.

With N = V = R the lobe of Karis' NoL-weighted estimator depends only on the angle theta between
the output direction n and the light direction w:

    K(theta) = D(h) cos(theta) for theta < pi/2 (else 0),   n.h = cos(theta / 2),

so the prefiltered level is the convolution of the panorama with a zonal kernel, and by the
Funk-Hecke theorem its SH coefficients are those of the panorama times the kernel's Legendre
coefficients k_l = int K P_l / int K (k_0 = 1). That turns the sum over every source texel
(`convolve`) into one projection of the panorama, shared by every level, a product, and one
synthesis per level at that level's texel directions: exact to the tolerance below, at any
roughness whose k_l fall below it by l = MAX_LMAX (r >= 0.06 or so).

The projection integrates the panorama as the piecewise-constant image the reference sees: in
azimuth exactly (a texel's box integrates e^{i m phi} to its centre value times sinc(m dphi/2)),
in polar angle by Gauss-Legendre nodes inside every texel row (enough of them for the highest l).
The transforms are ducc0's (spherical harmonic transforms with arbitrary rings, and synthesis at
arbitrary points through a non-uniform FFT to a stated accuracy).
"""

from __future__ import annotations

import functools
import math
import os

import numpy as np

from iblbake.core import brdf
from iblbake.core import conventions

# k_l below this (relative to k_0 = 1) are dropped; measured against the float64 brute-force
# reference on city/studio/sunset at face 256: every level within 0.02% (1e-5 gave 0.01% too)
TOLERANCE = 1e-6
# the finest band the projection computes: beyond it a level falls back to `convolve` / `fis`
# (alm memory grows as MAX_LMAX^2: 2048 is 100 MB for RGB)
MAX_LMAX = 2048
# accuracy of the synthesis at arbitrary points (relative to the L2 norm of the level)
SYNTHESIS_EPSILON = 1e-7


def source_hash() -> str:
    """Part of the cache key of a prefiltered chain (this module computes its spectral levels)."""
    import hashlib
    with open(__file__, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def _threads() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _kernel_nodes(alpha: float):
    """Gauss-Legendre nodes in theta on [0, pi/2]: panels growing geometrically from a fraction of
    the lobe, none wider than 0.01 rad (P_2048 oscillates with period ~0.003)."""
    edges = [0.0]
    t = alpha / 16.0
    while t < 0.5 * math.pi:
        edges.append(t)
        t = min(1.4 * t, t + 0.01)
    edges.append(0.5 * math.pi)
    g, w = np.polynomial.legendre.leggauss(24)
    a, b = np.array(edges[:-1])[:, None], np.array(edges[1:])[:, None]
    return (0.5 * (b - a) * g + 0.5 * (a + b)).ravel(), (0.5 * (b - a) * w).ravel()


def _ring_nodes(alpha: float):
    """Gauss-Legendre nodes in theta on [0, pi/2] for the Charlie lobe, a ring just inside the
    horizon (K ~ e^((theta - pi/2) / (2 alpha)) cos(theta)): uniform panels no wider than
    alpha / 2 or 0.01 rad."""
    width = min(0.01, 0.5 * alpha)
    edges = np.linspace(0.0, 0.5 * math.pi, int(math.ceil(0.5 * math.pi / width)) + 1)
    g, w = np.polynomial.legendre.leggauss(24)
    a, b = edges[:-1, None], edges[1:, None]
    return (0.5 * (b - a) * g + 0.5 * (a + b)).ravel(), (0.5 * (b - a) * w).ravel()


NDFS = ("ggx", "charlie")
# Charlie's lobe ends in a kink at the horizon, so its k_l fall only as about l^-2: 1e-4 keeps the
# bands finite (l = 1480 at r = 0.07) and measured within 4.2e-4 relative RMSE of the float64 brute
# force on city (sun included) at r = 0.125 ... 1 (1e-5 gave 1.7e-4 at twice the bands)
CHARLIE_TOLERANCE = 1e-4


def tolerance(ndf: str) -> float:
    return TOLERANCE if ndf == "ggx" else CHARLIE_TOLERANCE


@functools.lru_cache(maxsize=64)
def zonal_coefficients(alpha: float, tol: float = TOLERANCE, max_lmax: int = MAX_LMAX, ndf: str = "ggx"):
    """The kernel's Legendre coefficients k_0..k_L (k_0 = 1) for alpha > 0, L the last band with
    |k_l| > tol; None where that band lies beyond max_lmax (the level is too sharp for this
    method). P_l by the three-term recurrence, integrals by quadrature in theta. Cached: the
    plan (applicable) and the bake ask for the same alphas. `ndf` charlie: the sheen lobe, K =
    D_charlie(h) cos(theta), the same N = V = R estimator (glTF-IBL-Sampler's and the glTF
    Sample Viewer's: h drawn from D (n.h), the weight NoL)."""
    theta, wq = _kernel_nodes(alpha) if ndf == "ggx" else _ring_nodes(alpha)
    x = np.cos(theta)
    d = brdf.d_ggx if ndf == "ggx" else brdf.d_charlie
    # the kernel times the measure sin(theta) dtheta
    kw = d(np.sqrt(0.5 * (1.0 + x)), alpha) * x * np.sin(theta) * wq
    k = [kw.sum()]
    p_prev, p = np.ones_like(x), x
    quiet = 0
    for l in range(1, max_lmax + 33):
        k.append(kw @ p)
        quiet = quiet + 1 if abs(k[-1]) <= tol * abs(k[0]) else 0
        if quiet == 32:   # the k_l envelope decays monotonically: 32 quiet bands in a row end it
            break
        p_prev, p = p, ((2 * l + 1) * x * p - l * p_prev) / (l + 1)
    k = np.array(k) / k[0]
    loud = np.nonzero(np.abs(k) > tol)[0]
    lmax = int(loud[-1]) if len(loud) else 0
    return k[:lmax + 1] if lmax <= max_lmax else None


def applicable(alpha: float, ndf: str = "ggx") -> bool:
    return alpha > 0.0 and zonal_coefficients(float(alpha), tolerance(ndf), ndf=ndf) is not None


def _alm_index(lmax_from: int, lmax_to: int):
    """Positions of the (l, m) of a band-limit lmax_to inside ducc0's m-major layout of lmax_from,
    and each one's l."""
    idx = [m * (2 * lmax_from + 1 - m) // 2 + np.arange(m, lmax_to + 1) for m in range(lmax_to + 1)]
    ls = [np.arange(m, lmax_to + 1) for m in range(lmax_to + 1)]
    return np.concatenate(idx), np.concatenate(ls)


def project_texels(image, lmax: int, nthreads: int | None = None):
    """SH coefficients (channels, (lmax+1)(lmax+2)/2), ducc0 layout) of the equirect image read
    as piecewise constant over its texels, frame theta = pi v, phi = 2 pi u (docs/conventions.md's u, v)."""
    import ducc0.sht.experimental as sht
    h, w, c = np.shape(image)
    dth, dph = math.pi / h, 2.0 * math.pi / w
    # Gauss nodes per row: the phase of P_lm across a row is about lmax * dth
    q = 2 + int(math.ceil(lmax * dth / math.pi))
    g, gw = np.polynomial.legendre.leggauss(q)
    rows = np.repeat(np.arange(h), q)
    theta = (rows + 0.5 + 0.5 * np.tile(g, h)) * dth
    weight = np.tile(gw, h) * 0.5 * dth * np.sin(theta) * dph
    # one float64 copy, channel-major (a 8192x4096 panorama is 0.8 GB of it)
    maps = np.ascontiguousarray(np.moveaxis(np.asarray(image), -1, 0), dtype=np.float64).reshape(c, 1, h * w)
    alm = sht.adjoint_synthesis(map=maps, theta=theta, lmax=lmax, spin=0, mmax=lmax,
                                nphi=np.full(len(theta), w, np.uintp),
                                phi0=np.full(len(theta), 0.5 * dph),
                                ringstart=(rows * w).astype(np.uintp), ringfactor=weight,
                                nthreads=nthreads or _threads())[:, 0, :]
    m = np.concatenate([np.full(lmax + 1 - mv, mv) for mv in range(lmax + 1)])
    return alm * np.sinc(m * dph / (2.0 * math.pi))   # np.sinc(x) = sin(pi x) / (pi x)


def synthesize(alm, lmax: int, dirs, nthreads: int | None = None):
    """Evaluate SH coefficients (channels, nalm) of band-limit lmax at unit directions (..., 3)."""
    import ducc0.sht.experimental as sht
    dirs = np.asarray(dirs, dtype=np.float64)
    u, v = conventions.equirect_uv_from_dir(dirs.reshape(-1, 3))
    loc = np.stack([math.pi * v, 2.0 * math.pi * u], axis=-1)
    out = [sht.synthesis_general(alm=alm[ch][None, :], spin=0, lmax=lmax, loc=loc, epsilon=SYNTHESIS_EPSILON,
                                 nthreads=nthreads or _threads())[0] for ch in range(alm.shape[0])]
    return np.stack(out, axis=-1).reshape(dirs.shape[:-1] + (alm.shape[0],))


def prefilter_levels(source, dirs_per_level, roughness, nthreads: int | None = None, ndf: str = "ggx"):
    """Prefiltered values (float64, shaped like each dirs[..., 3] with the source's channels) of
    every level, all roughness > 0 and applicable(); one projection serves every level."""
    # a channel equal to an earlier one (a reflection capture's coverage, stored as grey) is
    # projected and synthesised once: the same values, a third of the work for grey
    src = np.asarray(source)
    same = [next(j for j in range(i + 1) if np.array_equal(src[..., j], src[..., i])) for i in range(src.shape[-1])]
    distinct = sorted(set(same))
    if len(distinct) < len(same):
        cols = [distinct.index(j) for j in same]
        return [lv[..., cols] for lv in prefilter_levels(src[..., distinct], dirs_per_level, roughness, nthreads, ndf)]
    alphas = [float(r) * float(r) for r in roughness]   # as the plan asks: the same cache entries
    if not all(applicable(a, ndf) for a in alphas):
        raise ValueError("spectral: a level is too sharp for MAX_LMAX (use convolve or fis)")
    ks = [zonal_coefficients(a, tolerance(ndf), ndf=ndf) for a in alphas]
    lmax = max(len(k) - 1 for k in ks)
    alm = project_texels(source, lmax, nthreads)
    # the exact level is a mean of source texels with non-negative weights, so it lies within the
    # source's range per channel; the bands dropped below TOLERANCE ring by about that fraction
    # of the range (a lone 1e6 sun over black: -1e-3 far from it), which the clamp removes
    flat = np.asarray(source).reshape(-1, np.shape(source)[-1])
    lo, hi = flat.min(0).astype(np.float64), flat.max(0).astype(np.float64)
    out = []
    for k, dirs in zip(ks, dirs_per_level):
        idx, ls = _alm_index(lmax, len(k) - 1)
        out.append(np.clip(synthesize(alm[:, idx] * k[ls], len(k) - 1, dirs, nthreads), lo, hi))
    return out


def irradiance(source, dirs, lmax: int, nthreads: int | None = None):
    """E(n) = int L(w) max(0, n.w) dw at unit directions `dirs` (..., 3), float64 with the
    source's channels: the panorama's SH to band lmax times the clamped cosine's Ahat_l
    (Funk-Hecke), synthesised there. The truncation at lmax is the only approximation (Ahat_l
    falls as l^-5/2; the kink at a sun's terminator converges slowest)."""
    from iblbake.core import sh

    alm = project_texels(source, lmax, nthreads)
    _, ls = _alm_index(lmax, lmax)          # each coefficient's l, in ducc0's layout
    ahat = np.array([sh.truncated_cos_sh(l) for l in range(lmax + 1)])
    return synthesize(alm * ahat[ls][None, :], lmax, dirs, nthreads)
