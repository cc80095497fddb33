"""Spherical Gaussians with fixed axes and one sharpness (the "SG Series", Pettineo 2016;
BakingLab's SG5-12): G_k(w) = A_k exp(lambda (mu_k . w - 1)), so the fit is linear in A.

- Axes: K points of the spherical Fibonacci lattice, +y polar (common.fibonacci_sphere).
- Sharpness: the one lambda whose lobe integrates to its share of the sphere, 4 pi / K:
  int exp(lambda (mu.w - 1)) dw = 2 pi (1 - e^{-2 lambda}) / lambda = 4 pi / K (K = 5: 2.48,
  6: 2.99, 9: 4.50, 12: 6.00), so that K lobes of amplitude 1 hold a uniform sky's energy.
- Least squares (Roughton and Sloan's exact form): the moments b_k = int L G_k dw over the
  panorama's texels, then Gram A = b with the lobes' exact Gram matrix
  int G_i G_j dw = 4 pi e^{-2 lambda} sinh(r)/r, r = lambda |mu_i + mu_j|.
- NNLS: the same normal equations with A >= 0 (Lawson-Hanson, common.nnls_gram).
- Irradiance: Hill's fitted SG-cosine product (Pettineo, SG Series part 3, "SGIrradianceFitted",
  after Stephen Hill 2016): with c0 = 0.36, c1 = 1/(4 c0), scale = 1 + 2 e^{-2 lambda} - 1/lambda,
  bias = (e^{-lambda} - e^{-2 lambda})/lambda - e^{-2 lambda}, x = sqrt(1 - scale),
  y = (c0 mu.n + c1 x)^2 / x where |c0 mu.n| <= c1 x, else saturate(mu.n);
  E = (scale y + bias) 2 pi A / lambda (the published approximate SG integral).

- Specular (`effects.specular: sg`): the split sum with the SG in place of the prefiltered
  chain. The GGX NDF as an SG about n, sharpness 2/alpha^2 (Pettineo, SG Series part 4,
  DistributionTermSG), warped with sharpness lambda_w = 2/alpha^2 / (4 max(n.v, 1e-4)) (Wang et
  al. 2009's warp, as Pettineo's WarpDistributionSG: the Jacobian of h -> r at h = n), its axis
  not the mirror direction r = 2 (n.v) n - v but the split sum's dominant direction between n and
  r (Lagarde and de Rousiers 2014; kernels/split_sum.h dominant_direction: the lobe's mean leans
  to n when rough; measured against the quadrature below it halves the mean error at roughness
  0.7-1, 16% against 21-39%); the environment's radiance along the lobe
  is the normalised SG-SG inner product sum_k A_k int G_k G_w / int G_w, with
  int exp(l1 (m1.w - 1)) exp(l2 (m2.w - 1)) dw = 2 pi (e^{d - l1 - l2} - e^{-d - l1 - l2}) / d,
  d = |l1 m1 + l2 m2|, and int G_w = 2 pi (1 - e^{-2 l2}) / l2; times the split sum's DFG table
  (F0 A + F90 B at n.v and roughness: Fresnel and visibility integrated over the whole lobe, not
  at its centre, which measured worse: 21-78% mean error at roughness 0.5-1). Against the float64
  quadrature of the GGX lobe on the SG's own radiance (tests/test_bases_specular.py), with F = 1
  and the lobe's exact albedo: mean relative error 5.5% at roughness 0.3, 11% at 0.5, 16% at 0.7
  and 1 (worst channel of 12 views, n.v 0.2-0.9; worst single view 12-53%): a rough reflection,
  not a glossy one.

Layout: K rows of per-channel amplitudes, row k the lobe about the Fibonacci axis
y_k = 1 - (2k + 1)/K, azimuth k pi (3 - sqrt 5) from +z towards +x, of the K's one sharpness."""

from __future__ import annotations

import math

import numpy as np

from iblbake.core.bases import common

NAME = "sg"
TITLE = "SG"
RANK = 3                # its place in BASES (the schema's choices, the CLI's, the studies')
HEADER = "basis_sg.h"
LOBES = (5, 6, 9, 12)
FITS = ("least_squares", "nnls")
OPTIONS = {"sg_lobes": (LOBES, 9, "sg: spherical Gaussian lobes (fixed Fibonacci axes, one sharpness)"),
           "sg_fit": (FITS, "least_squares", "sg: the fit, exact least squares or non-negative least squares "
                                             "(nnls where the lobes serve the specular term, unless given)")}
# where the lobes serve the specular term (specular: sg, or probes storing sg), these defaults:
# least squares rings negative around a sun, and the lobe, clamped at 0, shows black patches
# beside white ones on metals (scene/load.py _resolve_specular_fits)
SPECULAR_DEFAULTS = {"sg_fit": "nnls"}
HILL_C0 = 0.36
GLSL_COEFFS, GLSL_IRRADIANCE = "SG_AMPLITUDE", "sgIrradiance"     # glsl()'s names (the probes' sampler)
GLSL_SPECULAR = "sgSpecularRadiance"
SPECULAR = True        # specular_radiance, kernels/basis_sg.h basis_specular_radiance: `specular: sg`


def variants() -> list:
    return [{"sg_lobes": k, "sg_fit": f} for f in FITS for k in LOBES]


def label(opts) -> str:
    return f"SG{opts['sg_lobes']} {'LS' if opts['sg_fit'] == 'least_squares' else 'NNLS'}"


def floats(opts) -> int:
    return opts["sg_lobes"]


def sharpness(k: int) -> float:
    """lambda with 2 pi (1 - e^{-2 lambda}) / lambda = 4 pi / k (bisection; the left side falls)."""
    lo, hi = 1e-6, 1e3
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if (1.0 - math.exp(-2.0 * mid)) / mid > 2.0 / k:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def axes(k: int) -> np.ndarray:
    return common.fibonacci_sphere(k)


def lobes(d, k: int) -> np.ndarray:
    """G_k(d) with unit amplitude, (..., K)."""
    lam = sharpness(k)
    return np.exp(lam * (np.asarray(d, np.float64) @ axes(k).T - 1.0))


def gram(k: int) -> np.ndarray:
    """int G_i G_j dw = 2 pi (e^{r - 2 lambda} - e^{-r - 2 lambda}) / r, r = lambda |mu_i + mu_j|
    (4 pi e^{-2 lambda} at r = 0)."""
    lam, mu = sharpness(k), axes(k)
    r = lam * np.linalg.norm(mu[:, None] + mu[None, :], axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        g = 2 * np.pi * (np.exp(r - 2 * lam) - np.exp(-r - 2 * lam)) / r
    return np.where(r > 1e-12, g, 4 * np.pi * math.exp(-2 * lam))


def fit(b, opts) -> np.ndarray:
    """Amplitudes (..., K, C) from the moments b (..., K, C) (one fit per leading index: a probe)."""
    b = np.asarray(b, np.float64)
    g = gram(opts["sg_lobes"])
    if opts["sg_fit"] == "least_squares":
        return np.linalg.solve(g, b.reshape(-1, *b.shape[-2:])).reshape(b.shape)
    cols = np.moveaxis(b, -2, -1).reshape(-1, b.shape[-2])
    return np.moveaxis(np.stack([common.nnls_gram(g, c) for c in cols]).reshape(*b.shape[:-2], b.shape[-1], -1), -1, -2)


def project(image, opts) -> np.ndarray:
    k = opts["sg_lobes"]
    return fit(common.moments(image, lambda d: lobes(d, k)), opts)


def project_rays(values, dirs, opts) -> np.ndarray:
    """The fit from probe rays (common.ray_moments): values (P, R, C) -> (P, K, C)."""
    k = opts["sg_lobes"]
    return fit(common.ray_moments(values, dirs, lambda d: lobes(d, k)), opts)


def radiance(coeffs, dirs, opts) -> np.ndarray:
    return lobes(dirs, opts["sg_lobes"]) @ np.asarray(coeffs, np.float64)


def hill_irradiance(mu_dot_n, lam: float) -> np.ndarray:
    """Hill's fitted irradiance of a unit-amplitude SG (the module's docstring)."""
    mdn = np.asarray(mu_dot_n, np.float64)
    c1 = 1.0 / (4.0 * HILL_C0)
    eml = math.exp(-lam)
    em2l = eml * eml
    scale = 1.0 + 2.0 * em2l - 1.0 / lam
    bias = (eml - em2l) / lam - em2l
    x = math.sqrt(1.0 - scale)
    x0, x1 = HILL_C0 * mdn, c1 * x
    y = np.where(np.abs(x0) <= x1, (x0 + x1) ** 2 / x, np.clip(mdn, 0.0, 1.0))
    return (scale * y + bias) * 2.0 * math.pi / lam


def exact_irradiance(mu_dot_n, lam: float, lmax: int = 40) -> np.ndarray:
    """The float64 cosine convolution of a unit SG (Funk-Hecke, converged by lmax 40 for lambda
    <= 12): what hill_irradiance approximates."""
    f_l = common.zonal_moments(lambda t: np.exp(lam * (t - 1.0)), lmax)
    return common.legendre_series(common.funk_hecke(f_l, common.cosine_moments(lmax)), mu_dot_n)


def irradiance(coeffs, normals, opts) -> np.ndarray:
    k = opts["sg_lobes"]
    # clamped at 0 as SH: least squares can go negative behind a sun
    return np.maximum(0.0, hill_irradiance(np.asarray(normals, np.float64) @ axes(k).T, sharpness(k))
                      @ np.asarray(coeffs, np.float64))


def sg_inner_normalised(mu_dot_r, lam: float, lam_w) -> np.ndarray:
    """int G(mu, lam) G(r, lam_w) dw / int G(r, lam_w) dw for unit-amplitude lobes (the module's
    docstring), from exponents that stay in range for any sharpness."""
    t = np.asarray(mu_dot_r, np.float64)
    lw = np.asarray(lam_w, np.float64)
    d = np.sqrt(np.maximum(lam * lam + lw * lw + 2.0 * lam * lw * t, 1e-12))
    # d - lam - lw as (d^2 - lw^2)/(d + lw) - lam: no cancellation of two large numbers
    inner = (np.exp(lam * (lam + 2.0 * lw * t) / (d + lw) - lam) - np.exp(-d - lam - lw)) / d
    return inner * lw / -np.expm1(-2.0 * lw)


def specular_weights(r, lam_w, opts) -> np.ndarray:
    """s_k (..., K): the radiance along the warped lobe about r (..., 3) of sharpness lam_w (...,)
    is sum_k s_k A_k, s_k the normalised SG-SG inner product of lobe k with the warped lobe."""
    k = opts["sg_lobes"]
    return sg_inner_normalised(np.asarray(r, np.float64) @ axes(k).T, sharpness(k), np.asarray(lam_w)[..., None])


def validate(coeffs, opts) -> np.ndarray:
    return common.check_coefficients(coeffs, opts["sg_lobes"], f"SG{opts['sg_lobes']} amplitudes",
                                     nonnegative=opts["sg_fit"] == "nnls")


def defines(opts) -> dict:
    return {"BASIS_SG": 1, "SG_LOBES": opts["sg_lobes"]}


def pack(coeffs, opts) -> np.ndarray:
    """What kernels/basis_sg.h reads: K rows (A rgb, 0), then K rows (mu xyz, lambda)."""
    k = opts["sg_lobes"]
    out = common.rgb_rows(coeffs, 2 * k)
    out[k:, :3] = axes(k)
    out[k:, 3] = sharpness(k)
    return out


def glsl(coeffs, opts) -> str:
    k = opts["sg_lobes"]
    return f"""// iblbake spherical Gaussians: {k} lobes ({opts['sg_fit']}), G(w) = A exp(lambda (mu.w - 1));
// world +y up.
// irradiance: Hill's fitted SG-cosine product; diffuse = albedo / PI * sgIrradiance(normalize(N));
const int SG_LOBES = {k};
const float SG_SHARPNESS = {sharpness(k):.9g};
{common.glsl_vec3_array("SG_AMPLITUDE", np.asarray(coeffs)[:, :3])}
{common.glsl_vec3_array("SG_AXIS", axes(k))}

vec3 sgIrradiance(vec3 n) {{
    float lam = SG_SHARPNESS;
    float eml = exp(-lam), em2l = eml * eml;
    float scale = 1.0 + 2.0 * em2l - 1.0 / lam;
    float bias = (eml - em2l) / lam - em2l;
    float x = sqrt(1.0 - scale), x1 = x / (4.0 * {HILL_C0});
    vec3 e = vec3(0.0);
    for (int k = 0; k < SG_LOBES; ++k) {{
        float mdn = dot(SG_AXIS[k], n), x0 = {HILL_C0} * mdn;
        float y = abs(x0) <= x1 ? (x0 + x1) * (x0 + x1) / x : clamp(mdn, 0.0, 1.0);
        e += SG_AMPLITUDE[k] * ((scale * y + bias) * 6.28318530717959 / lam);
    }}
    return max(e, vec3(0.0));
}}
{common.GLSL_WARP}
// specular = (F0 A + F90 B) (the split sum's DFG table at n.v, roughness) * sgSpecularRadiance(N, V, roughness):
// the normalised SG-SG inner product of each lobe with the warped GGX lobe
vec3 sgSpecularRadiance(vec3 n, vec3 v, float roughness) {{
    float alpha = roughness * roughness;
    vec3 d = basisLobeAxis(n, v, alpha);
    float lamW = basisWarpSharpness(alpha, dot(n, v)), lam = SG_SHARPNESS;
    float norm = lamW / (1.0 - exp(-2.0 * lamW));
    vec3 e = vec3(0.0);
    for (int k = 0; k < SG_LOBES; ++k) {{
        float t = dot(SG_AXIS[k], d);
        float dd = sqrt(max(lam * lam + lamW * lamW + 2.0 * lam * lamW * t, 1e-12));
        float x = lam * (lam + 2.0 * lamW * t) / (dd + lamW) - lam;
        e += SG_AMPLITUDE[k] * ((exp(x) - exp(-dd - lam - lamW)) / dd * norm);
    }}
    return max(e, vec3(0.0));
}}
"""
