"""L1 SH with Geomerics' non-linear reconstruction (Enlighten; as in Roughton, Sloan and
Silvennoinen 2024 and Unity's shEvaluateDiffuseL1Geomerics): the 4 L1 radiance coefficients,
their irradiance reconstructed per channel as a power of the cosine to the L1 direction instead
of the linear L1 polynomial, so it never goes negative and sharpens for a directional sky.

With the linear irradiance E0 + e.n of the L1 coefficients (E0 = pi Y0 L_00, the mean irradiance;
e = 2 pi/3 * 0.488603 (L_11, L_1-1, L_10), x y z):
    R0 = E0, R1 = e / 2, r = |R1| / R0 (clamped to [0, 1]), q = (1 + n.R1/|R1|) / 2,
    p = 1 + 2 r, a = (1 - r)/(1 + r), E(n) = R0 (a + (1 - a)(p + 1) q^p).
The mean of q^p over the sphere is 1/(p + 1), so E keeps the mean irradiance R0 exactly; a
uniform sky (r = 0) gives R0 everywhere.
Layout: 4 rows, k = l (l + 1) + m, of per-channel radiance coefficients."""

from __future__ import annotations

import math

import numpy as np

from iblbake.core import sh as core_sh
from iblbake.core.bases import common

NAME = "l1_geomerics"
TITLE = "L1 Geomerics"
RANK = 1                # its place in BASES (the schema's choices, the CLI's, the studies')
HEADER = "basis_l1_geomerics.h"
OPTIONS: dict = {}
LIGHTMAP = False        # uniform light over a texel's hemisphere, black below, reads 7/6 of its irradiance
Y0 = 0.5 / math.sqrt(math.pi)
Y1 = math.sqrt(3.0 / (4.0 * math.pi))
GLSL_COEFFS, GLSL_IRRADIANCE = "L1_SH", "l1GeomericsIrradiance"     # glsl()'s names (the probes' sampler)


def variants() -> list:
    return [{}]


def label(opts) -> str:
    return "SH L1 Geomerics"


def floats(opts) -> int:
    return 4


def project(image, opts) -> np.ndarray:
    return core_sh.project(image, 2)


def project_rays(values, dirs, opts) -> np.ndarray:
    """From probe rays: their L1 SH moments (common.ray_moments), (P, 4, C)."""
    return common.ray_moments(values, dirs, lambda d: core_sh.sh_basis(d, 2))


def radiance(coeffs, dirs, opts) -> np.ndarray:
    return core_sh.evaluate(coeffs, dirs, 2)


def irradiance(coeffs, normals, opts) -> np.ndarray:
    c = np.asarray(coeffs, np.float64)
    n = np.asarray(normals, np.float64)
    out = np.zeros(n.shape[:-1] + (c.shape[1],))
    for ch in range(c.shape[1]):
        r0 = math.pi * Y0 * c[0, ch]
        r1 = 0.5 * (2.0 * math.pi / 3.0) * Y1 * np.array([c[3, ch], c[1, ch], c[2, ch]])
        if r0 <= 0.0:
            continue
        length = float(np.linalg.norm(r1))
        r = min(length / r0, 1.0)
        q = 0.5 * (1.0 + n @ (r1 / length)) if length > 0 else np.full(n.shape[:-1], 0.5)
        p, a = 1.0 + 2.0 * r, (1.0 - r) / (1.0 + r)
        out[..., ch] = r0 * (a + (1.0 - a) * (p + 1.0) * np.clip(q, 0.0, 1.0) ** p)
    return out


def validate(coeffs, opts) -> np.ndarray:
    return common.check_coefficients(coeffs, 4, "L1 Geomerics coefficients")


def defines(opts) -> dict:
    return {"BASIS_L1_GEOMERICS": 1}


def pack(coeffs, opts) -> np.ndarray:
    """4 rows (coefficient k, rgb)."""
    return common.rgb_rows(coeffs, 4)


def glsl(coeffs, opts) -> str:
    return f"""// iblbake L1 SH with Geomerics' non-linear reconstruction; radiance coefficients k = l (l + 1) + m,
// real orthonormal SH (Y1 ~ y, Y2 ~ z, Y3 ~ x); world +y up.
// diffuse = albedo / PI * l1GeomericsIrradiance(normalize(N));
{common.glsl_vec3_array("L1_SH", np.asarray(coeffs)[:, :3])}

float l1GeomericsChannel(float l0, vec3 l1, vec3 n) {{
    float r0 = 3.14159265358979 * {Y0:.9g} * l0;
    vec3 r1 = (3.14159265358979 / 3.0) * {Y1:.9g} * l1;
    if (r0 <= 0.0) return 0.0;
    float len = length(r1), r = min(len / r0, 1.0);
    float q = len > 0.0 ? clamp(0.5 * (1.0 + dot(n, r1 / len)), 0.0, 1.0) : 0.5;
    float p = 1.0 + 2.0 * r, a = (1.0 - r) / (1.0 + r);
    return r0 * (a + (1.0 - a) * (p + 1.0) * pow(q, p));
}}

vec3 l1GeomericsIrradiance(vec3 n) {{
    vec3 e;
    for (int c = 0; c < 3; ++c)
        e[c] = l1GeomericsChannel(L1_SH[0][c], vec3(L1_SH[3][c], L1_SH[1][c], L1_SH[2][c]), n);
    return e;
}}
"""
