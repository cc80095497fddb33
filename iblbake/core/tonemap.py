"""Tone mapping (docs/conventions.md), numpy twin of kernels/tonemap.h.

Exposure first (linear x 2^EV), then the operator, then the output transfer. Inputs are made
safe before anything else: NaN and negatives become 0, and values are capped at 1e18 (every
operator maps that to white; the cap keeps x^2 terms finite in float32), so NaN, negative or
infinite radiance never reaches a frame.
"""

from __future__ import annotations

import numpy as np

from iblbake.core import sampling

OPERATORS = ("aces", "reinhard", "hable", "pbr_neutral", "linear")
TRANSFERS = ("srgb", "gamma")
INPUT_CAP = 1e18
HABLE_WHITE = 11.2


def sanitize(x):
    """NaN -> 0, negative -> 0, +Inf and huge -> INPUT_CAP (np.fmax/fmin ignore NaN, like OpenCL)."""
    return np.fmin(np.fmax(np.asarray(x, dtype=np.float64), 0.0), INPUT_CAP)


def reinhard(x):
    return x / (1.0 + x)


def aces(x):
    """Narkowicz 2015 fit of the ACES filmic curve."""
    return np.clip((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)


def _hable_curve(x):
    a, b, c, d, e, f = 0.15, 0.50, 0.10, 0.20, 0.02, 0.30
    return (x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f) - e / f


def hable(x):
    """Uncharted 2 (Hable 2010), normalised by the white point 11.2 (no extra exposure bias)."""
    return np.clip(_hable_curve(x) / _hable_curve(HABLE_WHITE), 0.0, 1.0)


def pbr_neutral(rgb):
    """Khronos PBR Neutral, as its specification states (F90 = 0.04, Ks = 0.8 - F90, Kd = 0.15)."""
    rgb = np.asarray(rgb, dtype=np.float64)
    f90, kd = 0.04, 0.15
    ks = 0.8 - f90
    x = rgb.min(axis=-1, keepdims=True)
    f = np.where(x <= 2 * f90, x - x * x / (4 * f90), f90)
    c = rgb - f
    p = c.max(axis=-1, keepdims=True)
    pn = 1.0 - (1.0 - ks) ** 2 / (p + 1.0 - 2.0 * ks)
    g = 1.0 / (kd * (p - pn) + 1.0)
    compressed = c * (pn / np.maximum(p, 1e-30)) * g + pn * (1.0 - g)
    return np.where(p <= ks, c, compressed)


def linear(x):
    return np.clip(x, 0.0, 1.0)


def srgb_encode(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def tonemap(hdr, operator: str = "aces", exposure_ev: float = 0.0, transfer: str = "srgb",
            gamma: float = 2.2):
    """Linear HDR RGB (..., 3) -> display-encoded values in [0, 1] (float64)."""
    if operator not in OPERATORS:
        raise ValueError(f"unknown tone-mapping operator {operator!r}; choose one of {', '.join(OPERATORS)}")
    x = sanitize(sanitize(hdr) * 2.0 ** exposure_ev)
    if operator == "pbr_neutral":
        y = pbr_neutral(x)
    else:
        y = {"aces": aces, "reinhard": reinhard, "hable": hable, "linear": linear}[operator](x)
    y = np.clip(y, 0.0, 1.0)
    if transfer == "srgb":
        return srgb_encode(y)
    return np.power(y, 1.0 / gamma)


def to_u8(display):
    """Quantise display values in [0, 1] to 8 bits (round to nearest)."""
    return np.clip(np.floor(np.asarray(display) * 255.0 + 0.5), 0, 255).astype(np.uint8)


def dither_offsets(n: int):
    """Triangular dither in LSB units (-1, 1) per pixel index; twin of kernels/tonemap.cl DITHER."""
    h1 = sampling.pcg_hash(np.arange(n, dtype=np.uint64))
    h2 = sampling.pcg_hash(h1)
    u = ((h1 >> 8).astype(np.float64) + (h2 >> 8).astype(np.float64)) / 16777216.0
    return u - 1.0


def to_u8_dithered(display):
    """8-bit quantisation with the renderer's deterministic triangular dither."""
    d = np.asarray(display, np.float64)
    flat = d.reshape(-1, d.shape[-1])
    off = dither_offsets(len(flat))[:, None]
    return np.clip(np.floor(flat * 255.0 + 0.5 + off), 0, 255).astype(np.uint8).reshape(d.shape)


def display_u8(hdr, effects: dict, dither: bool = False):
    """A frame's 8-bit display image on the host, (..., 3) uint8: a scene's effects (tonemap,
    exposure, output_transfer, gamma) applied to hdr's RGB, as kernels/tonemap.cl does, with its
    dither where asked."""
    d = tonemap(np.asarray(hdr)[..., :3], effects["tonemap"], effects["exposure"], effects["output_transfer"],
                effects["gamma"])
    return to_u8_dithered(d) if dither else to_u8(d)
