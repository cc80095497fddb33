"""Spherical Gaussians with fixed axes and one sharpness (the "SG Series", Pettineo 2016;
BakingLab's SG5-12): G_k(w) = A_k exp(lambda (mu_k . w - 1)), so the fit is linear in A.

- Axes: K points of the spherical Fibonacci lattice, +y polar (common.fibonacci_sphere).
- Sharpness: the one lambda whose lobe integrates to its share of the sphere, 4 pi / K:
  int exp(lambda (mu.w - 1)) dw = 2 pi (1 - e^{-2 lambda}) / lambda = 4 pi / K (K = 5: 2.48,
  6: 2.99, 9: 4.50, 12: 6.00), so that K lobes of amplitude 1 hold a uniform sky's energy.
- Irradiance: the exact cosine convolution of a unit lobe, E(t) = sum_l e_l P_l(t), t = mu.n,
  e_l = (1 - e^{-2 lambda})/(2 lambda) (2l + 1) a_l(lambda) Ahat_l: by Funk-Hecke from
  exp(lambda t) = sum_l (2l + 1) i_l(lambda) P_l(t) (Abramowitz and Stegun 10.2.36; a_l = i_l/i_0,
  common.vmf_eigenvalues) and the clamped cosine's Ahat_l (Ramamoorthi and Hanrahan 2001). An
  off-axis normal has no elementary closed form (Pettineo, SG Series part 3; Meder and
  Bruederlin 2018 approximate it); the series falls super-exponentially past l ~ lambda:
  truncated at l = PROFILE_DEGREE = 12 it is within 1.1e-8 of the peak for lambda <= 6, the exact
  convolution to float32. The kernel evaluates it as that degree-12 polynomial in t (Horner; its
  power coefficients at most 0.5 of the peak, so float32 holds it to 1.7e-7), as the twin does.
  Hill's fitted SG-cosine product (used before) is 0.5-1.5% of the peak off at these
  sharpnesses, 3.4-6.6% at lambda 1-2, and fails below (192% at 0.5).
- Fits (`sg_fit`), each for the quantity the lobes serve:
  irradiance (the default: the diffuse term, `iblbake basis`, irradiance probes): least squares
  on the irradiance over the whole sphere of normals, E_k above against the panorama's
  (common.irradiance_normal_equations: exact by Funk-Hecke). K = 9 lobes fitted so are smoother,
  lambda = 2 (IRRADIANCE_SHARPNESS): as lambda falls their span nears L2 SH's, and on the eight
  example panoramas their worst relative RMSE against L2's falls from 1.42x (lambda 4.5: sunset
  1.65% against 1.16%) to 1.08x (1.25%), the Gram's condition number 1.1e3 and the amplitudes within 12x
  the mean radiance (fp16 holds them); K = 5 and 6 stay 3-9x L2 at any sharpness (5 or 6 floats
  cannot hold L2's 9) and K = 12 0.91x at lambda 2 or 6, so they keep the K's own.
  least_squares: on the radiance (Roughton and Sloan's exact form): the moments
  b_k = int L G_k dw, then Gram A = b with the lobes' exact Gram matrix
  int G_i G_j dw = 4 pi e^{-2 lambda} sinh(r)/r, r = lambda |mu_i + mu_j|. Its misfit of a sun
  leaks into the low orders the irradiance depends on: 3x the irradiance fit's error (SG9 11.9%
  against 3.99% mean relative RMSE on the example panoramas; docs/benchmarks.md).
  nnls: the radiance's normal equations with A >= 0 (Lawson-Hanson, common.nnls_gram): the
  specular lobe's fit (SPECULAR_DEFAULTS), where a negative lobe shows as black patches.
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
y_k = 1 - (2k + 1)/K, azimuth k pi (3 - sqrt 5) from +z towards +x, of the K's one sharpness
(2 for K = 9 fitted on the irradiance; the document's "axes" and "sharpness"); the irradiance at normal n is
max(0, sum_k A_k sum_l e_l P_l(mu_k . n)), e_l the document's "irradiance_legendre"."""

from __future__ import annotations

import math

import numpy as np

from iblbake.core.bases import common

NAME = "sg"
TITLE = "SG"
RANK = 3                # its place in BASES (the schema's choices, the CLI's, the studies')
HEADER = "basis_sg.h"
LOBES = (5, 6, 9, 12)
FITS = ("irradiance", "least_squares", "nnls")
OPTIONS = {"sg_lobes": (LOBES, 9, "sg: spherical Gaussian lobes (fixed Fibonacci axes, one sharpness)"),
           "sg_fit": (FITS, "irradiance", "sg: the fit, least squares on the irradiance (the diffuse term's), or on "
                                          "the radiance, exact least squares or non-negative least squares (nnls "
                                          "where the lobes serve the specular term, unless given)")}
# where the lobes serve the specular term (specular: sg, or probes storing sg), these defaults:
# least squares rings negative around a sun, and the lobe, clamped at 0, shows black patches
# beside white ones on metals (scene/load.py _resolve_specular_fits)
SPECULAR_DEFAULTS = {"sg_fit": "nnls"}
PROFILE_DEGREE = 12      # the irradiance's Legendre series, truncated (the docstring)
IRRADIANCE_SHARPNESS = {9: 2.0}     # the irradiance fit's smoother lobes (the docstring)
GLSL_COEFFS, GLSL_IRRADIANCE = "SG_AMPLITUDE", "sgIrradiance"     # glsl()'s names (the probes' sampler)
GLSL_SPECULAR = "sgSpecularRadiance"
SPECULAR = True        # specular_radiance, kernels/basis_sg.h basis_specular_radiance: `specular: sg`
LINEAR = True          # irradiance() linear in the coefficients before its clamp (probes.py irradiance_columns)


def variants() -> list:
    return [{"sg_lobes": k, "sg_fit": f} for f in FITS for k in LOBES]


def label(opts) -> str:
    fit = {"irradiance": "irradiance", "least_squares": "LS", "nnls": "NNLS"}[opts["sg_fit"]]
    return f"SG{opts['sg_lobes']} {fit}"


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


def lobe_sharpness(opts) -> float:
    """The lobes' sharpness: the K's one (sharpness), or IRRADIANCE_SHARPNESS where the
    irradiance fit's smoother lobes serve better (the module's docstring)."""
    k = opts["sg_lobes"]
    return IRRADIANCE_SHARPNESS.get(k, sharpness(k)) if opts["sg_fit"] == "irradiance" else sharpness(k)


def lobes(d, k: int, lam: float | None = None) -> np.ndarray:
    """G_k(d) with unit amplitude, (..., K), of sharpness lam (the K's own by default)."""
    lam = sharpness(k) if lam is None else lam
    return np.exp(lam * (np.asarray(d, np.float64) @ axes(k).T - 1.0))


def gram(k: int) -> np.ndarray:
    """int G_i G_j dw = 2 pi (e^{r - 2 lambda} - e^{-r - 2 lambda}) / r, r = lambda |mu_i + mu_j|
    (4 pi e^{-2 lambda} at r = 0)."""
    lam, mu = sharpness(k), axes(k)
    r = lam * np.linalg.norm(mu[:, None] + mu[None, :], axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        g = 2 * np.pi * (np.exp(r - 2 * lam) - np.exp(-r - 2 * lam)) / r
    return np.where(r > 1e-12, g, 4 * np.pi * math.exp(-2 * lam))


def irradiance_profile(lam: float, lmax: int = PROFILE_DEGREE) -> np.ndarray:
    """e_l, l = 0..lmax: a unit lobe's irradiance is sum_l e_l P_l(mu.n) (the module's docstring)."""
    l = np.arange(lmax + 1)
    return (-math.expm1(-2.0 * lam) / (2.0 * lam) * (2 * l + 1) * common.vmf_eigenvalues(lam, lmax)
            * common.cosine_moments(lmax))


def profile_power(lam: float) -> np.ndarray:
    """The truncated profile as power coefficients of t = mu.n, t^0..t^PROFILE_DEGREE (what the
    kernel and the GLSL evaluate by Horner)."""
    return np.polynomial.legendre.leg2poly(irradiance_profile(lam))


def exact_irradiance(mu_dot_n, lam: float, lmax: int = 40) -> np.ndarray:
    """The float64 cosine convolution of a unit SG (the series, lmax 40: converged to float64 for
    lambda <= 12)."""
    return common.legendre_series(irradiance_profile(lam, lmax), np.clip(mu_dot_n, -1.0, 1.0))


def _moment_lobes(opts):
    """The functions the fit's moments integrate the radiance against: the lobes themselves (a
    radiance fit), or the lobes convolved with the cosine twice (the irradiance fit)."""
    k = opts["sg_lobes"]
    if opts["sg_fit"] == "irradiance":
        return common.irradiance_normal_equations(irradiance_profile(lobe_sharpness(opts)), axes(k))[1]
    return lambda d: lobes(d, k)


def fit(b, opts) -> np.ndarray:
    """Amplitudes (..., K, C) from the moments b (..., K, C) (one fit per leading index: a probe)."""
    b = np.asarray(b, np.float64)
    k = opts["sg_lobes"]
    if opts["sg_fit"] == "irradiance":
        g = common.irradiance_normal_equations(irradiance_profile(lobe_sharpness(opts)), axes(k))[0]
        return common.solve_min_norm(g, b)
    if opts["sg_fit"] == "least_squares":
        return np.linalg.solve(gram(k), b.reshape(-1, *b.shape[-2:])).reshape(b.shape)
    cols = np.moveaxis(b, -2, -1).reshape(-1, b.shape[-2])
    return np.moveaxis(np.stack([common.nnls_gram(gram(k), c) for c in cols]).reshape(*b.shape[:-2], b.shape[-1], -1),
                       -1, -2)


def project(image, opts) -> np.ndarray:
    return fit(common.moments(image, _moment_lobes(opts)), opts)


def project_rays(values, dirs, opts) -> np.ndarray:
    """The fit from probe rays (common.ray_moments): values (P, R, C) -> (P, K, C)."""
    return fit(common.ray_moments(values, dirs, _moment_lobes(opts)), opts)


def radiance(coeffs, dirs, opts) -> np.ndarray:
    return lobes(dirs, opts["sg_lobes"], lobe_sharpness(opts)) @ np.asarray(coeffs, np.float64)


def irradiance(coeffs, normals, opts) -> np.ndarray:
    k = opts["sg_lobes"]
    t = np.clip(np.asarray(normals, np.float64) @ axes(k).T, -1.0, 1.0)
    # clamped at 0 as SH: a fit can go negative behind a sun
    e = np.polynomial.polynomial.polyval(t, profile_power(lobe_sharpness(opts)))
    return np.maximum(0.0, e @ np.asarray(coeffs, np.float64))


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
    return sg_inner_normalised(np.asarray(r, np.float64) @ axes(k).T, lobe_sharpness(opts),
                               np.asarray(lam_w)[..., None])


def document_fields(opts) -> dict:
    """What `iblbake basis`'s document adds to evaluate the lobes without this code (the Layout)."""
    k = opts["sg_lobes"]
    lam = lobe_sharpness(opts)
    return {"formula": "E(n) = max(0, sum_k c_k sum_l irradiance_legendre[l] P_l(axes[k] . n)), P_l the Legendre "
                       "polynomials (the lobes exp(sharpness (axes[k] . w - 1)) convolved with max(0, n . w))",
            "axes": axes(k).tolist(), "sharpness": lam, "irradiance_legendre": irradiance_profile(lam).tolist()}


def validate(coeffs, opts) -> np.ndarray:
    return common.check_coefficients(coeffs, opts["sg_lobes"], f"SG{opts['sg_lobes']} amplitudes",
                                     nonnegative=opts["sg_fit"] == "nnls")


def defines(opts) -> dict:
    return {"BASIS_SG": 1, "SG_LOBES": opts["sg_lobes"], "SG_PROFILE_DEGREE": PROFILE_DEGREE}


def pack(coeffs, opts) -> np.ndarray:
    """What kernels/basis_sg.h reads: K rows (A rgb, 0), K rows (mu xyz, lambda), then the
    irradiance profile's power coefficients (profile_power), four to a row."""
    k = opts["sg_lobes"]
    prof_rows = PROFILE_DEGREE // 4 + 1
    out = common.rgb_rows(coeffs, 2 * k + prof_rows)
    out[k:2 * k, :3] = axes(k)
    out[k:2 * k, 3] = lobe_sharpness(opts)
    out[2 * k:].flat[:PROFILE_DEGREE + 1] = profile_power(lobe_sharpness(opts))
    return out


def glsl(coeffs, opts) -> str:
    k = opts["sg_lobes"]
    return f"""// iblbake spherical Gaussians: {k} lobes ({opts['sg_fit']} fit), G(w) = A exp(lambda (mu.w - 1));
// world +y up.
// irradiance: each lobe's exact cosine convolution, a degree-{PROFILE_DEGREE} polynomial in mu.n (SG_PROFILE: its
// coefficients of t^0..t^{PROFILE_DEGREE}); diffuse = albedo / PI * sgIrradiance(normalize(N));
const int SG_LOBES = {k};
const float SG_SHARPNESS = {lobe_sharpness(opts):.9g};
{common.glsl_vec3_array("SG_AMPLITUDE", np.asarray(coeffs)[:, :3])}
{common.glsl_vec3_array("SG_AXIS", axes(k))}
{common.glsl_float_array("SG_PROFILE", profile_power(lobe_sharpness(opts)))}

vec3 sgIrradiance(vec3 n) {{
    vec3 e = vec3(0.0);
    for (int k = 0; k < SG_LOBES; ++k) {{
        float t = clamp(dot(SG_AXIS[k], n), -1.0, 1.0), s = SG_PROFILE[{PROFILE_DEGREE}];
        for (int i = {PROFILE_DEGREE - 1}; i >= 0; --i) s = s * t + SG_PROFILE[i];
        e += SG_AMPLITUDE[k] * s;
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
