"""What a lightmap texel keeps of its rays (`lightmap.basis`): the non-directional irradiance, the
L1 SH with its reading at the texel's normal made exact (sh_l1), or any coefficient basis of the
irradiance probes' registry a texel may hold (core/bases/probes.py PROBE_BASES, `lightmap`: L2 SH,
ZH3, SG, ambient dice; not L1 Geomerics, which reads a hemisphere's light 7/6 bright), fitted by
that basis's own project_rays and read by its own irradiance_at: a texel is a probe with a
hemisphere of rays. The octahedral atlas is left out (a tile of n x n texels a
texel). Per texel, rays over its hemisphere, each with its share w of it (solid angle; the bake's
mix of uniform and panorama-importance rays, render/lightmaps/bake.py texel_rays):
  irradiance  E(n) = sum w L cos (RGB)
  sh_l1       L_lm = sum w L Y_lm, then L_00 moved so that the reading at the texel's normal is its
              E (the linear L1 reading weighs a direction by 1/4 + cos/2, not max(cos, 0): light met
              head-on is read 25% low; Unity's directional lightmaps keep irradiance + direction)
  a registry basis fitted for the irradiance with a linear reading (L2 SH; SG and ambient dice
              with their `irradiance` fit): least squares of its irradiance against the rays' own
              at NORMALS normals over the texel's hemisphere, the only normals a lightmap is read
              at (a normal map's); the error at the texel's normal 0.55-0.68x that of the fit
              below on quad_room and the corridor (SG12 0.77x and 1.1x, better tilted), level
              at 60 degrees
  the others (ZH3, L1 Geomerics, the radiance fits): the registry's own project_rays, the lower
              hemisphere (behind the surface, where no light comes from) entering it as black:
              each ray's mirror image through the tangent plane with radiance 0, so the rays share
              the sphere equally as the probes' fits expect (BakingLab's SH lightmaps integrate
              the lower half as zero)
A basis that carries a specular lobe (LOBED: sg, ambient dice) keeps, where the frame reads
`specular: lightmap`, a second set for it (project_specular): its own fit of the radiance with its
SPECULAR_DEFAULTS (NNLS), the lower hemisphere the upper's mirror.
docs/manual.md 'Lightmaps' has each basis's error at normals tilted off the texel's."""

from __future__ import annotations

import math

import numpy as np

from iblbake.core import sh
from iblbake.core.bases.probes import PROBE_BASES
from iblbake.errors import InputError
from iblbake.scene.schema import LIGHTMAP_BASES as NAMES
from iblbake.scene.schema import LIGHTMAP_LOBED as LOBED  # noqa: F401  (bake's, store's: a second set)

OWN = NAMES[:2]         # irradiance, sh_l1: this module's; the rest the registry's
CHUNK = 256             # texels projected at once (the registry's fits hold texels x 2 samples x floats)
NORMALS = 128           # normals over a texel's hemisphere its irradiance is fitted at (hemisphere_fitted)


def options(name: str, settings: dict) -> dict:
    """The basis's options from a lightmap section (PROBE_BASES' keys: sg_lobes, sg_fit, ad_fit),
    each one of its choices (an InputError naming the key otherwise: the API's settings are not
    the schema's)."""
    if name in OWN:
        return {}
    specs, opts = PROBE_BASES[name].option_specs, PROBE_BASES[name].options(settings)
    for k, v in opts.items():
        if isinstance(v, bool) or v not in specs[k][0]:
            raise InputError(f"lightmap.{k}: {v!r} is not one of {', '.join(map(str, specs[k][0]))}")
    return opts


def floats(name: str, opts: dict) -> int:
    """RGB coefficients a texel keeps."""
    return {"irradiance": 1, "sh_l1": 4}[name] if name in OWN else PROBE_BASES[name].floats(opts)


def project(name: str, radiance, dirs, normals, opts: dict, weights=None):
    """(E (k, 3), the basis's coefficients (k, floats, 3)) of texels from their rays' radiance
    (k, s, 3) along dirs (k, s, 3) over the hemisphere of normals (k, 3), each ray's share of the
    hemisphere in weights (k, s) (solid angle: the sum over rays of w L f estimates the integral of
    L f; None: uniform rays, 2 pi / s each)."""
    radiance = _weighted(radiance, weights)          # from here on w L: each fit a sum over rays
    e = np.einsum("ksc,ksx,kx->kc", radiance, dirs, normals)
    if name == "irradiance":
        return e, e[:, None]
    if name == "sh_l1":
        return e, _sh_l1(radiance, dirs, normals, e)
    basis = PROBE_BASES[name]
    hemi = hemisphere_fitted(name, opts)
    out = np.empty((len(e), basis.floats(opts), 3))
    for a in range(0, len(e), CHUNK):
        r, d, n = radiance[a:a + CHUNK], dirs[a:a + CHUNK], normals[a:a + CHUNK]
        out[a:a + CHUNK] = (_hemisphere_fit if hemi else _black_below)(basis, r, d, n, opts)
    return e, out


def specular_options(name: str, opts: dict) -> dict:
    """The options of the texels' second set, the one the specular lobe reads (`effects.specular:
    lightmap`): the basis's, fitted for the radiance as its SPECULAR_DEFAULTS say (NNLS: least
    squares rings negative around a sun, black patches on metals; core/bases/sg.py)."""
    return {**opts, **getattr(PROBE_BASES[name].m, "SPECULAR_DEFAULTS", {})}


def project_specular(name: str, radiance, dirs, normals, opts: dict, weights=None):
    """The texels' second set (k, floats, 3), for the specular lobe: the basis's fit of the radiance
    (rays and weights as project's) with specular_options over the sphere, the lower hemisphere the
    upper one's mirror image (the lobe's tail past the horizon reads the light just above it, not
    black: a uniform sky is uniform, so read exactly)."""
    basis, spec = PROBE_BASES[name], specular_options(name, opts)
    radiance = _weighted(radiance, weights)
    out = np.empty((len(radiance), basis.floats(spec), 3))
    for a in range(0, len(radiance), CHUNK):
        r, d, n = radiance[a:a + CHUNK], dirs[a:a + CHUNK], normals[a:a + CHUNK]
        out[a:a + CHUNK] = _sphere_fit(basis, r, d, n, spec, r)
    return out


def _weighted(radiance, weights):
    """w L: each ray's radiance (k, s, 3) times its share of the hemisphere (k, s); None: uniform
    rays, 2 pi / s each."""
    if weights is None:
        weights = np.full(radiance.shape[:2], 2 * math.pi / radiance.shape[1])
    return radiance * weights[..., None]


def _black_below(basis, radiance, dirs, normals, opts):
    """The basis's own fit of the sphere, the lower hemisphere entering it as black."""
    return _sphere_fit(basis, radiance, dirs, normals, opts, np.zeros_like(radiance))


def _sphere_fit(basis, radiance, dirs, normals, opts, below):
    """The basis's own fit (project_rays) of the rays (radiance: w L) and their mirror images through
    the tangent plane, those of `below` (k, s, 3)."""
    mirror = dirs - 2 * np.einsum("ksx,kx->ks", dirs, normals)[..., None] * normals[:, None]
    # the registry's fits take moments 4 pi / R sum L f over R = 2 s rays (common.ray_moments)
    lit = np.concatenate([radiance, below], 1) * (2 * radiance.shape[1] / (4 * math.pi))
    return basis.project_rays(lit, np.ones(lit.shape[:2]), np.ones(len(radiance), bool),
                              np.concatenate([dirs, mirror], 1), opts)


def hemisphere_fitted(name: str, opts: dict) -> bool:
    """Whether a registry basis is fitted on the irradiance over its texel's hemisphere of normals:
    one fitted for the irradiance (L2 SH, an `irradiance` fit) whose reading is linear."""
    basis = PROBE_BASES[name]
    return (not opts or "irradiance" in opts.values()) and basis.irradiance_columns(np.eye(3), opts) is not None


def hemisphere_normals(normals) -> np.ndarray:
    """(k, NORMALS, 3): the Fibonacci lattice's upper half about each normal (Duff's frame), equal
    shares of the hemisphere."""
    from iblbake.core.bases.common import fibonacci_sphere
    from iblbake.render.lightmaps.bake import frames
    f = fibonacci_sphere(2 * NORMALS)
    f = f[f[:, 1] > 0]
    t, b = frames(normals)
    return f[:, 0, None] * t[:, None] + f[:, 2, None] * b[:, None] + f[:, 1, None] * normals[:, None]


def _hemisphere_fit(basis, radiance, dirs, normals, opts):
    """Least squares of the basis's irradiance (its columns, linear) against the rays' own at
    NORMALS normals over the texel's hemisphere, the minimum-norm solution (ambient dice's columns
    are dependent): (k, floats, 3). radiance: w L, each ray's times its share."""
    nn = hemisphere_normals(normals)
    cos = np.maximum(0.0, np.einsum("kmx,ksx->kms", nn, dirs))
    want = np.einsum("kms,ksc->kmc", cos, radiance)
    a = basis.irradiance_columns(nn, opts)                           # (k, NORMALS, floats)
    g = np.linalg.pinv(np.einsum("kmi,kmj->kij", a, a), rcond=1e-10, hermitian=True)
    return np.einsum("kij,kmj,kmc->kic", g, a, want)


def _sh_l1(radiance, dirs, normals, e):
    """The L1 SH of the radiance over the hemisphere (radiance: w L, each ray's times its share),
    L_00 moved to read E at the normal."""
    coeffs = np.einsum("ksc,ksj->kjc", radiance, sh.sh_basis(dirs, 2))
    linear = np.einsum("kj,kjc->kc", sh.sh_basis(normals, 2), coeffs * sh.ahat(2)[:, None])
    coeffs[:, 0] += (e - linear) / (math.pi * sh.sh_basis(normals[:1], 2)[0, 0])
    return coeffs


def sh_irradiance(coeffs, normals):
    """E at unit normals (..., 3) from the L1 SH of the radiance (..., 4, 3) (clamped at 0)."""
    e = coeffs * sh.ahat(2)[:, None]
    return np.maximum(0.0, np.einsum("...j,...jc->...c", sh.sh_basis(normals, 2), e))


def irradiance(name: str, coeffs, normals, opts: dict) -> np.ndarray:
    """E (n, 3) at unit normals (n, 3) from each point's coefficients (n, floats, 3), float64,
    clamped at 0."""
    coeffs = np.asarray(coeffs, np.float64)
    if name == "irradiance":
        return np.maximum(0.0, coeffs[:, 0])
    if name == "sh_l1":
        return sh_irradiance(coeffs, normals)
    basis = PROBE_BASES[name]
    cols = basis.irradiance_columns(normals, opts)          # a linear reading: every point at once
    if cols is not None:
        return np.maximum(0.0, np.einsum("nk,nkc->nc", cols, coeffs))
    return np.maximum(0.0, basis.irradiance_at(coeffs, np.arange(len(coeffs)), normals, opts))
