"""Panoramas: an environment as the bakes read it, from a file or an array."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from iblbake.api.guards import _arguments, _choice, _count, _fits, _is_path, _kind, _name, _path
from iblbake.errors import InputError


@dataclass(frozen=True)
class Panorama:
    """An environment as the bakes read it.

    pixels: float32 array (H, W, 3), linear RGB radiance, equirectangular (a cube map is
        resampled to this on reading).
    layout: what the file held: equirect, hcross, vcross, hstrip, vstrip, faces or ktx2.
    colour_space: the pixels' primaries and transfer, in words.
    path: the file read (or the name given to from_pixels).
    info: the file's description (iblbake.io.images.ImageInfo: size, format, sha256, the
        read policies and counts of repaired texels).
    policies: how it was read: nonfinite, negative, transfer, primaries, layout (as given).
    read_s: seconds spent reading and validating.

    A Panorama is frozen and its pixels read-only (its sha256 names them): copy the array
    (np.array(p.pixels)) to edit it and make a new one with from_pixels.
    """

    pixels: object
    layout: str
    colour_space: str
    path: str
    info: object
    policies: dict = field(default_factory=dict)
    read_s: float = 0.0

    def __post_init__(self):
        # frozen with read-only pixels: info.sha256 names these texels, so no edit may change them
        self.pixels.setflags(write=False)

    @property
    def width(self) -> int:
        return self.pixels.shape[1]

    @property
    def height(self) -> int:
        return self.pixels.shape[0]

    @property
    def warnings(self) -> list:
        """What reading said (declared primaries, kept negatives, a resampled cube map...)."""
        return self.info.warnings

    @classmethod
    @_arguments
    def from_pixels(cls, pixels, name: str = "<array>", nonfinite: str = "error", negative: str = "keep") -> Panorama:
        """A panorama from an array (H, W, 3) of linear Rec.709 RGB radiance (real numbers),
        equirectangular; the nonfinite and negative policies apply as for a file (load_panorama).
        The pixels are copied (float32): the policies repair the copy, never `pixels`, and later
        edits of `pixels` leave the Panorama (and its sha256) as it was."""
        import hashlib

        import numpy as np

        from iblbake.io import images

        _choice("nonfinite", nonfinite, ("error", "zero", "clamp"))
        _choice("negative", negative, ("keep", "clamp", "error"))
        if not isinstance(name, str):
            raise InputError(f"name: give a string (what messages call the panorama), not {_kind(name)}")
        if _is_path(pixels):
            raise InputError("pixels: give an array (H, W, 3) of linear RGB radiance, not a path "
                             "(iblbake.load_panorama(path) reads a file)")
        try:
            given = np.asarray(pixels)
        except (TypeError, ValueError):
            raise InputError(f"pixels: give an array (H, W, 3) of linear RGB radiance, not {_kind(pixels)}") from None
        if given.dtype.kind not in "iuf":
            raise InputError(f"pixels: give an array (H, W, 3) of real numbers (linear RGB radiance), not "
                             f"{_kind(pixels)} of {given.dtype}")
        if given.ndim != 3 or given.shape[2] != 3 or 0 in given.shape:
            raise InputError(f"{name}: a panorama is an array (H, W, 3), not {given.shape}")
        # the copy, and validate_texels's masks and magnitudes beside it (a broadcast view holds
        # none of this yet)
        _fits(f"pixels {given.shape}", given.size * (4 + 4 + 2), "give a smaller array")
        # a copy, always: the policies repair the Panorama's texels, never the caller's array, and
        # the caller's later edits do not reach the Panorama (nor make its sha256 wrong)
        rgb = np.array(given, dtype=np.float32, order="C", copy=True)
        info = images.ImageInfo(path=name, width=rgb.shape[1], height=rgb.shape[0], channels_in=("R", "G", "B"),
                                format="array", sha256=hashlib.sha256(rgb.tobytes()).hexdigest(),
                                nonfinite_policy=nonfinite, negative_policy=negative)
        rgb = images.validate_texels(rgb, info)
        return cls(rgb, "equirect", _colour_space(info, "keep"), name, info,
                   _policies(nonfinite, negative, "auto", "keep", "auto"))


def _policies(nonfinite, negative, transfer, primaries, layout) -> dict:
    return {"nonfinite": nonfinite, "negative": negative, "transfer": transfer, "primaries": primaries,
            "layout": layout}


def _colour_space(info, primaries: str) -> str:
    if info.chromaticities is None:
        return "linear Rec.709 (sRGB primaries, D65 white)"
    if primaries == "convert":
        return "linear Rec.709 (converted from the file's chromaticities, Bradford adaptation)"
    return "linear, in the file's declared chromaticities, kept as stored (primaries='convert' converts them)"


@_arguments
def load_panorama(path, primaries: str = "auto", *, layout: str = "auto", nonfinite: str = "error",
                  negative: str = "keep", transfer: str = "auto", max_pixels: int | None = None,
                  names: dict | None = None) -> Panorama:
    """Read an environment file into a Panorama.

    path: an EXR, HDR, PFM, TIFF, PNG or JPEG panorama, a cube map (a cross or strip of six faces,
        a KTX2 cube map) or six face files (a path containing {face}: px nx py ny pz nz).
    primaries: a file declaring non-Rec.709 chromaticities: 'auto' keeps its values as stored and
        says so in Panorama.warnings, 'keep' keeps them silently, 'convert' converts them to
        Rec.709/D65.
    layout: what the file holds ('auto' goes by {face}, .ktx2, then the aspect ratio); cube maps
        are resampled to an equirect panorama.
    nonfinite: NaN/Inf texels 'error' (the default), 'zero' or 'clamp'.
    negative: negative texels 'keep' (counted), 'clamp' to 0, or 'error'.
    transfer: how 8/16-bit texels decode: 'auto', 'srgb' or 'linear'.
    max_pixels: refuse larger images before decoding (a whole number >= 1; default
        $IBLBAKE_MAX_PIXELS or 8192^2).
    names: what error messages call each argument (by default its name; the command line passes
        its flags).

    Raises InputError naming the file and what to do.
    """
    from iblbake.bake import inputs

    _path("path", path, "a panorama file's")
    _choice("layout", layout, inputs.LAYOUTS)
    _choice("primaries", primaries, ("auto", "keep", "convert"))
    _choice("nonfinite", nonfinite, ("error", "zero", "clamp"))
    _choice("negative", negative, ("keep", "clamp", "error"))
    _choice("transfer", transfer, ("auto", "srgb", "linear"))
    if max_pixels is not None:
        max_pixels = _count("max_pixels", max_pixels)
    said = {k: _name(names, k) for k in ("max_pixels", "nonfinite", "negative", "transfer", "primaries", "layout")}
    t0 = time.perf_counter()
    pixels, info = inputs.read_environment(path, layout=layout, max_pixels=max_pixels, nonfinite=nonfinite,
                                           negative=negative, transfer=transfer, primaries=primaries, names=said,
                                           layout_name=said["layout"],
                                           layout_hint=_name(names, "layout_hint", said["layout"]))
    return Panorama(pixels, info.layout, _colour_space(info, primaries), str(path), info,
                    _policies(nonfinite, negative, transfer, primaries, layout),
                    time.perf_counter() - t0)



def _panorama(panorama) -> None:
    if not isinstance(panorama, Panorama):
        raise InputError(f"panorama: give an iblbake.Panorama (iblbake.load_panorama(path), or "
                         f"iblbake.Panorama.from_pixels(array)), not {_kind(panorama)}")
