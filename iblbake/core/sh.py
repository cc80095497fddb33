"""Real spherical harmonics (docs/conventions.md): orthonormal, z polar axis, no Condon-Shortley
phase, index k = l*(l+1) + m. Mirrors kernels/sh.h.

    Y_l^m = K_l^|m| P_l^|m|(z) * (sqrt2 cos(m phi) | 1 | sqrt2 sin(|m| phi)),  phi = atan2(y, x)

For l <= 2 this is exactly the 9-coefficient basis of Ramamoorthi and Hanrahan 2001. The associated Legendre
functions come from the standard stable recurrences (as Filament's CubemapSH):

    P_m^m     = (2m-1)!! (1 - z^2)^(m/2)
    P_{m+1}^m = (2m+1) z P_m^m
    P_l^m     = ((2l-1) z P_{l-1}^m - (l+m-1) P_{l-2}^m) / (l-m)
"""

from __future__ import annotations

import functools
import math

import numpy as np

from iblbake.core import conventions

MAX_BANDS = 16
WINDOWS = ("none", "hann", "lanczos")


def sh_index(l: int, m: int) -> int:
    return l * (l + 1) + m


def sh_normalization(l: int, m: int) -> float:
    """K_l^m = sqrt((2l+1)/(4 pi) * (l-m)!/(l+m)!), m >= 0."""
    ratio = 1.0
    for k in range(l - m + 1, l + m + 1):
        ratio /= k
    return math.sqrt((2 * l + 1) / (4.0 * math.pi) * ratio)


def legendre_table(z, bands: int) -> dict:
    """{(l, m): K_l^m P_l^m(z)} for 0 <= m <= l < bands (one contiguous array per entry)."""
    z = np.asarray(z, dtype=np.float64)
    s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    p = {}
    pmm = np.ones_like(z)
    for m in range(bands):
        if m > 0:
            pmm = pmm * ((2 * m - 1) * s)
        p[m, m] = pmm
        if m + 1 < bands:
            p[m + 1, m] = (2 * m + 1) * z * pmm
        for l in range(m + 2, bands):
            p[l, m] = ((2 * l - 1) * z * p[l - 1, m] - (l + m - 1) * p[l - 2, m]) / (l - m)
    return {lm: v * sh_normalization(*lm) for lm, v in p.items()}


def azimuth_table(phi, bands: int):
    """The azimuthal factor of Y for m = -(bands-1)..(bands-1), shape phi.shape + (2*bands-1,)
    indexed [m + bands - 1]: sqrt2 sin(|m| phi), 1, sqrt2 cos(m phi)."""
    phi = np.asarray(phi, dtype=np.float64)
    out = np.empty(phi.shape + (2 * bands - 1,))
    c = bands - 1
    out[..., c] = 1.0
    for m in range(1, bands):
        out[..., c + m] = math.sqrt(2.0) * np.cos(m * phi)
        out[..., c - m] = math.sqrt(2.0) * np.sin(m * phi)
    return out


def combine(legendre: dict, azimuth, bands: int):
    """Y_k from the two factors (broadcasting), shape (..., bands^2)."""
    shape = np.broadcast_shapes(legendre[0, 0].shape, azimuth.shape[:-1])
    out = np.empty(shape + (bands * bands,))
    c = bands - 1
    for l in range(bands):
        for m in range(-l, l + 1):
            out[..., sh_index(l, m)] = legendre[l, abs(m)] * azimuth[..., c + m]
    return out


def sh_basis(d, bands: int):
    """Y_k(d) for unit directions d[..., 3], shape (..., bands^2), float64."""
    d = np.asarray(d, dtype=np.float64)
    phi = np.arctan2(d[..., 1], d[..., 0])
    return combine(legendre_table(d[..., 2], bands), azimuth_table(phi, bands), bands)


def truncated_cos_sh(l: int) -> float:
    """Ahat_l: the clamped-cosine kernel's SH coefficient scaled by sqrt(4 pi / (2l+1)), so that
    E_lm = Ahat_l L_lm (Ramamoorthi and Hanrahan 2001; Filament's computeTruncatedCosSh)."""
    if l == 0:
        return math.pi
    if l == 1:
        return 2.0 * math.pi / 3.0
    if l % 2:
        return 0.0
    h = l // 2
    a0 = (1.0 if h % 2 else -1.0) / ((l + 2) * (l - 1))
    # l! / (h!^2 2^l), in logs: the factorials overflow a float from l = 171 (the spectral
    # irradiance goes to l = 1024)
    a1 = math.exp(math.lgamma(l + 1) - 2.0 * math.lgamma(h + 1) - l * math.log(2.0))
    return 2.0 * math.pi * a0 * a1


def ahat(bands: int):
    """Ahat per coefficient k, shape (bands^2,)."""
    return np.array([truncated_cos_sh(l) for l in range(bands) for _ in range(2 * l + 1)])


def window(bands: int, kind: str = "none"):
    """Per-coefficient ringing-reduction window (Sloan 2008, "Stupid SH Tricks"), shape (bands^2,).

    hann:    w_l = (1 + cos(pi l / bands)) / 2
    lanczos: w_l = sinc(l / bands) = sin(pi l / bands) / (pi l / bands)
    Both are 1 at l = 0 (the mean is kept) and fall to 0 just past the last band.
    """
    if kind not in WINDOWS:
        raise ValueError(f"unknown SH window {kind!r}; choose one of {', '.join(WINDOWS)}")
    ls = np.array([l for l in range(bands) for _ in range(2 * l + 1)], dtype=np.float64)
    if kind == "none":
        return np.ones_like(ls)
    x = ls / bands
    if kind == "hann":
        return 0.5 * (1.0 + np.cos(np.pi * x))
    return np.sinc(x)


def project_direct(image, bands: int, rotate_y_deg: float = 0.0, nodes: int = 6):
    """The slow, obviously-correct oracle of `project`: for every texel, int_texel Y_k dOmega by a
    tensor Gauss-Legendre rule in (theta, phi) over the texel's exact extent, every direction
    the exact inverse of the equirect mapping (a common trap). For small images (tests)."""
    image = np.asarray(image, dtype=np.float64)
    h, w, c = image.shape
    # Large texels (tiny images) are split so the rule stays accurate: pieces of <= pi/64.
    pt, pp = max(1, -(-64 // h)), max(1, -(-128 // w))
    x, wx = np.polynomial.legendre.leggauss(nodes)
    xt = ((np.arange(pt)[:, None] + 0.5 * (x[None, :] + 1)) / pt * 2 - 1).reshape(-1)
    xp = ((np.arange(pp)[:, None] + 0.5 * (x[None, :] + 1)) / pp * 2 - 1).reshape(-1)
    wt0, wp0 = np.tile(wx, pt) / pt, np.tile(wx, pp) / pp
    out = np.zeros((bands * bands, c))
    dphi = 2.0 * np.pi / w
    phi_c = conventions.equirect_phi(w, rotate_y_deg)
    for j in range(h):
        a, b = np.pi * j / h, np.pi * (j + 1) / h
        theta = 0.5 * (a + b) + 0.5 * (b - a) * xt
        wt = 0.5 * (b - a) * wt0 * np.sin(theta)
        phi = phi_c[:, None] + 0.5 * dphi * xp[None, :]           # (w, n)
        wp = 0.5 * dphi * wp0
        st = np.sin(theta)[:, None, None]
        d = np.stack(np.broadcast_arrays(st * np.sin(phi), np.cos(theta)[:, None, None], st * np.cos(phi)), -1)
        y = sh_basis(d, bands)                                     # (n_theta, w, n_phi, K)
        texel_integral = np.einsum("a,b,awbk->wk", wt, wp, y)     # (w, K)
        out += texel_integral.T @ image[j]
    return out


def evaluate(coeffs, d, bands: int):
    """sum_k coeffs[k] Y_k(d): coeffs (bands^2, C), d (..., 3) -> (..., C)."""
    return sh_basis(d, bands) @ np.asarray(coeffs, dtype=np.float64)


def irradiance(coeffs_e, n, bands: int):
    """Irradiance at normals n from irradiance coefficients, clamped at 0: a sharp
    source rings, and negative irradiance must not reach a frame."""
    return np.maximum(0.0, evaluate(coeffs_e, n, bands))


# --- exact texel integration, in separable form ----------------------------------------
#
# The panorama is piecewise constant over texels, so L_k = sum_texels L_texel * int_texel Y_k dOmega
# (exact for any W x H, 1x1 included; it differs from the midpoint sum L(d) Y(d) dOmega of
# docs/conventions.md by O(texel^2 l^2): 8e-6 relative at 1024x512 and 3 bands).
#
# On one equirect row (theta from +y), every Y_k is a trigonometric polynomial of degree <= l in
# the azimuth phi_e = atan2(x, z): Y_k = sum_t G[k, t](theta) T_t(phi_e), T = azimuth_table.
# - Over a texel's azimuth interval, the mean of cos(m phi) is cos(m phi_i) * sinc(m / W): a
#   per-m factor on the row's Fourier sums S[j, t, c] = sum_i L(i, j) T_t(phi_i), which are the
#   bandwidth-bound part (kernels/sh_project.cl).
# - Over the row's polar interval, int G[k, t](theta) sin(theta) dtheta by composite
#   Gauss-Legendre in theta (smooth, so it converges to float64 precision).
# G itself is solved from sh_basis at 2*bands-1 equispaced azimuths: exact, since the
# trigonometric polynomial has no more terms than points.

_GL_NODES = 8


def _polar_nodes(height: int):
    """Gauss-Legendre nodes/weights in theta per row: shape (height, n)."""
    pieces = max(1, -(-64 // height))  # rows wider than pi/64 are split
    # narrow rows need few nodes: the error is ~ (dtheta * l)^(2n) / (2n)!
    x, w = np.polynomial.legendre.leggauss(_GL_NODES if height < 256 else 4)
    edges = np.pi * np.arange(height * pieces + 1) / (height * pieces)
    a, b = edges[:-1, None], edges[1:, None]
    theta = 0.5 * (a + b) + 0.5 * (b - a) * x[None, :]
    weight = 0.5 * (b - a) * w[None, :] * np.sin(theta)
    return theta.reshape(height, -1), weight.reshape(height, -1)


def _g_at(theta, bands: int):
    """G[..., k, t] at polar angles theta (from +y)."""
    nt = 2 * bands - 1
    phis = 2.0 * np.pi * np.arange(nt) / nt
    st = np.sin(theta)[..., None]
    d = np.stack(np.broadcast_arrays(st * np.sin(phis), np.cos(theta)[..., None], st * np.cos(phis)), axis=-1)
    y = sh_basis(d, bands)                              # (..., nt, K)
    t_inv = np.linalg.inv(azimuth_table(phis, bands))   # (nt, nt)
    return np.einsum("ts,...sk->...kt", t_inv, y, optimize=True)


def azimuth_texel_means(width: int, bands: int):
    """Mean of T_t over one texel's azimuth interval divided by T_t at its centre: sinc(|m| / W)."""
    m = np.abs(np.arange(-(bands - 1), bands))
    return np.sinc(m / width)


@functools.lru_cache(maxsize=16)
def row_factors(height: int, bands: int):
    """int over row j of G[k, t](theta) sin(theta) dtheta, shape (height, bands^2, 2*bands-1)."""
    theta, weight = _polar_nodes(height)
    return np.einsum("hn,hnkt->hkt", weight, _g_at(theta, bands), optimize=True)


@functools.lru_cache(maxsize=16)
def _contraction(height: int, width: int, bands: int):
    """(bands^2, height * (2*bands-1)) matrix taking flattened row sums to coefficients."""
    scale = (2.0 * np.pi / width) * azimuth_texel_means(width, bands)
    g = row_factors(height, bands) * scale[None, None, :]          # (H, K, T)
    return np.ascontiguousarray(g.transpose(1, 0, 2).reshape(bands * bands, -1))


def project_row_sums(row_sums, bands: int, width: int):
    """Finish the projection from per-row Fourier sums S[j, t, c] (float64)."""
    row_sums = np.asarray(row_sums, dtype=np.float64)
    h, nt, c = row_sums.shape
    return _contraction(h, width, bands) @ row_sums.reshape(h * nt, c)


def row_sums_twin(image, bands: int, rotate_y_deg: float = 0.0):
    """numpy version of kernels/sh_project.cl: S[j, t, c] = sum_i L(i, j) T_t(phi_i)."""
    image = np.asarray(image, dtype=np.float64)
    t = azimuth_table(conventions.equirect_phi(image.shape[1], rotate_y_deg), bands)  # (W, nt)
    return np.matmul(image.transpose(0, 2, 1), t).transpose(0, 2, 1)   # (H, nt, C); BLAS, not einsum


def project(image, bands: int, rotate_y_deg: float = 0.0):
    """Radiance coefficients (bands^2, C) in float64: the numpy backend of `iblbake sh`."""
    return project_row_sums(row_sums_twin(image, bands, rotate_y_deg), bands, np.shape(image)[1])
