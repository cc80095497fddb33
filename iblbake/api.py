"""iblbake's public API (docs/api.md): bake image-based lighting from Python and get numpy arrays.

Every function returns arrays or the small dataclasses below, prints nothing and raises
iblbake.Error subclasses (iblbake.errors) with one-line messages (the command line prints them);
warnings are returned (a `warnings` list) or passed to a `warn(message)` callback. The command
line (iblbake.cli) is a layer over this module: what a command bakes, this module bakes.

Conventions (docs/conventions.md): world right-handed, +y up; panoramas equirectangular
(u = 0.5 - atan2(x, z) / (2 pi), v = acos(y) / pi, row 0 at the top), linear RGB, radiance in
the file's units (W m^-2 sr^-1 for a physical one); roughness is perceptual (alpha = r^2).

Imports are lazy (numpy, OpenImageIO and pyopencl load inside the functions): `import iblbake`
stays cheap and each call pays for what it uses.

Arguments are checked before any work: a wrong kind or value is an InputError naming the argument
and what it takes. Messages call the arguments by their names here; the functions the command
line calls take `names`, a mapping of argument names to what its messages call them (its flags).
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from iblbake.errors import InputError

if TYPE_CHECKING:                 # loaded on first use (import iblbake stays light)
    from iblbake.render.frame import Frame

# one OpenCL runtime per device spec for the process: sh, prefilter and dfg reuse it (building
# the kernels and probing the device is the start-up cost of a bake). A runtime's queue, programs
# and buffers are not for two threads at once (eight threads on one Renderer gave wrong frames):
# every call that runs on a runtime holds its lock (_on_device), so threads take turns on a device.
_RUNTIMES: dict = {}
_LOCKS: dict = {}                 # id(runtime) -> its lock
_MADE = threading.Lock()          # two threads asking for a new runtime make one


def _runtime(device: str | None, names: dict | None = None):
    _device(device)
    key = device or ""
    with _MADE:
        if key not in _RUNTIMES:
            from iblbake.device.runtime import Runtime
            rt = Runtime(device, _name(names, "device"))
            _LOCKS[id(rt)] = threading.RLock()
            _RUNTIMES[key] = rt
    return _RUNTIMES[key]


def _on_device(rt):
    """The lock of runtime `rt` (held while a call runs on it), or no lock for the host (None)."""
    import contextlib
    return contextlib.nullcontext() if rt is None else _LOCKS[id(rt)]


# the most samples a texel of prefilter (fis) and dfg takes: the scene keys' bound (docs/scene.md)
MAX_SAMPLES = 1 << 20

# Host memory of the panorama bakes, measured with tracemalloc (64x32 to 1024x512 panoramas, every
# basis and option; the constants hold the largest per texel, the fixed tables aside): the float64
# copy of the texels and the exact irradiance the `error` blocks sum, per texel; sh's host
# projection adds its (bands^2, rows x azimuth terms) contraction; a basis's fit its design rows.
SH_BYTES_PER_TEXEL = {"numpy": 64, "opencl": 16}
ERROR_BYTES_PER_TEXEL = 64
BASIS_BYTES_PER_TEXEL = 160
TABLE_BYTES = 64 << 20
VECTOR_BYTES = 1024

# ------------------------------------------------------------------------- argument checks

def _names(names: dict | None) -> dict:
    """A function's `names`: what its messages call its arguments, where not their own names."""
    if names is not None and not isinstance(names, dict):
        raise InputError(f"names: give a mapping of argument names to what messages call them, or None, "
                         f"not {_kind(names)}")
    return names or {}


def _name(names: dict | None, key: str, default: str | None = None) -> str:
    """What messages call argument `key`: names[key] where the caller says (the command line's
    flag), else `default`, else the argument's own name."""
    return _names(names).get(key, default or key)


def _kind(value) -> str:
    return type(value).__name__


def _shown(value) -> str:
    """A value as a message quotes it: repr on one line, cut to 60 characters (an array's repr
    spans lines, a long list's pages)."""
    try:
        if type(value).__module__ == "numpy" and getattr(value, "ndim", None) == 0:
            value = value.item()          # numpy's repr of a scalar depends on its print options
        text = " ".join(repr(value).split())
    except Exception:                              # noqa: BLE001 - a repr that fails is still a value
        text = f"<{_kind(value)}>"
    return text if len(text) <= 60 else text[:57] + "..."


def _gib(nbytes: float) -> str:
    return f"{nbytes / 2**30:.3g} GiB"


def _fits(what: str, nbytes: float, hint: str) -> None:
    """Before the work: an InputError saying how much memory `what` needs where that is more than
    this process may still allocate (its address-space limit, or the system's available memory)."""
    from iblbake.io.memory import host_bytes_available
    free = host_bytes_available()
    if free is not None and nbytes > free:
        raise InputError(f"{what}: needs about {_gib(nbytes)} of memory, more than the {_gib(max(free, 0))} "
                         f"this process may still allocate; {hint}")


def _whole(value) -> bool:
    """A whole number (a numpy integer too), not a bool."""
    import numbers
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _count(name: str, value, least: int = 1, most: int | None = None) -> int:
    """A whole number in [least, most] (numpy integers too; not a bool, nor a float such as 9.0)."""
    if not (_whole(value) and value >= least and (most is None or value <= most)):
        bounds = f">= {least}" if most is None else f"{least} to {most}"
        raise InputError(f"{name} {_shown(value)}: " + (f"use {bounds}" if _whole(value) and most is not None
                                                         else f"give a whole number {bounds}"))
    return int(value)


def _arguments(fn):
    """`fn` with its arguments checked as the others are: an unknown keyword or a missing argument
    is an InputError naming it (Python's own TypeError otherwise), as basis's options are."""
    import functools

    @functools.wraps(fn)
    def call(*args, **kwargs):
        import inspect
        sig = inspect.signature(fn)
        try:
            sig.bind(*args, **kwargs)
        except TypeError as e:
            what = fn.__qualname__.removesuffix(".__init__")
            takes = f"(its arguments: {', '.join(p for p in sig.parameters if p not in ('cls', 'self'))})"
            unknown = [k for k in kwargs if k not in sig.parameters]
            if unknown:
                raise InputError(f"{unknown[0]}: not an argument of {what} {takes}") from None
            raise InputError(f"{what}: {e} {takes}") from None
        return fn(*args, **kwargs)
    return call


def _real(name: str, value, least: float | None = None) -> float:
    """A finite real number (numpy's too; not a bool or a string), at least `least`."""
    import numbers
    if not (isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)
            and (least is None or value >= least)):
        raise InputError(f"{name} {_shown(value)}: give a finite number" + ("" if least is None else f" >= {least:g}"))
    return float(value)


def _flag(name: str, value) -> bool:
    """True or False (a numpy bool too): not 'no', 1 or None, which would read as one."""
    if isinstance(value, bool) or (type(value).__module__ == "numpy" and _kind(value) in ("bool", "bool_")):
        return bool(value)
    raise InputError(f"{name} {_shown(value)}: give True or False")


def _choice(name: str, value, choices) -> None:
    if not (isinstance(value, str) and value in choices):
        raise InputError(f"{name} {_shown(value)}: use one of {', '.join(map(str, choices))}")


def _callback(name: str, value):
    if value is not None and not callable(value):
        raise InputError(f"{name}: give a function (or None), not {_kind(value)} {_shown(value)}")
    return value


def _device(value) -> None:
    if value is not None and not isinstance(value, str):
        raise InputError(f"device: give an OpenCL device spec ('gpu', 'cpu', 'gpu:N', 'P:D' or part of a "
                         f"device's name) or None, not {_kind(value)} {_shown(value)}")


def _is_path(value) -> bool:
    import os
    return isinstance(value, (str, os.PathLike))


def _path(name: str, value, what: str):
    if not _is_path(value):
        raise InputError(f"{name}: give {what} path (a str or pathlib.Path), not {_kind(value)}")
    return _no_nul(name, value)


def _no_nul(name: str, path):
    """`path`, refused where it holds a NUL (no file can be named so: it read as a missing file,
    the NUL raw in the message), as a scene's path keys are."""
    import os
    text = os.fspath(path)
    if ("\0" if isinstance(text, str) else b"\0") in text:
        raise InputError(f"{name} {_shown(text)}: holds a NUL character, which no path can")
    return path


def _cache(cache):
    """The bake cache folder: None (the default) or a folder's path (made where missing; one that
    cannot be, a file say, is an InputError where the first bake needs it)."""
    return cache if cache is None else _path("cache", cache, "the bake cache folder's")


def _overrides(overrides) -> list:
    """'KEY.PATH=VALUE' strings: one string (one override), a list of them, or None."""
    if overrides is None:
        return []
    if isinstance(overrides, str):
        return [overrides]
    if not (isinstance(overrides, (list, tuple)) and all(isinstance(o, str) for o in overrides)):
        raise InputError(f"overrides: give 'KEY.PATH=VALUE' strings (one, or a list of them), not {_shown(overrides)}")
    return list(overrides)


def _panorama(panorama) -> None:
    if not isinstance(panorama, Panorama):
        raise InputError(f"panorama: give an iblbake.Panorama (iblbake.load_panorama(path), or "
                         f"iblbake.Panorama.from_pixels(array)), not {_kind(panorama)}")


def _intensity(panorama, value) -> float:
    """A scale of the panorama's radiance: finite, >= 0, and keeping its brightest texel within
    what a texel may hold (images.MAX_ABS_VALUE; beyond it the sums overflow)."""
    from iblbake.io.images import MAX_ABS_VALUE
    value = _real("intensity", value, 0)
    top = float(abs(panorama.pixels).max())
    if value * top > MAX_ABS_VALUE:
        raise InputError(f"intensity {value:g}: scales the panorama's brightest texel ({top:g}) past "
                         f"{MAX_ABS_VALUE:g}; give at most {MAX_ABS_VALUE / top:.3g}")
    return value


def _vectors(name: str, value):
    """An array (..., 3) of finite numbers, float64."""
    import numpy as np
    try:
        a = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: give unit vectors, an array (..., 3) of numbers, not {_kind(value)}") from None
    if a.ndim == 0 or a.shape[-1] != 3:
        raise InputError(f"{name}: give unit vectors, an array (..., 3) of numbers, not shape {a.shape}")
    # a basis's evaluation: measured at most 850 bytes a vector (ambient dice's specular lobe)
    _fits(f"{name} {a.shape}", VECTOR_BYTES * (a.size // 3), "give fewer vectors a call")
    if not np.isfinite(a).all():
        raise InputError(f"{name}: holds non-finite values; give finite unit vectors")
    length = np.linalg.norm(a, axis=-1)
    if a.size and np.abs(length - 1.0).max() > 1e-3:       # the formulas take directions, not any vector
        raise InputError(f"{name}: holds vectors of length {float(length.flat[np.abs(length - 1).argmax()]):.4g}; "
                         "give unit vectors (normalise them)")
    return a


# ----------------------------------------------------------------------------------- panoramas

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


# ---------------------------------------------------------------------------------- SH

@dataclass
class SH:
    """Spherical-harmonic coefficients of a panorama's lighting.

    Basis: real orthonormal SH (the integral of Y^2 over the sphere is 1), +z polar axis,
    phi = atan2(y, x), no Condon-Shortley phase, index k = l (l + 1) + m for l = 0..bands-1,
    m = -l..l, directions in the world frame (+y up). For l <= 2: Y0 = 0.282095,
    Y1 = 0.488603 y, Y2 = 0.488603 z, Y3 = 0.488603 x, Y4 = 1.092548 xy, Y5 = 1.092548 yz,
    Y6 = 0.315392 (3z^2 - 1), Y7 = 1.092548 xz, Y8 = 0.546274 (x^2 - y^2).

    radiance: float64 (bands^2, 3), L_k (the window applied): L(d) ~ sum_k L_k Y_k(d), in the
        panorama's radiance units.
    irradiance: float64 (bands^2, 3), E_k = Ahat_l L_k: E(n) = max(0, sum_k E_k Y_k(n)); the
        diffuse light a Lambertian albedo a reflects is a / pi * E(n).
    error: the irradiance measured against the exact (float64, every texel) at 256 normals
        (relative_rmse, max_relative_error, most_negative_relative), or None.
    document: the JSON document `iblbake sh` writes (format iblbake.sh, version 1).
    """

    bands: int
    window: str
    radiance: object
    irradiance: object
    error: dict | None
    document: dict

    def _nine(self, what: str) -> None:
        """The engines' formats hold at most 3 bands (9 coefficients)."""
        if self.bands > 3:
            raise InputError(f"{what} holds at most 3 bands (9 coefficients), this SH has {self.bands}; "
                             f"bake it with iblbake.sh(panorama, bands=3) or fewer")

    def to_filament(self):
        """(9, 3) Filament IndirectLight irradiance (cmgen's sh.txt): E_k times Filament's basis
        constants / pi; its shader's polynomial gives E(n) / pi. Fewer bands padded with zeros
        (Filament's irradiance(bands, sh) reads the first bands^2 rows). At most 3 bands."""
        import numpy as np

        from iblbake.bake import sh as shbake
        self._nine("to_filament: Filament's irradiance")
        e = shbake.filament_coefficients(self.document)
        out = np.zeros((9, 3))
        out[:len(e)] = e
        return out

    def to_threejs(self):
        """(9, 3) three.js SphericalHarmonics3 (a LightProbe's sh): the radiance coefficients
        L_k, fewer bands padded with zeros. At most 3 bands."""
        from iblbake.bake import sh as shbake
        self._nine("to_threejs: three.js's SphericalHarmonics3")
        return shbake.threejs_coefficients(self.document)

    def to_gltf(self):
        """(9, 3) EXT_lights_image_based irradianceCoefficients as Babylon.js reads them: E_k
        with the Condon-Shortley signs and the loader's x mirror, fewer bands padded with zeros.
        At most 3 bands."""
        from iblbake.bake import sh as shbake
        self._nine("to_gltf: EXT_lights_image_based")
        return shbake.gltf_coefficients(self.document)

    def to_glsl(self) -> str:
        """A GLSL function shIrradiance(n) with the irradiance coefficients, any number of bands."""
        from iblbake.bake import sh as shbake
        return shbake.glsl_snippet(self.document)

    def export(self, fmt: str = "iblbake") -> str:
        """The text `iblbake sh --format FMT` writes: iblbake (the JSON document), filament,
        threejs, gltf or glsl (docs/manual.md 'SH for engines')."""
        from iblbake.bake import sh as shbake
        _choice("format", fmt, shbake.FORMATS)
        if fmt in ("filament", "threejs", "gltf"):
            self._nine(f"format {fmt}")
        return shbake.export(self.document, fmt)


@_arguments
def sh(panorama: Panorama, bands: int = 3, window: str | None = None, *, rotate_y: float = 0.0,
       intensity: float = 1.0, backend: str = "auto", device: str | None = None, error: bool = True,
       names: dict | None = None) -> SH:
    """Project a panorama onto spherical harmonics (exact texel integrals, float64) and bake the
    irradiance coefficients.

    bands: 1 to 16 (l = 0..bands-1; 3 gives the classic 9 coefficients).
    window: None (or 'none'), 'hann' w_l = (1 + cos(pi l / bands)) / 2 or 'lanczos'
        w_l = sinc(l / bands), applied per band against ringing around bright suns.
    rotate_y: degrees about +y (+x towards -z; taken mod 360). intensity: a scale of the
        radiance (>= 0, keeping the brightest texel within 1e30).
    backend: 'numpy' (host, float64), 'opencl' (the reduction kernel on `device`) or 'auto'
        (numpy where that is quicker than starting OpenCL).
    device: an OpenCL device spec ('gpu', 'cpu', 'gpu:N', 'P:D' or part of a name).
    error: measure the SH irradiance against the exact irradiance (SH.error).
    names: what error messages call each argument (by default its name; the command line passes
        its flags).

    Returns an SH (the coefficients in the convention its docstring gives, with converters
    to the engine formats).
    """
    import numpy as np

    from iblbake.bake import sh as shbake
    from iblbake.core import conventions, sh as core_sh

    _names(names)
    _panorama(panorama)
    bands = _count("bands", bands, 1, core_sh.MAX_BANDS)
    window = "none" if window is None else window
    _choice("window", window, core_sh.WINDOWS)
    _choice("backend", backend, ("auto", *shbake.BACKENDS))
    rotate_y = conventions.wrap_degrees(_real("rotate_y", rotate_y))
    intensity = _intensity(panorama, intensity)
    error = _flag("error", error)
    _device(device)
    t_start = time.perf_counter()
    info = panorama.info
    backend = shbake.choose_backend(backend, panorama.width, panorama.height, bands)
    texels = panorama.width * panorama.height
    table = 96 * bands * bands * panorama.height * (2 * bands - 1) if backend == "numpy" else 0
    _fits(f"sh bands {bands} of a {panorama.width}x{panorama.height} panorama",
          (SH_BYTES_PER_TEXEL[backend] + ERROR_BYTES_PER_TEXEL * error) * texels + table + TABLE_BYTES,
          "use a smaller panorama, fewer bands" + (", backend 'opencl'" if backend == "numpy" else "")
          + (" or error=False" if error else ""))
    rt = _runtime(device, names) if backend == "opencl" else None
    device_label = rt.device_label if rt else "numpy (float64, host)"
    with _on_device(rt):
        coeffs, project_s = shbake.project(panorama.pixels, bands, backend, rt, rotate_y)
    coeffs = coeffs * intensity
    options = {"bands": bands, "window": window, "backend": backend, "rotate_y_deg": rotate_y,
               "intensity": intensity, **{k: v for k, v in panorama.policies.items() if k != "layout"},
               "input_layout": panorama.policies["layout"]}
    timings = {"read_s": round(panorama.read_s, 6), "project_s": round(project_s, 6)}
    doc = shbake.document(coeffs, bands=bands, window=window, info=info, options=options,
                          device=device_label, timings=timings)
    if error:
        t0 = time.perf_counter()
        doc["error"] = shbake.irradiance_error(panorama.pixels, np.asarray(doc["irradiance"]), bands, rotate_y,
                                               intensity)
        doc["timings"]["error_s"] = round(time.perf_counter() - t0, 6)
    doc["elapsed_s"] = round(panorama.read_s + time.perf_counter() - t_start, 6)
    return SH(bands, window, np.asarray(doc["radiance"]), np.asarray(doc["irradiance"]), doc.get("error"), doc)


# ----------------------------------------------------------------------------- directional bases

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


# ------------------------------------------------------------------------- prefiltered chain, DFG

@dataclass
class Chain:
    """A GGX-prefiltered radiance chain (the split sum's first factor).

    levels: float32 arrays, level k of roughness roughness[k] = k / (K - 1): equirect (h, 2h, 3),
        cubemap (6 s, s, 3: faces +X -X +Y -Y +Z -Z stacked vertically) or octahedral (s, s, 3).
    roughness: perceptual roughness of each level (alpha = r^2).
    sizes: each level's size (equirect height, cube face or octahedral side).
    methods: how each level was computed (spectral, convolve@N, fis, resample).
    """

    layout: str
    levels: list
    roughness: list
    sizes: list
    methods: list


@_arguments
def prefilter(panorama: Panorama, size: int | None = None, levels: int | None = None, layout: str = "equirect", *,
              min_size: int = 8, method: str = "auto", samples: int = 256, backend: str = "opencl",
              device: str | None = None, progress=None) -> Chain:
    """GGX-prefilter a panorama into a chain of levels of increasing roughness (not cached; the
    command `iblbake mips` bakes the same levels into its cache).

    size: the base size (equirect height, cube face or octahedral side; default: the panorama's
        height, half of it for a cube map). levels: K, 1 to 32 (default: one per halving down to
        min_size). layout: 'equirect', 'cubemap' or 'octahedral'.
    method: 'spectral' (exact, in the SH domain), 'convolve' (exact sum over texels), 'fis'
        (filtered importance sampling with `samples` samples a texel, 1 to 2^20) or 'auto'.
    backend: 'opencl' (on `device`) or 'numpy' (the float64 twins: small sizes only).
    The memory the chain needs is estimated first: more than the process may allocate is an
    InputError saying how much (numpy's auto bakes a sharp level by fis where convolve's
    sub-texel grid would not fit).
    progress: called with 1 as each level is done.
    """
    from iblbake.bake import layouts
    from iblbake.bake import mips as mipsbake

    _panorama(panorama)
    _choice("layout", layout, tuple(layouts.LAYOUT_IDS))
    _choice("method", method, ("auto", "spectral", "convolve", "fis"))
    _choice("backend", backend, ("opencl", "numpy"))
    size = None if size is None else _count("size", size)
    levels = None if levels is None else _count("levels", levels, 1, layouts.MAX_LEVELS)
    min_size, samples = _count("min_size", min_size), _count("samples", samples, 1, MAX_SAMPLES)
    _device(device)
    _callback("progress", progress)
    baker = mipsbake.Baker(backend, rt=_runtime(device) if backend == "opencl" else None)

    def options(s):
        return mipsbake.PrefilterOptions(layout, s, levels, min_size, method, samples)

    opts = options(size).resolved(panorama.height)
    mipsbake.check_chain_fits(layout, opts["base_size"], lambda s: options(s).resolved(0)["sizes"], baker.rt, "size")
    src = (panorama.width, panorama.height)
    methods = baker.plan(layouts.radiance_chain_sizes(*src), opts)      # before work: a level too sharp is said
    _fits(f"prefilter size {opts['base_size']}, {len(methods)} levels, backend {backend}",
          mipsbake.prefilter_host_bytes(src, opts, methods, backend),
          "use fewer levels, a smaller size" + (", backend 'opencl' or method 'fis'" if backend == "numpy" else ""))
    with _on_device(baker.rt):
        chain = baker.radiance_chain(panorama.pixels)
        out, methods = baker.prefilter(chain, opts, progress=progress)
    return Chain(layout, out, list(opts["roughness"]), list(opts["sizes"]), list(methods))


@_arguments
def dfg(size: int = 128, *, samples: int = 4096, multiscatter: bool = False, backend: str = "opencl",
        device: str | None = None):
    """The split sum's DFG table: float32 (size, size, 2), column i NoV = i / (size - 1) (at least
    1e-4), row j perceptual roughness r = j / (size - 1); channels (A, B) with
    specular = prefiltered * (F0 A + F90 B), or with multiscatter (B, A + B), Filament's energy
    compensation. GGX, height-correlated Smith; `samples` GGX samples per texel (1 to 2^20). Baked once a
    process per device and arguments."""
    from iblbake.bake import mips as mipsbake

    _choice("backend", backend, ("opencl", "numpy"))
    size, samples = _count("size", size, 2, 4096), _count("samples", samples, 1, MAX_SAMPLES)
    multiscatter = _flag("multiscatter", multiscatter)
    _device(device)
    if backend == "numpy":          # the twin's float64 (size, size) sums and temporaries, its sample points
        _fits(f"dfg size {size}, samples {samples}, backend numpy", 120 * size * size + 16 * samples,
              "use backend 'opencl' or a smaller size")
    baker = mipsbake.Baker(backend, rt=_runtime(device) if backend == "opencl" else None)
    with _on_device(baker.rt):
        return mipsbake.dfg_table(baker, size, samples, multiscatter)


# ------------------------------------------------------------------------------ scenes, frames

@_arguments
def load_scene(path_or_dict, overrides=(), *, folder=".", outputs=None, names: dict | None = None):
    """A validated scene (iblbake.Scene: .data, the scene with every default filled and every path
    absolute; `iblbake render --help-schema` lists the keys).

    path_or_dict: a scene YAML file, a mapping of what one holds (its relative paths resolve in
        `folder`; numpy numbers and arrays, tuples and path objects read as the numbers, lists and
        strings a file holds), or a Scene (validated again with the overrides and outputs given).
        A Scene is read-only: one whose data was edited after loading is an InputError naming
        the key edited (here, and so in render, bake_probes and accuracy).
    overrides: 'key.path=value' strings applied before validation (values parse as YAML), as
        `iblbake render --set`: a list of them, or one string.
    outputs: frame paths that replace output.frame (as `render -o`): a list, or one path.
    names: what error messages call each argument (by default its name; the command line passes
        its flags).

    Raises InputError naming the file, line and dotted key (the closest valid key for a typo).
    """
    import os
    from collections.abc import Mapping

    from iblbake.scene import load as scene_load

    _names(names)
    overrides = _overrides(overrides)
    if outputs is not None:
        if _is_path(outputs):
            outputs = [outputs]
        if not (isinstance(outputs, (list, tuple)) and all(_is_path(o) for o in outputs)):
            raise InputError(f"outputs: give frame paths (.png or .exr; one, or a list of them), not {_shown(outputs)}")
        outputs = [os.fspath(_no_nul("outputs", o)) for o in outputs]
    said = _name(names, "overrides")
    if isinstance(path_or_dict, scene_load.Scene):
        edited = scene_load.edited_key(path_or_dict)
        if edited is not None:
            key = edited or "KEY"
            raise InputError(f"{path_or_dict.source}: Scene.data{'.' + edited if edited else ''} was changed after "
                             f"load_scene; a Scene is read-only: give the change as an override "
                             f"(iblbake.load_scene(scene, ['{key}=VALUE'])), or edit the mapping and load it again")
        if not overrides and outputs is None:
            return path_or_dict
        return scene_load.load_any(path_or_dict, overrides, outputs, override_name=said)
    if isinstance(path_or_dict, Mapping):
        _path("folder", folder, "a folder's")
        # the mapping itself, not a copy: a section holding the scene then names itself (materials.m.self)
        return scene_load.load_data(path_or_dict, folder, overrides, outputs, override_name=said)
    if not _is_path(path_or_dict):
        raise InputError(f"scene: give a scene file's path, a mapping of what one holds, or an iblbake.Scene, "
                         f"not {_kind(path_or_dict)}")
    return scene_load.load(_no_nul("scene", path_or_dict), overrides, outputs, override_name=said)


class Renderer:
    """Renders scenes on one OpenCL runtime and one bake cache, across calls: kernels are built
    once, bakes (SH, chains, DFG, probes) are kept in memory and in the cache folder, and with
    `reuse` passes whose inputs did not change since the last frame are not run again.

    device: an OpenCL device spec (default $IBLBAKE_DEVICE, else the first working GPU, else
        CPU). cache: the bake cache folder (default $IBLBAKE_CACHE, else the per-user cache).
    reuse: keep the last frame on the device for the next (a series of frames of one size).
    names: what error messages call each argument (by default its name; the command line passes
        its flags).
    """

    @_arguments
    def __init__(self, device: str | None = None, cache=None, reuse: bool = True, *, names: dict | None = None):
        from iblbake.render import Bakes, Reuse

        _device(device)
        cache = _cache(cache)
        reuse = _flag("reuse", reuse)
        self._names = _names(names)
        self.runtime = _runtime(device, names)
        self.bakes = Bakes(cache)
        self.bakes.runtime = self.runtime
        self._reuse = Reuse() if reuse else None

    @property
    def device(self) -> str:
        return self.runtime.device_label

    @_arguments
    def render(self, scene, *, warn=None, progress=None, profile_paths: bool = False) -> Frame:
        """Render a Scene (load_scene) into a Frame (iblbake.Frame: hdr, tonemapped, aovs,
        report). warn(message) gets the warnings, and the notes on what the scene asks that the
        frame does not do (a key not read, a term skipped); progress(fraction) the share of long
        work (path tracing, probe rays) done. profile_paths: after the frame, measure where the
        reference pass's time goes (per bounce: shading, closest-hit and shadow-ray traversal),
        the report's `paths_profile`; the frame is the same."""
        from iblbake.render import frame as render_frame

        _callback("warn", warn)
        _callback("progress", progress)
        profile_paths = _flag(_name(self._names, "profile_paths"), profile_paths)
        from iblbake.render.plan import effect_modes

        sc = load_scene(scene, names=self._names)
        if profile_paths:
            _profiled(sc, self._names)
        with _on_device(self.runtime):          # one frame at a time on the runtime (and this Renderer)
            frame = render_frame.render(sc, runtime=self.runtime, cache=self.bakes, reuse=self._reuse, warn=warn,
                                        progress=progress, profile_paths=profile_paths)
        for note in effect_modes(sc).notes:     # what the scene asks that the frame did not do
            if warn:
                warn(note)
        return frame


def _profiled(scene, names) -> None:
    """A scene asked to profile its paths has the reference pass, or fails in one line."""
    from iblbake.render import plan

    if not any(p.profiles == "paths" for p in plan(scene).passes):
        raise InputError(f"{_name(names, 'profile_paths')}: the scene has no reference pass to profile "
                         f"(effects.diffuse or effects.specular: reference)")


@_arguments
def render(scene, device: str | None = None, *, cache=None, warn=None, progress=None, profile_paths: bool = False,
           names: dict | None = None) -> Frame:
    """Render a scene once (a Scene, a scene file or a mapping; see load_scene) on `device` into a
    Frame (HDR array, tone-mapped array, report). A series of frames: use a Renderer.
    profile_paths: measure where the reference pass's time goes (Renderer.render). names: what
    error messages call each argument (by default its name; the command line passes its flags)."""
    _callback("warn", warn)
    _callback("progress", progress)
    profile_paths = _flag(_name(names, "profile_paths"), profile_paths)
    sc = load_scene(scene, names=names)            # a bad scene is said before the device starts
    if profile_paths:
        _profiled(sc, names)
    return Renderer(device, cache, reuse=False, names=names).render(sc, warn=warn, progress=progress,
                                                                    profile_paths=profile_paths)


# ----------------------------------------------------------------------------------- probes

@dataclass
class ProbeVolume:
    """A scene's irradiance probe volume (DDGI, RTXGI's layouts; docs/manual.md 'iblbake probes').

    irradiance: float32 (what the volume's files hold), the octahedral atlas (rows, columns, 3)
        or, for probes.irradiance: sh, (probes, 9, 3) SH irradiance coefficients (SH's
        convention), or for a directional basis (probes, floats, 3) its radiance coefficients
        (manifest['basis'] says its layout).
    distance: float32 atlas of the ray distances' moments (R: mean distance, G: its square).
    data: float32 (probes, 4): each probe's offset from its grid position in world units, and
        its state (0 active, 1 inactive).
    grid: origin, spacing and counts (x, y, z); probe (gx, gy, gz) sits at
        origin + (gx, gy, gz) * spacing + offset, index gy * nx * nz + gz * nx + gx.
    states: the count of active and inactive probes.
    manifest: probes.json as `iblbake probes` writes it (every convention spelled out).
    reflections: each reflection probe's capture: {'capture': float32 (h, 2h, 7): R, G, B, A, sky.R,
        sky.G, sky.B (render/reflection_probes.py CHANNELS), 'settings', and its prefiltered chains}.
    cached: whether the bake came from the cache. entry: the cache folder holding the atlases.
    """

    irradiance: object
    distance: object
    data: object
    grid: dict
    states: dict
    representation: str
    manifest: dict
    reflections: list
    cached: bool
    entry: str
    device: str
    volume: dict = field(repr=False, default_factory=dict)

    def glsl(self) -> str:
        """probes.glsl: a GLSL function that samples the volume's files."""
        from iblbake.render import probes
        return probes.glsl(self.volume, self.manifest)


@_arguments
def bake_probes(scene, device: str | None = None, *, cache=None, warn=None, progress=None,
                names: dict | None = None) -> ProbeVolume:
    """Bake a scene's irradiance probe volume (its `probes:` section; a scene without one gets
    the section's defaults: an automatic grid over the scene's bounds, its spacing from the scene's
    interior, 1024 rays each, octahedral irradiance) by tracing paths from every probe, and each
    reflection probe's capture; cached by content in `cache` (as render). names: what error
    messages call each argument (by default its name; the command line passes its flags)."""

    import numpy as np

    from iblbake.render import Bakes, probes
    from iblbake.render.units import Job

    _names(names)
    _device(device)
    cache = _cache(cache)
    _callback("warn", warn)
    _callback("progress", progress)
    sc = load_scene(scene, names=names)     # the probes unit is asked for by name: the scene is left as it is
    if not sc.data["objects"]:
        raise InputError(f"{sc.source}: the scene has no objects; probes light objects (add some)")
    rt = _runtime(device, names)
    bakes = Bakes(cache)
    bakes.runtime = rt
    job = Job(sc, rt, bakes, warn or (lambda _m: None), progress)
    for w in bakes.environment(sc.data["environment"])[1].warnings:     # as a frame says them
        job.warn(w)
    with _on_device(rt):
        vol, cached, extra = bakes.load("probes", job)
        reflections = bakes.load("reflection_probes", job)[0] if sc.data["reflection_probes"] else []
    vol = probes.sampled(vol, sc.data["probes"])
    man = probes.manifest(vol)
    from iblbake.render.reflection_probes import CHANNELS as rp_channels
    man["reflection_probes"] = [{"file": f"reflection_{k}.exr", **c["settings"],
                                 "channels": list(rp_channels),
                                 "layout": "equirect in the world frame (the panoramas' mapping); R, G, B the linear "
                                           "radiance of the paths that met the scene, A the share of them that did "
                                           "(the coverage), sky.R, sky.G, sky.B the radiance of those that escaped "
                                           "(the sky through the openings, read without parallax); "
                                           "docs/conventions.md 'Reflection probes' has the reading"}
                                for k, c in enumerate(reflections)]
    f32 = [np.asarray(vol[k], np.float32) for k in ("irradiance", "distance", "data")]     # as the files hold them
    return ProbeVolume(*f32, man["grid"], man["states"], man["representation"], man, list(reflections), cached,
                       extra["entry"], rt.device_label, vol)


# --------------------------------------------------------------------------------- accuracy

@dataclass
class Accuracy:
    """What each approximation of a scene's lighting costs and how far it is from the converged
    reference (docs/manual.md 'What accuracy costs').

    records: one dict a rung (the table's rows): term, label, values (the scene keys it sets),
        mode, time_s (median lighting-pass seconds), frame_s, bake_s, kernel_build_s,
        relative_rmse, mean and max relative error, flip (HDR-FLIP, where measured), pareto.
    frontier: term -> the labels on its Pareto frontier of (time, relative RMSE), by time.
    reference: term -> the reference's noise (two seeds; noise_bulk the same over the 99% of
        pixels where they agree best), samples per pixel, what stopped it, seconds; hdr and mask
        are the float32 (H, W, 4) frame and its measured pixels.
    configured: the scene as configured (both terms) against the sum of the references.
    summary: the JSON document `iblbake accuracy --json` prints (accuracy.json).
    study: the study (its scene, settings and each rung's frame, for plots and error maps).
    rungs: the rungs run, in the records' order.
    """

    records: list
    frontier: dict
    reference: dict
    configured: dict
    summary: dict
    study: object = field(repr=False, default=None)
    rungs: list = field(repr=False, default_factory=list)


@_arguments
def accuracy(scene, ladder=None, *, overrides=(), max_side: int = 320, repeats: int = 3,
             target_noise: float = 0.003, max_samples: int = 4096, visibility: bool = True, bounces=None,
             flip: bool = True, cache=None, device: str | None = None, jobs: int = 1, devices=None, warn=None,
             progress=None, before_run=None, names: dict | None = None) -> Accuracy:
    """Render a scene's converged reference per lighting term (diffuse, specular: visibility and
    every bounce, two seeds, its noise measured), then a ladder of approximations of each term,
    each timed (median of `repeats` renders) and measured over the object pixels.

    scene: a scene file, a mapping or a Scene, as load_scene takes (the study loads it at
        `max_side` with each rung's values); overrides: as load_scene's.
    ladder: None (the default ladder for the scene and device), 'realtime' (the real-time modes
        as shipped), 'bases', 'probe_bases' or a ladder file ({rungs: [AXIS, ...]} in the sweep
        syntax).
    max_side: 8 to 8192. repeats: 1 to 100.
    bounces: the reference's bounces: 'unbounded' or a count (1: the direct light alone). None is
        unbounded; a value given, other than 1, is warned about where no light passes between
        the scene's surfaces (the reference is then the direct light).
    target_noise (>= 0), max_samples (1 to 2^20): the reference's stopping rule per seed.
    jobs, devices: render the reference seeds in `jobs` worker processes, one device spec each
        in turn (a list), into the cache.
    warn(message): what the study says (a reference stopped short, rungs left out).
    progress(): called as each reference seed and rung is done.
    before_run(study, rungs, reads): called once every rung's scene has validated and before
        anything renders; reads are (what, path) of every file the study reads.
    names: what messages call each argument (by default its name; the command line passes its
        flags).
    """
    import os

    from iblbake.render import Bakes
    from iblbake.scene import load as scene_load
    from iblbake.scene.schema import MAX_BOUNCES
    from iblbake.study import accuracy as acc, ladder as ladders

    # every argument is checked before the scene loads and anything renders
    _names(names)
    if not (ladder is None or _is_path(ladder)):
        raise InputError(f"ladder: give None, one of {', '.join(ladders.LADDERS)} or a ladder file's path, "
                         f"not {_kind(ladder)}")
    if ladder is not None:
        _no_nul("ladder", ladder)
    overrides = _overrides(overrides)
    max_side, repeats = _count("max_side", max_side, 8, 8192), _count("repeats", repeats, 1, 100)
    target_noise = _real("target_noise", target_noise, 0)
    max_samples = _count("max_samples", max_samples, 1, 1 << 20)
    visibility, flip = _flag("visibility", visibility), _flag("flip", flip)
    if not (bounces is None or bounces == "unbounded" or (_whole(bounces) and 1 <= bounces <= MAX_BOUNCES)):
        raise InputError(f"bounces {_shown(bounces)}: use None or 'unbounded', or a count from 1 to {MAX_BOUNCES}")
    bounces = int(bounces) if _whole(bounces) else bounces
    cache = _cache(cache)
    _device(device)
    jobs = _count("jobs", jobs)
    if not (devices is None or (isinstance(devices, (list, tuple)) and all(isinstance(d, str) for d in devices))):
        raise InputError(f"devices: give a list of OpenCL device specs (one a worker, in turn), or None, "
                         f"not {_shown(devices)}")
    for name, f in (("warn", warn), ("progress", progress), ("before_run", before_run)):
        _callback(name, f)
    said = {k: _name(names, k) for k in ("bounces", "max_samples", "max_side", "overrides", "ladder")}
    no_visibility = _name(names, "visibility", "visibility False")

    say = warn or (lambda _m: None)
    given = bounces is not None
    bounces = "unbounded" if bounces is None else bounces
    settings = acc.Settings(max_side=max_side, repeats=repeats, target_noise=target_noise, max_samples=max_samples,
                            flip=flip, visibility=visibility, bounces=bounces)
    # a file is loaded by the study itself (each rung's values over the file's); a mapping or a
    # Scene is validated here with the overrides, and the study validates it again with each
    # rung's values. The overrides are checked here either way, said as this function names them.
    sc = load_scene(scene, overrides, names=names)
    from_file = _is_path(scene)
    rt = _runtime(device, names)
    with _on_device(rt):             # the study's frames on the runtime, one thread at a time
        study = acc.Study(str(scene) if from_file else sc, overrides if from_file else (), settings, runtime=rt,
                          bakes=Bakes(cache), warn=warn, names={k: said[k] for k in ("max_side", "overrides")})
        if given and bounces != 1 and not study.paths:
            why = (f"with {no_visibility} every object is lit as if alone, so no light passes between them"
                   if not visibility else "no light passes between this scene's surfaces")
            say(f"{said['bounces']} {bounces}: {why}; the reference is the direct light (bounces 1)")
        ladder_file = None
        if ladder in ladders.LADDERS:
            rungs = ladders.LADDERS[ladder](study.scene, study.fx)
        elif ladder:
            ladder_file = os.fspath(ladder)
            rungs = ladders.ladder_from_file(ladder_file, study.scene, study.fx, flag=said["ladder"])
        else:
            rungs = ladders.default_ladder(study.scene, study.fx, rt.info.kind, paths=study.paths)
            over = [r for r in rungs if dict(r.values).get("effects.reference.max_samples", 0) > max_samples]
            if over:                     # measured against a reference of fewer samples: their error is its noise
                say(f"left out {len(over)} rungs with more samples than the reference's {said['max_samples']} "
                    f"{max_samples}: {', '.join(r.label for r in over)}")
                rungs = [r for r in rungs if r not in over]
        rungs = [ladders.configured_rung(study.scene, t) for t in study.terms] + rungs
        reads = scene_load.named_input_files(study.scene) + ([("the ladder", ladder_file)] if ladder_file else [])
        for r in rungs:                  # every rung's scene validates before anything renders
            reads += scene_load.named_input_files(study.load(study.rung_values(r), origin=f"ladder rung {r.label!r}"))
        if not os.path.isfile(sc.source):    # a mapping: no scene file is read
            reads = [(what, path) for what, path in reads if what != "the scene file"]
        if before_run:
            before_run(study, rungs, reads)
        spread = None
        if jobs > 1:
            from iblbake.study import workers
            spread = workers.render_references_parallel(study, jobs, list(devices or [device]), warn=say)
        study.progress = progress or (lambda *_: None)
        refs = {t: study.render_reference(t) for t in study.terms}
        rows = [study.run_rung(r) for r in rungs]
        for t in study.terms:
            r = refs[t]
            if "max_samples" in r["stopped"] and r["noise_each"] > 2 * target_noise:
                say(f"the {t} reference stopped at {max_samples} samples per pixel with noise "
                    f"{100 * r['noise']:.2f}% (target {100 * target_noise:g}% per seed): errors below about twice "
                    f"that are its noise. Slow convergence on a path-traced reference is light reaching a "
                    f"surface by a mirror or a glossy lobe from a small bright source (a caustic), which "
                    f"only BSDF sampling finds: raise {said['max_samples']}, or {said['bounces']} 1 for the "
                    f"direct light")
        configured = study.configured_frame()
        front = acc.frontiers(rows)
        high = acc.above_reference(rows)
        if high:
            say(f"{len(high)} {'rungs have' if len(high) > 1 else 'rung has'} more samples than the reference reached "
                f"({', '.join(r['label'] for r in high)}): their error is the reference's noise; kept off "
                f"the frontier (raise {said['max_samples']} above theirs to measure them)")
        records = [{**r, "pareto": r["label"] in front.get(r["term"], [])} for r in rows]
        summary = {
            "scene": str(scene) if from_file else sc.source, "device": rt.device_label,
            "resolution": acc.study_resolution(study.scene, max_side), "repeats": repeats,
            "reference": {t: {k: v for k, v in refs[t].items() if k not in ("hdr", "mask")} | {
                "stopping_rule": f"each seed: relative standard error <= {target_noise} or {max_samples} samples",
                "bounces": bounces if study.paths else 1,
                "object_pixels": int(refs[t]["mask"].sum()),
                "measured_pixels": int(study.metric_mask(t, refs[t]["hdr"]).sum())} for t in study.terms},
            "rungs": records, "frontier": front, "configured": configured,
            "time_split_s": {k: round(v, 3) for k, v in study.times.items()},
        }
        if spread:
            summary["reference_workers"] = spread
        return Accuracy(records, front, refs, configured, summary, study, rungs)


def __getattr__(name):
    # the scene and frame classes live with their loader and renderer (iblbake.scene.load,
    # iblbake.render.frame), which import the schema, YAML and numpy: loaded when asked for
    if name == "Scene":
        from iblbake.scene.load import Scene
        return Scene
    if name == "Frame":
        from iblbake.render.frame import Frame
        return Frame
    raise AttributeError(f"module 'iblbake.api' has no attribute {name!r}")
