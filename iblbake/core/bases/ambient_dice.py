"""Ambient dice, the RBF variant (Iwanicki and Sloan, "Ambient Dice", EGSR 2017; evaluated as
Probulator's evaluateSRBF, troughton/Probulator): 12 lobes on the icosahedron's vertices, one value
per vertex and channel (12 floats; the paper's Bezier variant stores value and two tangent
derivatives per vertex, 36), each lobe a clamped zonal polynomial of t = max(0, v_i . w):

    w(t) = 0.7 (t^2 / 2) + 0.3 (5 t^4 / 6) = 0.35 t^2 + 0.25 t^4

Only the lobe on the positive side of each of the 6 axes is non-zero, and since the 12 vertices
are a spherical 5-design, sum_i w_i(w) = 0.35 * 2 + 0.25 * 6/5 = 1 everywhere: a partition of
unity, so a uniform sky is exact.

Fit: exact least squares against the panorama (moments b_i = int L w_i dw, Gram int w_i w_j dw
by Funk-Hecke, its Legendre series converged to float64 by l = 160).
Irradiance: the cosine convolution of w is exactly a Legendre series of degree 4 (the even
moments of w vanish past l = 4 and the cosine's odd ones past l = 1):
E_i(n) = sum_{l in 0,1,2,4} (2l+1)/(4 pi) w_l Ahat_l P_l(v_i . n), its constants derived here.

Axes (vertex 2j = +a_j, 2j+1 = -a_j, normalised; t = 1/golden ratio):
a = (1, t, 0), (-1, t, 0), (0, 1, t), (0, 1, -t), (t, 0, 1), (-t, 0, 1).
Layout: 12 rows (vertex order above) of per-channel values."""

from __future__ import annotations

import functools

import numpy as np

from iblbake.core.bases import common

NAME = "ambient_dice"
TITLE = "ambient dice"
HEADER = "basis_ambient_dice.h"
OPTIONS: dict = {}
VERTICES = 12
_T = (np.sqrt(5.0) - 1.0) / 2.0
GLSL_COEFFS, GLSL_IRRADIANCE = "AD_VALUE", "ambientDiceIrradiance"     # glsl()'s names (the probes' sampler)


def variants() -> list:
    return [{}]


def label(opts) -> str:
    return "ambient dice"


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


def project(image, opts) -> np.ndarray:
    return np.linalg.solve(gram(), common.moments(image, lobes))


def project_rays(values, dirs, opts) -> np.ndarray:
    """The fit from probe rays (common.ray_moments): values (P, R, C) -> (P, 12, C)."""
    b = common.ray_moments(values, dirs, lobes)
    return np.linalg.solve(gram(), b.reshape(-1, *b.shape[-2:])).reshape(b.shape)


def radiance(coeffs, dirs, opts) -> np.ndarray:
    return lobes(dirs) @ np.asarray(coeffs, np.float64)


def irradiance(coeffs, normals, opts) -> np.ndarray:
    t = np.asarray(normals, np.float64) @ vertices().T
    return np.maximum(0.0, common.legendre_series(irradiance_profile(), t) @ np.asarray(coeffs, np.float64))


def validate(coeffs, opts) -> np.ndarray:
    return common.check_coefficients(coeffs, VERTICES, "ambient dice values")


def defines(opts) -> dict:
    return {"BASIS_AMBIENT_DICE": 1}


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
"""
