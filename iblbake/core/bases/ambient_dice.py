"""Ambient dice, the RBF variant (Iwanicki and Sloan, "Ambient Dice", EGSR 2017; evaluated as
Probulator's evaluateSRBF, troughton/Probulator): 12 lobes on the icosahedron's vertices, one value
per vertex and channel (12 floats; the paper's Bezier variant stores value and two tangent
derivatives per vertex, 36), each lobe a clamped zonal polynomial of t = max(0, v_i . w):

    w(t) = 0.7 (t^2 / 2) + 0.3 (5 t^4 / 6) = 0.35 t^2 + 0.25 t^4

Only the lobe on the positive side of each of the 6 axes is non-zero, and since the 12 vertices
are a spherical 5-design, sum_i w_i(w) = 0.35 * 2 + 0.25 * 6/5 = 1 everywhere: a partition of
unity, so a uniform sky is exact.

Fit (`ad_fit`), each for the quantity the lobes serve: irradiance (the default: the diffuse
term, `iblbake basis`, irradiance probes), least squares on the irradiance over the whole sphere
of normals (common.irradiance_normal_equations with the profile below; the 12 irradiances are
linearly dependent, so the minimum-norm values): 3.65% against 3.97% on city, 7.66% against 8.21%
on studio (docs/benchmarks.md); exact least squares on the radiance (moments b_i = int L w_i dw,
Gram int w_i w_j dw by Funk-Hecke, its Legendre series converged to float64 by l = 160), or NNLS
on the radiance's normal equations (every value >= 0: least squares rings negative around a sun
or a softbox, which the irradiance's cosine smooths away but the specular lobe reads as dark
patches; the specular lobe's fit, SPECULAR_DEFAULTS).
Irradiance: the cosine convolution of w is exactly a Legendre series of degree 4 (the even
moments of w vanish past l = 4 and the cosine's odd ones past l = 1):
E_i(n) = sum_{l in 0,1,2,4} (2l+1)/(4 pi) w_l Ahat_l P_l(v_i . n), its constants derived here.

Specular (`effects.specular: ambient_dice`, and `specular: probes` from ambient-dice probes): the
split sum with the radiance along the warped GGX lobe, as SG's (sg.py: Pettineo's warp, a
normalised spherical Gaussian about the dominant direction, sharpness lambda_w; the DFG table
outside): sum_i c_i h(v_i . r, lambda_w), h the lobe w convolved with the normalised SG (a von
Mises-Fisher density). By Funk-Hecke h(mu, lambda) = sum_l a_l(lambda) w_l P_l(mu), w_l the
Legendre coefficients of w (exact Gauss-Legendre on each half, w being a polynomial on [0, 1]),
a_l = I_{l+1/2}(lambda) / I_{1/2}(lambda) the density's own (common.vmf_eigenvalues).
The kernel reads h from a table (TABLE_ROWS rows of log2 lambda from TABLE_LOG2_LO in steps of
TABLE_STEP, TABLE_COLS columns of mu over [-1, 1], bilinear; beyond its ends the end rows): within
5.4e-4 of the lobe's peak 0.6 of the series (measured; tests/test_bases_specular.py), the 12 weights
then divided by their sum, which the exact h make 1 (a uniform sky is exact). Roughton 2019 fits a
different approximation (a lerp between the mirror value and the diffuse fit, scaled by a LUT).

Axes (vertex 2j = +a_j, 2j+1 = -a_j, normalised; t = 1/golden ratio):
a = (1, t, 0), (-1, t, 0), (0, 1, t), (0, 1, -t), (t, 0, 1), (-t, 0, 1).
Layout: 12 rows of per-channel values, row 2j the vertex +a_j and row 2j+1 the vertex -a_j, a_j
normalised (1, t, 0), (-1, t, 0), (0, 1, t), (0, 1, -t), (t, 0, 1), (-t, 0, 1), t = 1/golden ratio."""

from __future__ import annotations

import functools
import math

import numpy as np

from iblbake.core.bases import common

NAME = "ambient_dice"
TITLE = "ambient dice"
RANK = 4                # its place in BASES (the schema's choices, the CLI's, the studies')
HEADER = "basis_ambient_dice.h"
FITS = ("irradiance", "least_squares", "nnls")
OPTIONS = {"ad_fit": (FITS, "irradiance", "ambient_dice: the fit, least squares on the irradiance (the diffuse "
                                          "term's), or on the radiance, exact least squares or non-negative least "
                                          "squares (no negative radiance: its specular has no dark rings; nnls "
                                          "where the lobes serve the specular term, unless given)")}
SPECULAR_DEFAULTS = {"ad_fit": "nnls"}      # as sg's (sg.py SPECULAR_DEFAULTS)
VERTICES = 12
_T = (np.sqrt(5.0) - 1.0) / 2.0
GLSL_COEFFS, GLSL_IRRADIANCE = "AD_VALUE", "ambientDiceIrradiance"     # glsl()'s names (the probes' sampler)
GLSL_SPECULAR = "ambientDiceSpecularRadiance"
GLSL_TABLE = "ambientDiceSpecularTable"          # the sampler of specular_table in glsl()
SPECULAR = True        # specular_weights, kernels/basis_ambient_dice.h: `specular: ambient_dice`
LINEAR = True          # irradiance() linear in the coefficients before its clamp (probes.py irradiance_columns)
TABLE_LOG2_LO, TABLE_STEP, TABLE_ROWS, TABLE_COLS = -2.0, 0.25, 65, 129   # lambda 0.25 .. 16384


def variants() -> list:
    return [{"ad_fit": f} for f in FITS]


def _fit(opts) -> str:
    return opts.get("ad_fit", "irradiance")


def label(opts) -> str:
    return "ambient dice " + {"irradiance": "irradiance", "least_squares": "LS", "nnls": "NNLS"}[_fit(opts)]


def floats(opts) -> int:
    return VERTICES


def vertices() -> np.ndarray:
    a = np.array([[1, _T, 0], [-1, _T, 0], [0, 1, _T], [0, 1, -_T], [_T, 0, 1], [-_T, 0, 1]], np.float64)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    return np.stack([a, -a], 1).reshape(VERTICES, 3)


def lobe(t):
    t = np.maximum(np.asarray(t, np.float64), 0.0)
    t2 = t * t
    return 0.35 * t2 + 0.25 * t2 * t2


def lobes(d) -> np.ndarray:
    return lobe(np.asarray(d, np.float64) @ vertices().T)


@functools.lru_cache(maxsize=1)
def gram() -> np.ndarray:
    c = common.funk_hecke(*(2 * [common.zonal_moments(lobe, 160, nodes=128)]))
    v = vertices()
    return common.legendre_series(c, np.clip(v @ v.T, -1.0, 1.0))


@functools.lru_cache(maxsize=1)
def irradiance_profile() -> np.ndarray:
    """Legendre coefficients (l = 0..4) of one lobe's irradiance against v_i . n."""
    return common.funk_hecke(common.zonal_moments(lobe, 4), common.cosine_moments(4))


def fit(b, opts) -> np.ndarray:
    """Values (..., 12, C) from the moments b (..., 12, C) (_moment_lobes): least squares on the
    irradiance or the radiance, or NNLS on the radiance's normal equations (common.nnls_gram),
    one fit per leading index and channel."""
    b = np.asarray(b, np.float64)
    if _fit(opts) == "irradiance":
        return common.solve_min_norm(common.irradiance_normal_equations(irradiance_profile(), vertices())[0], b)
    g = gram()
    if _fit(opts) == "least_squares":
        return np.linalg.solve(g, b.reshape(-1, *b.shape[-2:])).reshape(b.shape)
    cols = np.moveaxis(b, -2, -1).reshape(-1, b.shape[-2])
    return np.moveaxis(np.stack([common.nnls_gram(g, c) for c in cols]).reshape(*b.shape[:-2], b.shape[-1], -1), -1, -2)


def _moment_lobes(opts):
    """The lobes themselves (a radiance fit), or convolved with the cosine twice (irradiance)."""
    if _fit(opts) == "irradiance":
        return common.irradiance_normal_equations(irradiance_profile(), vertices())[1]
    return lobes


def project(image, opts) -> np.ndarray:
    return fit(common.moments(image, _moment_lobes(opts)), opts)


def project_rays(values, dirs, opts) -> np.ndarray:
    """The fit from probe rays (common.ray_moments): values (P, R, C) -> (P, 12, C)."""
    return fit(common.ray_moments(values, dirs, _moment_lobes(opts)), opts)


def radiance(coeffs, dirs, opts) -> np.ndarray:
    return lobes(dirs) @ np.asarray(coeffs, np.float64)


def irradiance(coeffs, normals, opts) -> np.ndarray:
    t = np.asarray(normals, np.float64) @ vertices().T
    return np.maximum(0.0, common.legendre_series(irradiance_profile(), t) @ np.asarray(coeffs, np.float64))


def _legendre(t, lmax: int) -> np.ndarray:
    return common._legendre_all(t, lmax)


@functools.lru_cache(maxsize=8)
def lobe_legendre(lmax: int) -> np.ndarray:
    """w_l, l = 0..lmax: w(t) = sum_l w_l P_l(t) (exact: w is 0 on [-1, 0] and a polynomial on [0, 1])."""
    x, wq = common.gauss_legendre(lmax // 2 + 8)
    t, wq = 0.5 * (x + 1.0), 0.5 * wq
    return (2 * np.arange(lmax + 1) + 1) / 2 * (_legendre(t, lmax) @ (lobe(t) * wq))


def lobe_convolved(mu, lam) -> np.ndarray:
    """h(mu, lambda): lobe w averaged over the normalised SG of sharpness lambda about an axis at
    cosine mu from the vertex (float64 series, converged: lmax grows with sqrt(lambda)); mu (M,),
    lam (N,) -> (N, M)."""
    lam = np.atleast_1d(np.asarray(lam, np.float64))
    lmax = int(64 + 7.0 * math.sqrt(float(lam.max())))
    coeff = common.vmf_eigenvalues(lam, lmax) * lobe_legendre(lmax)
    return coeff @ _legendre(np.clip(np.asarray(mu, np.float64), -1.0, 1.0), lmax)


@functools.lru_cache(maxsize=1)
def _table() -> np.ndarray:
    lam = 2.0 ** (TABLE_LOG2_LO + TABLE_STEP * np.arange(TABLE_ROWS))
    out = lobe_convolved(np.linspace(-1.0, 1.0, TABLE_COLS), lam)
    out.setflags(write=False)
    return out


def specular_table(opts) -> np.ndarray:
    """The kernel's table of h (TABLE_ROWS, TABLE_COLS), float64."""
    return _table()


def table_lookup(mu, lam) -> np.ndarray:
    """h(mu, lambda) read from the table as kernels/basis_ambient_dice.h does (bilinear, clamped to
    its ends)."""
    t = _table()
    x = np.clip((np.log2(np.maximum(np.asarray(lam, np.float64), 1e-30)) - TABLE_LOG2_LO) / TABLE_STEP,
                0.0, TABLE_ROWS - 1.0)
    y = (np.clip(np.asarray(mu, np.float64), -1.0, 1.0) + 1.0) * 0.5 * (TABLE_COLS - 1)
    x0 = np.minimum(np.floor(x).astype(int), TABLE_ROWS - 2)
    y0 = np.minimum(np.floor(y).astype(int), TABLE_COLS - 2)
    fx, fy = x - x0, y - y0
    return ((t[x0, y0] * (1 - fy) + t[x0, y0 + 1] * fy) * (1 - fx)
            + (t[x0 + 1, y0] * (1 - fy) + t[x0 + 1, y0 + 1] * fy) * fx)


def specular_weights(r, lam_w, opts) -> np.ndarray:
    """s_i (..., 12): the radiance along the warped lobe about r of sharpness lam_w is sum_i s_i c_i."""
    mu = np.asarray(r, np.float64) @ vertices().T
    s = table_lookup(mu, np.asarray(lam_w, np.float64)[..., None])
    return s / s.sum(-1, keepdims=True)     # the exact h sum to 1 (the lobes' partition of unity)


def document_fields(opts) -> dict:
    """What `iblbake basis`'s document adds to evaluate the values without this code: the vertices
    and the irradiance profile, E(n) = max(0, sum_i c_i sum_l e_l P_l(v_i . n))."""
    return {"formula": "E(n) = max(0, sum_i c_i sum_l irradiance_legendre[l] P_l(axes[i] . n)), P_l the Legendre "
                       "polynomials",
            "axes": vertices().tolist(), "irradiance_legendre": irradiance_profile().tolist()}


def validate(coeffs, opts) -> np.ndarray:
    return common.check_coefficients(coeffs, VERTICES, "ambient dice values",
                                     nonnegative=_fit(opts) == "nnls")


def defines(opts) -> dict:
    return {"BASIS_AMBIENT_DICE": 1, "AD_TABLE_ROWS": TABLE_ROWS, "AD_TABLE_COLS": TABLE_COLS,
            "AD_TABLE_LOG2_LO": f"{TABLE_LOG2_LO}f", "AD_TABLE_STEP": f"{TABLE_STEP}f"}


def _power_profile() -> np.ndarray:
    """The irradiance profile as a polynomial in t, c0 + c1 t + c2 t^2 + c4 t^4 (kernel, GLSL)."""
    return np.polynomial.legendre.leg2poly(irradiance_profile())


def pack(coeffs, opts) -> np.ndarray:
    """What kernels/basis_ambient_dice.h reads: 12 rows (value rgb, 0), 12 rows (vertex xyz, 0),
    then the profile's power coefficients (t^0, t^1, t^2, t^4)."""
    out = common.rgb_rows(coeffs, 2 * VERTICES + 1)
    out[VERTICES:2 * VERTICES, :3] = vertices()
    p = _power_profile()
    out[-1] = [p[0], p[1], p[2], p[4]]
    return out


def glsl(coeffs, opts) -> str:
    p = _power_profile()
    return f"""// iblbake ambient dice (RBF variant, Iwanicki and Sloan 2017): 12 icosahedron lobes
// w(t) = 0.35 t^2 + 0.25 t^4, t = max(0, v.w); world +y up.
// diffuse = albedo / PI * ambientDiceIrradiance(normalize(N));
{common.glsl_vec3_array("AD_VALUE", np.asarray(coeffs)[:, :3])}
{common.glsl_vec3_array("AD_VERTEX", vertices())}

vec3 ambientDiceIrradiance(vec3 n) {{
    vec3 e = vec3(0.0);
    for (int i = 0; i < 12; ++i) {{
        float t = dot(AD_VERTEX[i], n), t2 = t * t;
        e += AD_VALUE[i] * ({p[0]:.9g} + {p[1]:.9g} * t + {p[2]:.9g} * t2 + {p[4]:.9g} * t2 * t2);
    }}
    return max(e, vec3(0.0));
}}
{common.GLSL_WARP}
// specular = (F0 A + F90 B) (the split sum's DFG table at n.v, roughness) * ambientDiceSpecularRadiance(N, V,
// roughness): each lobe averaged over the warped GGX lobe, h(v_i.d, lambda) read from the table
// `iblbake basis --specular-table FILE.exr` writes ({TABLE_COLS} x {TABLE_ROWS}, R: column j is v_i.d = -1 + 2 j / {TABLE_COLS - 1},
// row i log2 lambda = {TABLE_LOG2_LO} + {TABLE_STEP} i; bind it unfiltered: this reads it bilinearly)
uniform sampler2D ambientDiceSpecularTable;

vec3 ambientDiceSpecularRadiance(vec3 n, vec3 v, float roughness) {{
    float alpha = roughness * roughness;
    vec3 d = basisLobeAxis(n, v, alpha);
    float x = clamp((log2(max(basisWarpSharpness(alpha, dot(n, v)), 1e-30)) - ({TABLE_LOG2_LO})) / {TABLE_STEP}, 0.0,
                    {TABLE_ROWS - 1}.0);
    int x0 = min(int(x), {TABLE_ROWS - 2});
    float fx = x - float(x0), sum = 0.0;
    vec3 e = vec3(0.0);
    for (int i = 0; i < 12; ++i) {{
        float y = (clamp(dot(AD_VERTEX[i], d), -1.0, 1.0) + 1.0) * 0.5 * {TABLE_COLS - 1}.0;
        int y0 = min(int(y), {TABLE_COLS - 2});
        float fy = y - float(y0);
        float a = texelFetch(ambientDiceSpecularTable, ivec2(y0, x0), 0).r;
        float b = texelFetch(ambientDiceSpecularTable, ivec2(y0 + 1, x0), 0).r;
        float c = texelFetch(ambientDiceSpecularTable, ivec2(y0, x0 + 1), 0).r;
        float f = texelFetch(ambientDiceSpecularTable, ivec2(y0 + 1, x0 + 1), 0).r;
        float w = mix(mix(a, b, fy), mix(c, f, fy), fx);
        e += AD_VALUE[i] * w;
        sum += w;
    }}
    return max(e / sum, vec3(0.0));
}}
"""
