"""Sample sets and warps, in pairs sample_x / pdf_x (pbrt-v4's habit). Mirrors kernels/sampling.h."""

from __future__ import annotations

import numpy as np

from iblbake.core import brdf
from iblbake.core import conventions


def radical_inverse_vdc(i):
    """Van der Corput radical inverse in base 2 of 32-bit integers: bits mirrored about the point."""
    b = np.asarray(i, dtype=np.uint64) & 0xFFFFFFFF
    b = ((b << 16) | (b >> 16)) & 0xFFFFFFFF
    b = ((b & 0x55555555) << 1) | ((b & 0xAAAAAAAA) >> 1)
    b = ((b & 0x33333333) << 2) | ((b & 0xCCCCCCCC) >> 2)
    b = ((b & 0x0F0F0F0F) << 4) | ((b & 0xF0F0F0F0) >> 4)
    b = ((b & 0x00FF00FF) << 8) | ((b & 0xFF00FF00) >> 8)
    return b.astype(np.float64) * (1.0 / 4294967296.0)


def hammersley(n: int):
    """The N-point Hammersley set (i/N, radical_inverse(i)), shape (N, 2)."""
    i = np.arange(n)
    return np.stack([i / n, radical_inverse_vdc(i)], axis=-1)


def sample_ggx_half(u, alpha):
    """GGX half-vector in the local frame (z = normal) from u in [0,1)^2.

    phi = 2 pi u0, theta = atan2(alpha sqrt(u1), sqrt(1 - u1)) (finite at u1 -> 1);
    pdf over half-vectors = D(h) cos(theta_h)  (pdf_ggx_half).
    """
    u = np.asarray(u, dtype=np.float64)
    phi = 2.0 * np.pi * u[..., 0]
    theta = np.arctan2(np.asarray(alpha) * np.sqrt(u[..., 1]), np.sqrt(np.maximum(0.0, 1.0 - u[..., 1])))
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def pdf_ggx_half(noh, alpha):
    return brdf.d_ggx(noh, alpha) * np.clip(noh, 0.0, 1.0)


def pdf_ggx_reflected(noh, voh, alpha):
    """pdf of l = reflect(-v, h) when h ~ pdf_ggx_half: D(h) NoH / (4 VoH) (Jacobian 1/(4 VoH))."""
    return pdf_ggx_half(noh, alpha) / np.maximum(4.0 * voh, 1e-30)


def to_world(local, n):
    """Local (x, y, z = n) vectors to world, with the Duff et al. frame of DESIGN.md."""
    t, b = conventions.tangent_frame(n)
    return local[..., 0:1] * t + local[..., 1:2] * b + local[..., 2:3] * np.asarray(n)
