"""A panorama's bakes: spherical harmonics, the GGX-prefiltered chain and the DFG table."""

from __future__ import annotations

import time
from dataclasses import dataclass

from iblbake.api.guards import _arguments, _callback, _choice, _count, _device, _fits, _flag, _intensity, _names, _real
from iblbake.api.panorama import Panorama, _panorama
from iblbake.api.runtimes import _on_device, _runtime
from iblbake.errors import InputError

# the most samples a texel of prefilter (fis) and dfg takes: the scene keys' bound (docs/scene.md)
MAX_SAMPLES = 1 << 20

# Host memory of the panorama bakes, measured with tracemalloc (64x32 to 1024x512 panoramas, every
# basis and option; the constants hold the largest per texel, the fixed tables aside): the float64
# copy of the texels and the exact irradiance the `error` blocks sum, per texel; sh's host
# projection adds its (bands^2, rows x azimuth terms) contraction (a basis's fit: api/bases.py).
SH_BYTES_PER_TEXEL = {"numpy": 64, "opencl": 16}
ERROR_BYTES_PER_TEXEL = 64
TABLE_BYTES = 64 << 20


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
