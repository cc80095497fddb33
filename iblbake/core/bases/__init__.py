"""The directional bases of the distant environment's diffuse light, registered once: each module
here is one basis (its float64 projection and evaluation, the twin of its kernel header; its
coefficient layout and checks; its GLSL function), found by its NAME and placed by its RANK, and
the scene's `effects.diffuse` choices and options, the render source (render/sources/basis.py),
the probes' bases (probes.py), the kernels' list of headers (kernels/basis_headers.h, generated),
`iblbake basis`, the tests and the shoot-out (benchmarks/bench_bases.py) are derived from BASES.
`sh` keeps its own kernel source (render/sources/sh.py; HEADER None). Adding a basis:
docs/conventions.md "Directional bases"."""

from __future__ import annotations

import importlib
import pkgutil

import numpy as np

REGISTRIES = ("probes",)       # modules here built from BASES (imported after it)


def _found() -> list:
    """The modules here that are a basis (a NAME), in RANK order."""
    mods = [importlib.import_module(f"{__name__}.{m.name}") for m in pkgutil.iter_modules(__path__)
            if m.name not in REGISTRIES]
    return sorted((m for m in mods if hasattr(m, "NAME")), key=lambda m: m.RANK)


BASES = {m.NAME: m for m in _found()}

# the ones evaluated by the generic source and kernels/bases.h (sh has its own)
DIFFUSE = tuple(n for n, m in BASES.items() if m.HEADER)
# the ones that carry a specular lobe (specular_weights, kernels/bases.h basis_specular_radiance):
# `effects.specular: <name>` for the panorama, `specular: probes` for probes that store one
SPECULAR = tuple(n for n, m in BASES.items() if m.HEADER and getattr(m, "SPECULAR", False))


def frame_basis(effects: dict) -> str | None:
    """The one basis a frame's shade pass compiles (kernels/bases.h: one BASIS_<NAME>): the diffuse
    one, else the specular one (scene/load.py refuses two different ones)."""
    if effects["diffuse"] in DIFFUSE:
        return effects["diffuse"]
    return effects["specular"] if effects["specular"] in SPECULAR else None


def probe_bytes(name: str, opts: dict, bytes_per_float: int) -> int:
    """Bytes per probe: floats x 3 channels x bytes_per_float, and the indices a non-linear basis
    (Haar) keeps beside its values."""
    m = BASES[name]
    return m.floats(opts) * 3 * bytes_per_float + (m.index_bytes(opts) if hasattr(m, "index_bytes") else 0)


def options_of(name: str, effects: dict) -> dict:
    """The scene's options of basis `name` (its OPTIONS keys from effects)."""
    return {k: effects[k] for k in BASES[name].OPTIONS}


def specular_variants(name: str) -> list:
    """The variants of a basis with a specular lobe that fit it for the lobe: not those fitted on
    the irradiance (their amplitudes make the cosine-convolved lobes, not the radiance along one)."""
    return [o for o in BASES[name].variants() if "irradiance" not in o.values()]


def specular_radiance(name: str, coeffs, r, lam_w, opts: dict) -> np.ndarray:
    """The radiance (..., C) along the warped GGX lobe about r (..., 3) of sharpness lam_w (...,)
    (common.lobe_axis, common.warp_sharpness) from basis `name`'s coefficients (K, C): linear in
    them, sum_k s_k c_k with the basis's specular_weights s, clamped at 0 (kernels/bases.h)."""
    s = BASES[name].specular_weights(r, lam_w, opts)
    return np.maximum(0.0, s @ np.asarray(coeffs, np.float64))


def specular_table(name: str, opts: dict) -> np.ndarray | None:
    """The table a basis's kernel reads its specular weights from (float32, flat; kernels/bases.h
    basis_table), or None where it has a closed form."""
    m = BASES[name]
    return m.specular_table(opts).astype(np.float32).ravel() if hasattr(m, "specular_table") else None
