"""What the directional bases share (float64, no device): the panorama's texels as directions and
solid angles, the Fibonacci sphere, zonal (Funk-Hecke) convolution with the clamped cosine, and
non-negative least squares on the normal equations.

Irradiance is radiometric throughout: E(n) = int L(w) max(0, n.w) dw (docs/conventions.md)."""

from __future__ import annotations

import math

import numpy as np

from iblbake.core import conventions
from iblbake.core import sh as core_sh

FOUR_PI = 4.0 * math.pi


def texel_rows(image, rows: int = 64):
    """(image rows (r, W, C), directions (r, W, 3), solid angle per texel (r,)) of an equirect
    panorama, `rows` rows at a time: the midpoint rule with exact texel solid angles."""
    img = np.asarray(image, np.float64)
    h, w = img.shape[:2]
    om = conventions.equirect_row_solid_angles(w, h)
    dirs = conventions.equirect_texel_dirs(w, h)
    for r0 in range(0, h, rows):
        yield img[r0:r0 + rows], dirs[r0:r0 + rows], om[r0:r0 + rows]


def moments(image, lobes) -> np.ndarray:
    """b_k = sum over texels of L f_k(d) dOmega, lobes(d (..., 3)) -> (..., K): shape (K, C)."""
    out = None
    for img, d, om in texel_rows(image):
        part = np.einsum("rwk,rwc,r->kc", lobes(d), img, om, optimize=True)
        out = part if out is None else out + part
    return out


def ray_moments(values, dirs, lobes) -> np.ndarray:
    """The moments from ray samples instead of texels: values (..., R, C) of R rays along dirs
    (R, 3), or each probe's own (..., R, 3) (a lightmap's texels), that share the sphere equally
    (the probes' spherical Fibonacci set), so each weighs 4 pi / R:
    b_k = 4 pi / R sum_i L_i f_k(d_i), shape (..., K, C)."""
    f = lobes(np.asarray(dirs, np.float64))
    return np.einsum("...rk,...rc->...kc", f, np.asarray(values, np.float64), optimize=True) * (FOUR_PI / f.shape[-2])


def fibonacci_sphere(n: int) -> np.ndarray:
    """n unit vectors on a spherical Fibonacci lattice, +y polar: y_k = 1 - (2k + 1)/n, azimuth
    k times the golden angle pi (3 - sqrt 5) from +z towards +x (equal-area rings)."""
    k = np.arange(n)
    y = 1.0 - (2 * k + 1) / n
    phi = k * np.pi * (3.0 - np.sqrt(5.0))
    s = np.sqrt(np.maximum(0.0, 1.0 - y * y))
    return np.stack([s * np.sin(phi), y, s * np.cos(phi)], -1)


def _legendre_all(t, lmax: int):
    """P_0..P_lmax at t, shape (lmax + 1,) + t.shape (Bonnet's recurrence)."""
    t = np.asarray(t, np.float64)
    p = np.empty((lmax + 1,) + t.shape)
    p[0] = 1.0
    if lmax:
        p[1] = t
    for l in range(1, lmax):
        p[l + 1] = ((2 * l + 1) * t * p[l] - l * p[l - 1]) / (l + 1)
    return p


def gauss_legendre(n: int):
    """Gauss-Legendre nodes and weights on [-1, 1] (as numpy's leggauss, whose eigenvalue solve is
    O(n^3)): Newton on P_n from Tricomi's asymptotic guesses, O(n^2), converged to float64 for
    any n (the weights 2 / ((1 - x^2) P_n'(x)^2))."""
    i = np.arange(1, n + 1)
    x = np.cos(np.pi * (i - 0.25) / (n + 0.5)) * (1 - (n - 1) / (8.0 * n ** 3))
    for _ in range(100):
        p0, p1 = np.ones_like(x), x.copy()
        for k in range(1, n):
            p0, p1 = p1, ((2 * k + 1) * x * p1 - k * p0) / (k + 1)
        dp = n * (x * p1 - p0) / (x * x - 1)
        step = p1 / dp
        x -= step
        if np.abs(step).max() < 1e-15:
            break
    p0, p1 = np.ones_like(x), x.copy()
    for k in range(1, n):
        p0, p1 = p1, ((2 * k + 1) * x * p1 - k * p0) / (k + 1)
    dp = n * (x * p1 - p0) / (x * x - 1)
    return x[::-1].copy(), (2.0 / ((1 - x * x) * dp * dp))[::-1].copy()


def zonal_moments(f, lmax: int, nodes: int = 96) -> np.ndarray:
    """f_l = 2 pi int_{-1}^{1} f(t) P_l(t) dt, l = 0..lmax, by Gauss-Legendre on [-1, 0] and [0, 1]
    apart (the lobes clamped at t = 0 are smooth on each half: exact for polynomials there)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    t = np.concatenate([0.5 * (x - 1), 0.5 * (x + 1)])
    wt = np.concatenate([0.5 * w, 0.5 * w])
    return 2 * np.pi * _legendre_all(t, lmax) @ (wt * f(t))


def funk_hecke(f_l, g_l) -> np.ndarray:
    """Legendre coefficients c_l of int f(a.w) g(b.w) dw = sum_l c_l P_l(a.b) from the zonal
    moments of f and g (Funk-Hecke): c_l = (2l + 1)/(4 pi) f_l g_l."""
    l = np.arange(len(f_l))
    return (2 * l + 1) / (4 * np.pi) * np.asarray(f_l) * np.asarray(g_l)


def cosine_moments(lmax: int) -> np.ndarray:
    """The clamped cosine's zonal moments: Ahat_l (core/sh.py truncated_cos_sh)."""
    return np.array([core_sh.truncated_cos_sh(l) for l in range(lmax + 1)])


def vmf_eigenvalues(lam, lmax: int) -> np.ndarray:
    """a_l(lambda) = i_l(lambda) / i_0(lambda), l = 0..lmax (i_l the modified spherical Bessel
    functions of the first kind): the Legendre coefficients of the normalised SG, since
    exp(lambda t) = sum_l (2l + 1) i_l(lambda) P_l(t) (Abramowitz and Stegun 10.2.36). Their ratios
    by Miller's backward recurrence r_l = 1 / ((2l + 1)/lambda + r_{l+1}) (a_1 = coth lambda -
    1/lambda), stable for any lambda > 0; shape lam.shape + (lmax + 1,)."""
    lam = np.asarray(lam, np.float64)[..., None]
    top = lmax + 64 + int(4.0 * math.sqrt(float(lam.max())))
    ratios = np.empty(lam.shape[:-1] + (lmax + 1,))
    r = np.zeros(lam.shape)
    for l in range(top, 0, -1):
        r = 1.0 / ((2 * l + 1) / lam + r)
        if l <= lmax:
            ratios[..., l] = r[..., 0]
    ratios[..., 0] = 1.0
    return np.cumprod(ratios, -1)


def legendre_series(c_l, t) -> np.ndarray:
    """sum_l c_l P_l(t)."""
    return np.polynomial.legendre.legval(np.asarray(t, np.float64), np.asarray(c_l, np.float64))


def irradiance_normal_equations(profile, axes):
    """Least squares on the irradiance over the whole sphere of normals (the limit of uniformly
    spread sample normals), for lobes whose irradiance is sum_l e_l P_l(mu_k . n) (profile e_l,
    axes mu_k): min int (sum_k A_k E_k(n) - E(n))^2 dn. By Funk-Hecke the Gram
    int E_i E_j dn = sum_l 4 pi/(2l + 1) e_l^2 P_l(mu_i . mu_j), and the moments
    int E E_k dn = int L(w) h(mu_k . w) dw, h = sum_l e_l Ahat_l P_l (the lobe convolved with the
    cosine twice), summed over texels or rays as every fit's moments. Returns (Gram, the moments'
    lobes: d (..., 3) -> (..., K)); solve with solve_min_norm."""
    e, mu = np.asarray(profile, np.float64), np.asarray(axes, np.float64)
    l = np.arange(len(e))
    g = legendre_series(4 * np.pi / (2 * l + 1) * e * e, np.clip(mu @ mu.T, -1.0, 1.0))
    h = e * cosine_moments(len(e) - 1)
    return g, lambda d: legendre_series(h, np.clip(np.asarray(d, np.float64) @ mu.T, -1.0, 1.0))


def solve_min_norm(gram, b) -> np.ndarray:
    """gram x = b (..., K, C) by the pseudo-inverse (relative cutoff 1e-10): the minimum-norm
    solution where the lobes' irradiances are linearly dependent (ambient dice's 12: the Gram's
    condition number 1e17), the plain solution elsewhere."""
    b = np.asarray(b, np.float64)
    return np.einsum("ij,...jc->...ic", np.linalg.pinv(gram, rcond=1e-10, hermitian=True), b)


def nnls_gram(gram, b, max_iter: int | None = None) -> np.ndarray:
    """min ||f - sum_k x_k g_k||^2 over x >= 0 from the normal equations (gram = <g_i, g_j>,
    b = <f, g_k>): Lawson and Hanson's active-set algorithm (Solving Least Squares Problems,
    1974, ch. 23), which reads A only through A^T A and A^T y. KKT at the end: x >= 0, the gradient
    w = b - gram x is <= 0 where x = 0 and 0 where x > 0."""
    g = np.asarray(gram, np.float64)
    b = np.asarray(b, np.float64)
    n = len(b)
    x = np.zeros(n)
    free = np.zeros(n, bool)
    tol = 1e-12 * max(np.abs(g).max(), 1e-300) * n * max(np.abs(b).max(), 1e-300)
    for _ in range(max_iter or 3 * n + 10):
        w = b - g @ x
        if free.all() or (w[~free] <= tol).all():
            break
        j = int(np.argmax(np.where(free, -np.inf, w)))
        free[j] = True
        while True:
            s = np.zeros(n)
            s[free] = np.linalg.solve(g[np.ix_(free, free)], b[free])
            if (s[free] > 0).all():
                break
            bad = free & (s <= 0)
            alpha = np.min(x[bad] / (x[bad] - s[bad]))
            x = x + alpha * (s - x)
            free &= x > 1e-15 * max(x.max(), 1e-300)
            x[~free] = 0.0
        x = s
    return x


def luminance_axis(l1_xyz) -> np.ndarray:
    """The unit direction of the luminance-weighted L1 vectors (l1_xyz: (3, C), x y z rows), +y
    where they cancel (a uniform sky): ZH3's zonal axis and Geomerics' dominant direction."""
    from iblbake.core.metrics import LUMINANCE
    c = l1_xyz.shape[1]
    v = l1_xyz[:, :3] @ LUMINANCE if c >= 3 else l1_xyz[:, 0]
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 * max(float(np.abs(l1_xyz).max()), 1e-300) else np.array([0.0, 1.0, 0.0])


def check_coefficients(coeffs, rows: int, what: str, nonnegative: bool = False) -> np.ndarray:
    """A loaded coefficient array (rows, C) of finite floats (and >= 0 where the fit keeps them
    so), else ValueError naming what is wrong."""
    a = np.asarray(coeffs, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != rows or a.shape[1] < 1:
        raise ValueError(f"{what}: expected {rows} rows of per-channel coefficients, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{what}: non-finite coefficients")
    if nonnegative and (a < 0).any():
        raise ValueError(f"{what}: negative coefficients where the fit keeps them >= 0")
    return a


def glsl_vec3_array(name: str, rows) -> str:
    vals = ",\n    ".join("vec3(" + ", ".join(f"{float(v):.9g}" for v in r[:3]) + ")" for r in rows)
    return f"const vec3 {name}[{len(rows)}] = vec3[{len(rows)}](\n    {vals}\n);"


def glsl_float_array(name: str, vals) -> str:
    return f"const float {name}[{len(vals)}] = float[{len(vals)}](" + ", ".join(f"{float(v):.9g}" for v in vals) + ");"


# --- the warped GGX lobe every specular basis reads its radiance along (sg.py's docstring derives it)

def warp_sharpness(alpha, nov) -> np.ndarray:
    """The warped NDF lobe's sharpness 2/alpha^2 / (4 n.v) (Pettineo's SG warp; kernels/bases.h
    basis_warp_sharpness); alpha = roughness^2."""
    a2 = np.maximum(np.asarray(alpha, np.float64) ** 2, 1e-8)
    return 2.0 / a2 / (4.0 * np.maximum(np.asarray(nov, np.float64), 1e-4))


def lobe_axis(n, v, alpha) -> np.ndarray:
    """The warped lobe's axis: the dominant direction between n and the mirror direction
    (kernels/split_sum.h dominant_direction)."""
    n, v = np.asarray(n, np.float64), np.asarray(v, np.float64)
    r = 2 * (n * v).sum(-1, keepdims=True) * n - v
    s = np.clip(1 - np.asarray(alpha, np.float64), 0, 1)[..., None]
    d = n + (r - n) * (s * (np.sqrt(s) + np.asarray(alpha, np.float64)[..., None]))
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


# the warp in GLSL (warp_sharpness, lobe_axis): what each specular basis's GLSL function reads
GLSL_WARP = """
// the warped GGX lobe (Pettineo's SG warp about the split sum's dominant direction): its axis and
// sharpness at unit normal n, unit vector towards the viewer v, alpha = roughness^2
vec3 basisLobeAxis(vec3 n, vec3 v, float alpha) {
    vec3 r = 2.0 * dot(n, v) * n - v;
    float s = clamp(1.0 - alpha, 0.0, 1.0);
    return normalize(n + (r - n) * (s * (sqrt(s) + alpha)));
}

float basisWarpSharpness(float alpha, float nov) {
    return 2.0 / max(alpha * alpha, 1e-8) / (4.0 * max(nov, 1e-4));
}
"""


def rgb_rows(coeffs, rows: int) -> np.ndarray:
    """A kernel block of `rows` float4 rows, the coefficients' RGB in the first ones (a header's
    per-basis tables, such as lobe axes, fill the rest)."""
    out = np.zeros((rows, 4), np.float32)
    c = np.asarray(coeffs)
    out[:len(c), :3] = c[:, :3]
    return out
