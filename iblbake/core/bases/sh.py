"""Spherical harmonics as a basis (core/sh.py has the math: L1 = 2 bands, L2 = 3, L3 = 4, and
the ringing windows, Sloan 2008). Its kernel side is render/sources/sh.py and kernels/sh.h, the
scene's `effects.sh_bands` and `effects.sh_window`: no options of its own here.
Layout: bands^2 rows, k = l (l + 1) + m, of per-channel radiance coefficients (windowed)."""

from __future__ import annotations

import numpy as np

from iblbake.core import sh as core_sh
from iblbake.core.bases import common

NAME = "sh"
TITLE = "SH"
RANK = 0                # its place in BASES (the schema's choices, the CLI's, the studies')
HEADER = None          # render/sources/sh.py
OPTIONS: dict = {}


def variants() -> list:
    return [{"sh_bands": 2, "sh_window": "none"}, {"sh_bands": 3, "sh_window": "none"},
            {"sh_bands": 3, "sh_window": "hann"}, {"sh_bands": 3, "sh_window": "lanczos"},
            {"sh_bands": 4, "sh_window": "none"}]


def label(opts) -> str:
    w = opts.get("sh_window", "none")
    return f"SH L{opts['sh_bands'] - 1}" + ("" if w == "none" else f" {w}")


def floats(opts) -> int:
    return opts["sh_bands"] ** 2


def project(image, opts) -> np.ndarray:
    b = opts["sh_bands"]
    return core_sh.project(image, b) * core_sh.window(b, opts.get("sh_window", "none"))[:, None]


def radiance(coeffs, dirs, opts) -> np.ndarray:
    return core_sh.evaluate(coeffs, dirs, opts["sh_bands"])


def irradiance(coeffs, normals, opts) -> np.ndarray:
    b = opts["sh_bands"]
    return core_sh.irradiance(np.asarray(coeffs) * core_sh.ahat(b)[:, None], normals, b)


def validate(coeffs, opts) -> np.ndarray:
    return common.check_coefficients(coeffs, opts["sh_bands"] ** 2, f"SH {opts['sh_bands']}-band coefficients")
