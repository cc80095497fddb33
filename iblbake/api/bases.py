"""A panorama in a directional basis other than SH (l1_geomerics, zh3, sg, ambient_dice, haar)."""

from __future__ import annotations

import time
from dataclasses import dataclass

from iblbake.api.bakes import ERROR_BYTES_PER_TEXEL, TABLE_BYTES
from iblbake.api.guards import _arguments, _choice, _fits, _flag, _intensity, _shown, _vectors, _whole
from iblbake.api.panorama import Panorama, _panorama
from iblbake.errors import InputError

# host memory of a basis's fit a texel, its design rows (measured as iblbake.api.bakes's constants)
BASIS_BYTES_PER_TEXEL = 160


@dataclass
class Basis:
    """A panorama's light in a directional basis other than SH (docs/conventions.md "Directional
    bases": l1_geomerics, zh3, sg, ambient_dice, haar), in the world frame (+y up).

    name, options: the basis and its options (sg: sg_lobes, sg_fit; haar: haar_coefficients).
    label: its name in tables ("SG9 irradiance"). coefficients: float64 (rows, 3) of radiance
        coefficients, rows as document['layout'] says (haar: (rows, 4), the 4th column each
        kept coefficient's code).
    error: the irradiance against the exact (float64, every texel) at 256 normals
        (relative_rmse, max_relative_error), or None. document: the JSON `iblbake basis` writes.
    specular: whether the basis carries a specular lobe (sg, ambient_dice).
    """

    name: str
    options: dict
    label: str
    coefficients: object
    error: dict | None
    document: dict

    @property
    def specular(self) -> bool:
        from iblbake.core import bases
        return self.name in bases.SPECULAR

    def irradiance(self, normals):
        """E(n) = int L max(0, n.w) dw at unit normals (..., 3): (..., 3), clamped at 0."""
        from iblbake.core import bases
        return bases.BASES[self.name].irradiance(self.coefficients, _vectors("normals", normals), self.options)

    def specular_radiance(self, normals, views, roughness):
        """The radiance along the warped GGX lobe (the split sum's first factor from the basis:
        times the DFG table's F0 A + F90 B it is the specular light): unit normals and unit
        vectors towards the viewer (..., 3), perceptual roughness (...,) or a number: (..., 3).
        Only for a basis that carries a specular lobe (sg, ambient_dice)."""
        import numpy as np

        from iblbake.core import bases
        from iblbake.core.bases import common
        if not self.specular:
            raise InputError(f"basis {self.name} carries no specular lobe: use one of {', '.join(bases.SPECULAR)}")
        n, v = _vectors("normals", normals), _vectors("views", views)
        if n.shape != v.shape:
            raise InputError(f"views: shape {v.shape}, normals {n.shape}: give one view a normal")
        try:
            if isinstance(roughness, str):
                raise TypeError
            r = np.asarray(roughness, np.float64)
            alpha = np.broadcast_to(r ** 2, n.shape[:-1])
        except (TypeError, ValueError):
            raise InputError(f"roughness: give a number or an array {n.shape[:-1]} of numbers 0 to 1, "
                             f"not {_shown(roughness)}") from None
        if not ((r >= 0) & (r <= 1)).all():
            raise InputError("roughness: give perceptual roughness 0 to 1")
        nov = np.clip((n * v).sum(-1), 0.0, 1.0)
        return bases.specular_radiance(self.name, self.coefficients, common.lobe_axis(n, v, alpha),
                                       common.warp_sharpness(alpha, nov), self.options)

    def to_glsl(self) -> str:
        """The basis's GLSL: its coefficients and an irradiance function (and, for sg, a
        specular one); `iblbake basis --glsl` prints it."""
        from iblbake.core import bases
        return bases.BASES[self.name].glsl(self.coefficients, self.options)

    def export(self, fmt: str = "iblbake") -> str:
        """The text `iblbake basis --format FMT` writes: iblbake (the JSON document) or glsl."""
        import json
        _choice("format", fmt, ("iblbake", "glsl"))
        return self.to_glsl() if fmt == "glsl" else json.dumps(self.document, indent=1) + "\n"


@_arguments
def basis(panorama: Panorama, name: str, *, intensity: float = 1.0, error: bool = True, **options) -> Basis:
    """Project a panorama onto a directional basis (float64, exact texel integrals; least squares
    where the basis's lobes are not orthogonal).

    name: l1_geomerics, zh3, sg, ambient_dice or haar (spherical harmonics: iblbake.sh).
    options: the basis's own (sg_lobes 5 | 6 | 9 | 12, sg_fit and ad_fit 'irradiance' |
        'least_squares' | 'nnls'; haar_coefficients 16 | 32 | 64 | 128 | 256); the schema's defaults where left out.
    intensity: a scale of the radiance (>= 0). error: measure the irradiance (Basis.error).
    """
    from iblbake.bake import bases as bakebases
    from iblbake.core import bases

    _panorama(panorama)
    names = tuple(n for n in bases.BASES if n != "sh")
    if name == "sh":
        raise InputError("basis sh: spherical harmonics are iblbake.sh (bands, window)")
    _choice("basis", name, names)
    m = bases.BASES[name]
    for k in options:
        if k not in m.OPTIONS:
            raise InputError(f"{k}: not an option of basis {name}"
                             + (f" (its options: {', '.join(m.OPTIONS)})" if m.OPTIONS else " (it has none)"))
    opts = {}
    for k, (choices, default, _doc) in m.OPTIONS.items():
        value = options.get(k, default)
        # a count is a whole number (9, not 9.0, which would label the basis "SG9.0"), a fit a string
        fits = _whole(value) if all(_whole(c) for c in choices) else isinstance(value, str)
        if not (fits and value in choices):
            raise InputError(f"{k} {_shown(value)}: use one of {', '.join(map(str, choices))}")
        opts[k] = int(value) if _whole(value) else value
    intensity = _intensity(panorama, intensity)
    error = _flag("error", error)
    _fits(f"basis {name} of a {panorama.width}x{panorama.height} panorama",
          (BASIS_BYTES_PER_TEXEL + ERROR_BYTES_PER_TEXEL * error) * panorama.width * panorama.height + TABLE_BYTES,
          "use a smaller panorama" + (" or error=False" if error else ""))
    t0 = time.perf_counter()
    coeffs = m.project(panorama.pixels[..., :3], opts)
    coeffs[:, :3] *= intensity
    timings = {"read_s": round(panorama.read_s, 6), "project_s": round(time.perf_counter() - t0, 6)}
    read = {**{k: v for k, v in panorama.policies.items() if k != "layout"},
            "input_layout": panorama.policies["layout"], "intensity": intensity}
    doc = bakebases.document(coeffs, name=name, opts=opts, info=panorama.info, options=read, timings=timings)
    if error:
        t1 = time.perf_counter()
        doc["error"] = bakebases.irradiance_error(panorama.pixels, name, opts, coeffs, intensity)
        doc["timings"]["error_s"] = round(time.perf_counter() - t1, 6)
    doc["elapsed_s"] = round(panorama.read_s + time.perf_counter() - t0, 6)
    return Basis(name, opts, m.label(opts), coeffs, doc.get("error"), doc)
