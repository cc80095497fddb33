"""ZH3 (Roughton, Sloan and Silvennoinen, "ZH3: Quadratic Zonal Harmonics", I3D 2024): L1 SH plus
one zonal L2 coefficient per channel along a single axis, the direction of the luminance-weighted
L1 vectors (common.luminance_axis; +y where they cancel), which the shader recomputes from the
stored L1, so the axis costs nothing. The zonal coefficient is the projection onto the unit
zonal harmonic Z(a.w) = sqrt(5/(16 pi)) (3 (a.w)^2 - 1); by the addition theorem
Z(a.w) = sqrt(4 pi/5) sum_m Y_2m(a) Y_2m(w), so z = sqrt(4 pi/5) sum_m Y_2m(a) L_2m from the L2
projection (core/sh.py). This is the paper's stored-coefficient ZH3 (5 floats a channel), not
its hallucinated variant (4).
Irradiance: pi Y0 L_00 + 2 pi/3 sum L_1m Y_1m(n) + pi/4 z Z(a.n), clamped at 0 (as SH).
Layout: 5 rows: the 4 L1 radiance coefficients (k = l (l + 1) + m), then z."""

from __future__ import annotations

import math

import numpy as np

from iblbake.core import sh as core_sh
from iblbake.core.bases import common

NAME = "zh3"
TITLE = "ZH3"
RANK = 2                # its place in BASES (the schema's choices, the CLI's, the studies')
HEADER = "basis_zh3.h"
OPTIONS: dict = {}
ZONAL = math.sqrt(5.0 / (16.0 * math.pi))
GLSL_COEFFS, GLSL_IRRADIANCE = "ZH3", "zh3Irradiance"     # glsl()'s names (the probes' sampler)


def variants() -> list:
    return [{}]


def label(opts) -> str:
    return "ZH3"


def floats(opts) -> int:
    return 5


def axis(coeffs) -> np.ndarray:
    c = np.asarray(coeffs, np.float64)
    return common.luminance_axis(np.stack([c[3], c[1], c[2]]))


def from_l2(sh9) -> np.ndarray:
    """ZH3 coefficients (5, C) from L2 radiance coefficients (9, C)."""
    sh9 = np.asarray(sh9, np.float64)
    a = axis(sh9[:4])
    y2 = core_sh.sh_basis(a, 3)[4:9]
    return np.concatenate([sh9[:4], (math.sqrt(4.0 * math.pi / 5.0) * y2 @ sh9[4:9])[None]])


def project(image, opts) -> np.ndarray:
    return from_l2(core_sh.project(image, 3))


def project_rays(values, dirs, opts) -> np.ndarray:
    """From probe rays: their L2 SH moments (common.ray_moments), then from_l2 per probe."""
    sh9 = common.ray_moments(values, dirs, lambda d: core_sh.sh_basis(d, 3))
    return np.stack([from_l2(c) for c in sh9.reshape(-1, *sh9.shape[-2:])]).reshape(*sh9.shape[:-2], 5, sh9.shape[-1])


def _zonal(coeffs, d):
    t = np.asarray(d, np.float64) @ axis(coeffs)
    return ZONAL * (3.0 * t * t - 1.0)


def radiance(coeffs, dirs, opts) -> np.ndarray:
    c = np.asarray(coeffs, np.float64)
    return core_sh.evaluate(c[:4], dirs, 2) + _zonal(c, dirs)[..., None] * c[4]


def irradiance(coeffs, normals, opts) -> np.ndarray:
    c = np.asarray(coeffs, np.float64)
    e = core_sh.evaluate(c[:4] * core_sh.ahat(2)[:, None], normals, 2)
    return np.maximum(0.0, e + core_sh.truncated_cos_sh(2) * _zonal(c, normals)[..., None] * c[4])


def document_fields(opts) -> dict:
    """What a document of ZH3 coefficients adds to evaluate them without this code (irradiance())."""
    from iblbake.core.metrics import LUMINANCE
    return {"formula": "E(n) = max(0, sum_{k<4} ahat[k] c_k Y_k(n) + ahat[4] zonal (3 (a.n)^2 - 1) c_4), Y_k the "
                       "real orthonormal SH (k = l (l + 1) + m), a the unit vector of sum_channels luminance[ch] "
                       "(c_3, c_1, c_2)[ch] (x, y, z; +y where it is 0)",
            "ahat": [math.pi, *[2.0 * math.pi / 3.0] * 3, core_sh.truncated_cos_sh(2)], "zonal": ZONAL,
            "luminance": LUMINANCE.tolist()}


def validate(coeffs, opts) -> np.ndarray:
    return common.check_coefficients(coeffs, 5, "ZH3 coefficients")


def defines(opts) -> dict:
    return {"BASIS_ZH3": 1}


def pack(coeffs, opts) -> np.ndarray:
    """5 rows (coefficient, rgb)."""
    return common.rgb_rows(coeffs, 5)


def glsl(coeffs, opts) -> str:
    y0, y1 = 0.5 / math.sqrt(math.pi), math.sqrt(3.0 / (4.0 * math.pi))
    return f"""// iblbake ZH3 (Roughton, Sloan, Silvennoinen 2024): L1 radiance SH (k = l (l + 1) + m; Y1 ~ y, Y2 ~ z,
// Y3 ~ x) and one zonal L2 coefficient along the luminance L1 axis; world +y up.
// diffuse = albedo / PI * zh3Irradiance(normalize(N));
{common.glsl_vec3_array("ZH3", np.asarray(coeffs)[:, :3])}

vec3 zh3Irradiance(vec3 n) {{
    vec3 lum = vec3(0.2126, 0.7152, 0.0722);
    vec3 v = vec3(dot(ZH3[3], lum), dot(ZH3[1], lum), dot(ZH3[2], lum));
    vec3 a = dot(v, v) > 0.0 ? normalize(v) : vec3(0.0, 1.0, 0.0);
    float t = dot(a, n);
    vec3 e = 3.14159265358979 * {y0:.9g} * ZH3[0]
           + (2.0 * 3.14159265358979 / 3.0) * {y1:.9g} * (ZH3[1] * n.y + ZH3[2] * n.z + ZH3[3] * n.x)
           + (3.14159265358979 / 4.0) * {ZONAL:.9g} * (3.0 * t * t - 1.0) * ZH3[4];
    return max(e, vec3(0.0));
}}
"""
