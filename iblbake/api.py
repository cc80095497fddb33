"""iblbake's public API (docs/api.md): bake image-based lighting from Python and get numpy arrays.

Every function returns arrays or the small dataclasses below, prints nothing and raises
iblbake.Error subclasses (iblbake.errors) with the one-line messages the command line prints;
warnings are returned (a `warnings` list) or passed to a `warn(message)` callback. The command
line (iblbake.cli) is a layer over this module: what a command bakes, this module bakes.

Conventions (docs/conventions.md): world right-handed, +y up; panoramas equirectangular
(u = 0.5 - atan2(x, z) / (2 pi), v = acos(y) / pi, row 0 at the top), linear RGB, radiance in
the file's units (W m^-2 sr^-1 for a physical one); roughness is perceptual (alpha = r^2).

Imports are lazy (numpy, OpenImageIO and pyopencl load inside the functions): `import iblbake`
stays cheap and each call pays for what it uses.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from iblbake.errors import InputError

if TYPE_CHECKING:                 # loaded on first use (import iblbake stays light)
    from iblbake.render.frame import Frame

# one OpenCL runtime per device spec for the process: sh, prefilter and dfg reuse it (building
# the kernels and probing the device is the start-up cost of a bake)
_RUNTIMES: dict = {}


def _runtime(device: str | None):
    key = device or ""
    if key not in _RUNTIMES:
        from iblbake.device.runtime import Runtime
        _RUNTIMES[key] = Runtime(device)
    return _RUNTIMES[key]


def _whole(value) -> bool:
    """A whole number (a numpy integer too), not a bool."""
    import numbers
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _choice(name: str, value, choices) -> None:
    if value not in choices:
        raise InputError(f"{name} {value!r}: use one of {', '.join(map(str, choices))}")


# ----------------------------------------------------------------------------------- panoramas

@dataclass
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
    """

    pixels: object
    layout: str
    colour_space: str
    path: str
    info: object
    policies: dict = field(default_factory=dict)
    read_s: float = 0.0

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
    def from_pixels(cls, pixels, name: str = "<array>", nonfinite: str = "error", negative: str = "keep") -> Panorama:
        """A panorama from an array (H, W, 3) of linear Rec.709 RGB radiance, equirectangular;
        the nonfinite and negative policies apply as for a file (load_panorama)."""
        import hashlib

        import numpy as np

        from iblbake.io import images

        rgb = np.ascontiguousarray(pixels, dtype=np.float32)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or 0 in rgb.shape:
            raise InputError(f"{name}: a panorama is an array (H, W, 3), not {rgb.shape}")
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
    max_pixels: refuse larger images before decoding (default $IBLBAKE_MAX_PIXELS or 8192^2).
    names: what error messages call each policy (the command line passes its flags).

    Raises InputError naming the file and what to do.
    """
    from iblbake.bake import inputs

    _choice("layout", layout, inputs.LAYOUTS)
    _choice("primaries", primaries, ("auto", "keep", "convert"))
    _choice("nonfinite", nonfinite, ("error", "zero", "clamp"))
    _choice("negative", negative, ("keep", "clamp", "error"))
    _choice("transfer", transfer, ("auto", "srgb", "linear"))
    t0 = time.perf_counter()
    pixels, info = inputs.read_environment(path, layout=layout, max_pixels=max_pixels, nonfinite=nonfinite,
                                           negative=negative, transfer=transfer, primaries=primaries, names=names)
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

    def to_filament(self):
        """(9, 3) Filament IndirectLight irradiance (cmgen's sh.txt): E_k times Filament's basis
        constants / pi; its shader's polynomial gives E(n) / pi. At most 3 bands."""
        from iblbake.bake import sh as shbake
        return shbake.filament_coefficients(self.document)

    def to_threejs(self):
        """(9, 3) three.js SphericalHarmonics3 (a LightProbe's sh): the radiance coefficients
        L_k, fewer bands padded with zeros. At most 3 bands."""
        from iblbake.bake import sh as shbake
        return shbake.threejs_coefficients(self.document)

    def to_gltf(self):
        """(9, 3) EXT_lights_image_based irradianceCoefficients as Babylon.js reads them: E_k
        with the Condon-Shortley signs and the loader's x mirror. At most 3 bands."""
        from iblbake.bake import sh as shbake
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
        return shbake.export(self.document, fmt)


def sh(panorama: Panorama, bands: int = 3, window: str | None = None, *, rotate_y: float = 0.0,
       intensity: float = 1.0, backend: str = "auto", device: str | None = None, error: bool = True) -> SH:
    """Project a panorama onto spherical harmonics (exact texel integrals, float64) and bake the
    irradiance coefficients.

    bands: 1 to 16 (l = 0..bands-1; 3 gives the classic 9 coefficients).
    window: None (or 'none'), 'hann' w_l = (1 + cos(pi l / bands)) / 2 or 'lanczos'
        w_l = sinc(l / bands), applied per band against ringing around bright suns.
    rotate_y: degrees about +y (+x towards -z). intensity: a scale of the radiance (>= 0).
    backend: 'numpy' (host, float64), 'opencl' (the reduction kernel on `device`) or 'auto'
        (numpy where that is quicker than starting OpenCL).
    device: an OpenCL device spec ('gpu', 'cpu', 'gpu:N', 'P:D' or part of a name).
    error: measure the SH irradiance against the exact irradiance (SH.error).

    Returns an SH (the coefficients in the convention its docstring gives, with converters
    to the engine formats).
    """
    import math

    import numpy as np

    from iblbake.bake import sh as shbake
    from iblbake.core import sh as core_sh

    window = window or "none"
    bands = int(bands) if _whole(bands) else bands
    if not (_whole(bands) and 1 <= bands <= core_sh.MAX_BANDS):
        raise InputError(f"bands {bands!r}: use 1 to {core_sh.MAX_BANDS}")
    _choice("window", window, core_sh.WINDOWS)
    _choice("backend", backend, ("auto", *shbake.BACKENDS))
    if not (math.isfinite(rotate_y) and math.isfinite(intensity) and intensity >= 0):
        raise InputError(f"rotate_y {rotate_y}, intensity {intensity}: give finite numbers, intensity >= 0")
    t_start = time.perf_counter()
    info = panorama.info
    backend = shbake.choose_backend(backend, panorama.width, panorama.height, bands)
    rt = _runtime(device) if backend == "opencl" else None
    device_label = rt.device_label if rt else "numpy (float64, host)"
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


def prefilter(panorama: Panorama, size: int | None = None, levels: int | None = None, layout: str = "equirect", *,
              min_size: int = 8, method: str = "auto", samples: int = 256, backend: str = "opencl",
              device: str | None = None, progress=None) -> Chain:
    """GGX-prefilter a panorama into a chain of levels of increasing roughness (not cached; the
    command `iblbake mips` bakes the same levels into its cache).

    size: the base size (equirect height, cube face or octahedral side; default: the panorama's
        height, half of it for a cube map). levels: K (default: one per halving down to
        min_size). layout: 'equirect', 'cubemap' or 'octahedral'.
    method: 'spectral' (exact, in the SH domain), 'convolve' (exact sum over texels), 'fis'
        (filtered importance sampling with `samples` samples a texel) or 'auto'.
    backend: 'opencl' (on `device`) or 'numpy' (the float64 twins: small sizes only).
    progress: called with 1 as each level is done.
    """
    from iblbake.bake import layouts
    from iblbake.bake import mips as mipsbake

    _choice("layout", layout, tuple(layouts.LAYOUT_IDS))
    _choice("method", method, ("auto", "spectral", "convolve", "fis"))
    _choice("backend", backend, ("opencl", "numpy"))
    for name, v, least in (("size", size, 1), ("levels", levels, 1), ("min_size", min_size, 1),
                           ("samples", samples, 1)):
        if v is not None and not (_whole(v) and v >= least):
            raise InputError(f"{name} {v!r}: give a whole number >= {least}")
    size, levels, min_size, samples = (None if v is None else int(v) for v in (size, levels, min_size, samples))
    baker = mipsbake.Baker(backend, rt=_runtime(device) if backend == "opencl" else None)

    def options(s):
        return mipsbake.PrefilterOptions(layout, s, levels, min_size, method, samples)

    opts = options(size).resolved(panorama.height)
    mipsbake.check_chain_fits(layout, opts["base_size"], lambda s: options(s).resolved(0)["sizes"], baker.rt, "size")
    chain = baker.radiance_chain(panorama.pixels)
    out, methods = baker.prefilter(chain, opts, progress=progress)
    return Chain(layout, out, list(opts["roughness"]), list(opts["sizes"]), list(methods))


def dfg(size: int = 128, *, samples: int = 4096, multiscatter: bool = False, backend: str = "opencl",
        device: str | None = None):
    """The split sum's DFG table: float32 (size, size, 2), column i NoV = i / (size - 1) (at least
    1e-4), row j perceptual roughness r = j / (size - 1); channels (A, B) with
    specular = prefiltered * (F0 A + F90 B), or with multiscatter (B, A + B), Filament's energy
    compensation. GGX, height-correlated Smith; `samples` GGX samples per texel. Baked once a
    process per device and arguments."""
    from iblbake.bake import mips as mipsbake

    _choice("backend", backend, ("opencl", "numpy"))
    if not (_whole(size) and 2 <= size <= 4096):
        raise InputError(f"size {size!r}: use 2 to 4096")
    if not (_whole(samples) and samples >= 1):
        raise InputError(f"samples {samples!r}: give a whole number >= 1")
    baker = mipsbake.Baker(backend, rt=_runtime(device) if backend == "opencl" else None)
    return mipsbake.dfg_table(baker, int(size), int(samples), bool(multiscatter))


# ------------------------------------------------------------------------------ scenes, frames

def load_scene(path_or_dict, overrides=(), *, folder=".", outputs=None):
    """A validated scene (iblbake.Scene: .data, the scene with every default filled and every path
    absolute; `iblbake render --help-schema` lists the keys).

    path_or_dict: a scene YAML file, or a mapping of what one holds (its relative paths resolve
        in `folder`).
    overrides: 'key.path=value' strings applied before validation (values parse as YAML), as
        `iblbake render --set`.
    outputs: frame paths that replace output.frame (as `render -o`).

    Raises InputError naming the file, line and dotted key (the closest valid key for a typo).
    """
    from iblbake.scene import load as scene_load

    if isinstance(path_or_dict, dict):
        return scene_load.load_data(path_or_dict, folder, overrides, outputs)
    return scene_load.load(path_or_dict, overrides, outputs)


class Renderer:
    """Renders scenes on one OpenCL runtime and one bake cache, across calls: kernels are built
    once, bakes (SH, chains, DFG, probes) are kept in memory and in the cache folder, and with
    `reuse` passes whose inputs did not change since the last frame are not run again.

    device: an OpenCL device spec (default $IBLBAKE_DEVICE, else the first working GPU, else
        CPU). cache: the bake cache folder (default $IBLBAKE_CACHE, else the per-user cache).
    reuse: keep the last frame on the device for the next (a series of frames of one size).
    """

    def __init__(self, device: str | None = None, cache=None, reuse: bool = True):
        from iblbake.render import Bakes, Reuse

        self.runtime = _runtime(device)
        self.bakes = Bakes(cache)
        self.bakes.runtime = self.runtime
        self._reuse = Reuse() if reuse else None

    @property
    def device(self) -> str:
        return self.runtime.device_label

    def render(self, scene, *, warn=None, progress=None) -> Frame:
        """Render a Scene (load_scene) into a Frame (iblbake.Frame: hdr, tonemapped, aovs,
        report). warn(message) gets the warnings; progress(fraction) the share of long work
        (path tracing, probe rays) done."""
        from iblbake.render import frame as render_frame

        return render_frame.render(_scene(scene), runtime=self.runtime, cache=self.bakes, reuse=self._reuse,
                                   warn=warn, progress=progress)


def _scene(scene):
    from iblbake.scene.load import Scene
    return scene if isinstance(scene, Scene) else load_scene(scene)


def render(scene, device: str | None = None, *, cache=None, warn=None, progress=None) -> Frame:
    """Render a scene once (a Scene, a scene file or a mapping; see load_scene) on `device` into a
    Frame (HDR array, tone-mapped array, report). A series of frames: use a Renderer."""
    return Renderer(device, cache, reuse=False).render(scene, warn=warn, progress=progress)


# ----------------------------------------------------------------------------------- probes

@dataclass
class ProbeVolume:
    """A scene's irradiance probe volume (DDGI, RTXGI's layouts; docs/manual.md 'iblbake probes').

    irradiance: float32, the octahedral atlas (rows, columns, 3) or, for probes.irradiance: sh,
        (probes, 9, 3) SH irradiance coefficients (SH's convention), or for a directional basis
        (probes, floats, 3) its radiance coefficients (manifest['basis'] says its layout).
    distance: float32 atlas of the ray distances' moments (R: mean distance, G: its square).
    data: float32 (probes, 4): each probe's offset from its grid position in world units, and
        its state (0 active, 1 inactive).
    grid: origin, spacing and counts (x, y, z); probe (gx, gy, gz) sits at
        origin + (gx, gy, gz) * spacing + offset, index gy * nx * nz + gz * nx + gx.
    states: the count of active and inactive probes.
    manifest: probes.json as `iblbake probes` writes it (every convention spelled out).
    reflections: each reflection probe's capture: {'capture': float32 (h, 2h, 4), 'settings'}.
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


def bake_probes(scene, device: str | None = None, *, cache=None, warn=None, progress=None) -> ProbeVolume:
    """Bake a scene's irradiance probe volume (its `probes:` section) by tracing paths from every
    probe, and each reflection probe's capture; cached by content in `cache` (as render)."""
    from iblbake.render import Bakes, probes
    from iblbake.render.units import Job

    sc = _scene(scene)                  # asked for by name: the scene's effects need not read probes
    if not sc.data["objects"]:
        raise InputError(f"{sc.source}: the scene has no objects; probes light objects (add some)")
    rt = _runtime(device)
    bakes = Bakes(cache)
    bakes.runtime = rt
    job = Job(sc, rt, bakes, warn or (lambda _m: None), progress)
    for w in bakes.environment(sc.data["environment"])[1].warnings:     # as a frame says them
        job.warn(w)
    vol, cached, extra = bakes.load("probes", job)
    reflections = bakes.load("reflection_probes", job)[0] if sc.data["reflection_probes"] else []
    vol = probes.sampled(vol, sc.data["probes"])
    man = probes.manifest(vol)
    man["reflection_probes"] = [{"file": f"reflection_{k}.exr", **c["settings"],
                                 "layout": "equirect in the world frame (the panoramas' mapping); RGB the linear "
                                           "radiance of the scene, A the share of the texel the scene covers (the "
                                           "rest is the distant panorama along the reflected ray)"}
                                for k, c in enumerate(reflections)]
    return ProbeVolume(vol["irradiance"], vol["distance"], vol["data"], man["grid"], man["states"],
                       man["representation"], man, list(reflections), cached, extra["entry"], rt.device_label, vol)


# --------------------------------------------------------------------------------- accuracy

@dataclass
class Accuracy:
    """What each approximation of a scene's lighting costs and how far it is from the converged
    reference (docs/manual.md 'What accuracy costs').

    records: one dict a rung (the table's rows): term, label, values (the scene keys it sets),
        mode, time_s (median lighting-pass seconds), frame_s, bake_s, kernel_build_s,
        relative_rmse, mean and max relative error, flip (HDR-FLIP, where measured), pareto.
    frontier: term -> the labels on its Pareto frontier of (time, relative RMSE), by time.
    reference: term -> the reference's noise (two seeds), samples per pixel, what stopped it,
        seconds; hdr and mask are the float32 (H, W, 4) frame and its measured pixels.
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


def accuracy(scene, ladder=None, *, overrides=(), max_side: int = 320, repeats: int = 3,
             target_noise: float = 0.003, max_samples: int = 4096, visibility: bool = True, bounces=None,
             flip: bool = True, cache=None, device: str | None = None, jobs: int = 1, devices=None, warn=None,
             progress=None, before_run=None) -> Accuracy:
    """Render a scene's converged reference per lighting term (diffuse, specular: visibility and
    every bounce, two seeds, its noise measured), then a ladder of approximations of each term,
    each timed (median of `repeats` renders) and measured over the object pixels.

    scene: a scene file (the study loads it at `max_side` with each rung's values).
    ladder: None (the default ladder for the scene and device), 'realtime' (the real-time modes
        as shipped) or a ladder file ({rungs: [AXIS, ...]} in the sweep syntax).
    bounces: the reference's bounces: 'unbounded' or a count (1: the direct light alone). None is
        unbounded; a value given, other than 1, is warned about where no light passes between
        the scene's surfaces (the reference is then the direct light).
    target_noise, max_samples: the reference's stopping rule per seed.
    jobs, devices: render the reference seeds in `jobs` worker processes, one device spec each
        in turn (a list), into the cache.
    warn(message): what the study says (a reference stopped short, rungs left out).
    progress(): called as each reference seed and rung is done.
    before_run(study, rungs, reads): called once every rung's scene has validated and before
        anything renders; reads are (what, path) of every file the study reads.
    """
    from iblbake.render import Bakes
    from iblbake.scene import load as scene_load
    from iblbake.study import accuracy as acc, ladder as ladders

    say = warn or (lambda _m: None)
    given = bounces is not None
    bounces = "unbounded" if bounces is None else bounces
    settings = acc.Settings(max_side=max_side, repeats=repeats, target_noise=target_noise, max_samples=max_samples,
                            flip=flip, visibility=visibility, bounces=bounces)
    rt = _runtime(device)
    study = acc.Study(str(scene), overrides, settings, runtime=rt, bakes=Bakes(cache), warn=warn)
    if given and bounces != 1 and not study.paths:
        why = ("with --no-visibility every object is lit as if alone, so no light passes between them"
               if not visibility else "no light passes between this scene's surfaces")
        say(f"--bounces {bounces}: {why}; the reference is the direct light (bounces 1)")
    ladder_file = None
    if ladder in ladders.LADDERS:
        rungs = ladders.LADDERS[ladder](study.scene, study.fx)
    elif ladder:
        ladder_file = str(ladder)
        rungs = ladders.ladder_from_file(ladder_file, study.scene, study.fx)
    else:
        rungs = ladders.default_ladder(study.scene, study.fx, rt.info.kind, paths=study.paths)
        over = [r for r in rungs if dict(r.values).get("effects.reference.max_samples", 0) > max_samples]
        if over:                     # measured against a reference of fewer samples: their error is its noise
            say(f"left out {len(over)} rungs with more samples than the reference's --max-samples "
                f"{max_samples}: {', '.join(r.label for r in over)}")
            rungs = [r for r in rungs if r not in over]
    rungs = [ladders.configured_rung(study.scene, t) for t in study.terms] + rungs
    reads = scene_load.named_input_files(study.scene) + ([("the ladder", ladder_file)] if ladder_file else [])
    for r in rungs:                  # every rung's scene validates before anything renders
        reads += scene_load.named_input_files(study.load(study.rung_values(r), origin=f"ladder rung {r.label!r}"))
    if before_run:
        before_run(study, rungs, reads)
    spread = None
    if jobs > 1:
        from iblbake.study import workers
        spread = workers.render_references_parallel(study, jobs, list(devices or [device]))
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
                f"only BSDF sampling finds: raise --max-samples, or --bounces 1 for the direct light")
    configured = study.configured_frame()
    front = acc.frontiers(rows)
    high = acc.above_reference(rows)
    if high:
        say(f"{len(high)} {'rungs have' if len(high) > 1 else 'rung has'} more samples than the reference reached "
            f"({', '.join(r['label'] for r in high)}): their error is the reference's noise; kept off "
            f"the frontier (raise --max-samples above theirs to measure them)")
    records = [{**r, "pareto": r["label"] in front.get(r["term"], [])} for r in rows]
    summary = {
        "scene": str(scene), "device": rt.device_label,
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
