"""The metallic-roughness BRDF terms of docs/conventions.md, in numpy. Mirrors kernels/brdf.h.

alpha = roughness^2 (perceptual roughness, Burley/Karis/glTF/Filament).
"""

from __future__ import annotations

import numpy as np

ALPHA_MIN = 1e-7  # keeps D and V finite at roughness 0 (a mirror is handled as a delta elsewhere)


def alpha_from_roughness(r):
    return np.asarray(r, dtype=np.float64) ** 2


def d_ggx(noh, alpha):
    """GGX / Trowbridge-Reitz NDF: alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2)."""
    a2 = np.maximum(np.asarray(alpha, dtype=np.float64) ** 2, ALPHA_MIN**2)
    noh = np.clip(noh, 0.0, 1.0)
    d = (1.0 - noh) * (1.0 + noh) + noh * noh * a2     # = noh^2 (a2 - 1) + 1, no cancellation
    return a2 / (np.pi * d * d)


def d_ggx_sc(sin2, cos2, alpha):
    """GGX D from sin^2 and cos^2 of the half vector's angle (kernels/ggx.h d_ggx_sc): sin^2 taken
    as |n x h|^2 keeps its relative precision for near-mirror lobes, where 1 - NoH does not (a
    normal 6e-8 off unit length in float32 moves NoH by more than 1 - cos of a 1e-4 lobe)."""
    a2 = np.maximum(np.asarray(alpha, dtype=np.float64) ** 2, ALPHA_MIN**2)
    d = sin2 + cos2 * a2
    return a2 / (np.pi * d * d)


def v_smith_ggx_correlated(nov, nol, alpha):
    """Height-correlated Smith visibility V = G / (4 NoV NoL) (Heitz 2014), as Filament's DFG code."""
    a2 = np.asarray(alpha, dtype=np.float64) ** 2
    nov = np.clip(nov, 0.0, 1.0)
    nol = np.clip(nol, 0.0, 1.0)
    lv = nol * np.sqrt(nov * nov * (1.0 - a2) + a2)
    ll = nov * np.sqrt(nol * nol * (1.0 - a2) + a2)
    return 0.5 / np.maximum(lv + ll, 1e-30)


def f_schlick(voh, f0, f90=1.0):
    return f0 + (f90 - f0) * (1.0 - np.clip(voh, 0.0, 1.0)) ** 5


def f_schlick_roughness(nov, f0, roughness, f90=1.0):
    """Roughness-aware Schlick (LearnOpenGL's fresnelSchlickRoughness, after Lagarde 2011) (used only for the diffuse weight kD)."""
    f0 = np.asarray(f0, dtype=np.float64)
    return f0 + (np.maximum(f90 - roughness, f0) - f0) * (1.0 - np.clip(nov, 0.0, 1.0)) ** 5


# --- sheen (KHR_materials_sheen; Estevez and Kulla 2017, "Production Friendly Microfacet Sheen BRDF")

SHEEN_ALPHA_MIN = 1e-6


def d_charlie(noh, alpha):
    """Charlie NDF (2 + 1/alpha) sin(theta_h)^(1/alpha) / (2 pi), alpha = sheen roughness^2;
    normalised: int D (n.h) dw_h = 1."""
    a = np.maximum(np.asarray(alpha, dtype=np.float64), SHEEN_ALPHA_MIN)
    noh = np.clip(noh, 0.0, 1.0)
    sin2 = (1.0 - noh) * (1.0 + noh)
    return (2.0 + 1.0 / a) * np.power(sin2, 0.5 / a) / (2.0 * np.pi)


def v_ashikhmin(nov, nol):
    """Ashikhmin and Premoze's visibility 1 / (4 (NoL + NoV - NoL NoV)) clamped to [0, 1], as the
    glTF Sample Viewer's sheen LUT has it (Filament's "Neubelt" without the clamp): unclamped,
    the sheen albedo at grazing NoV and low roughness grows without bound (174 at NoV 1e-4)."""
    nov, nol = np.clip(nov, 0.0, 1.0), np.clip(nol, 0.0, 1.0)
    return np.minimum(1.0 / np.maximum(4.0 * (nol + nov - nol * nov), 1e-30), 1.0)
