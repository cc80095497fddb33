"""`iblbake mips`: plan, bake and cache the radiance chain, the prefiltered chain and the DFG table.

Three cache entries, each keyed by what changes its content, so that a renderer that reads only
one of them bakes only that one:
- radiance:    the input's content and read policies
- prefiltered: that, plus layout, sizes, levels, method, samples, bias
- dfg:         size, samples, variant (independent of the panorama)
One EXR per level (a truncated chain or a cube/octahedral layout is not a standard MIP-mapped
EXR, which must go down to 1x1 in one 2D layout); the manifest lists sizes and roughness.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from iblbake.bake import cache
from iblbake.device import runtime as cl
from iblbake.device.programs import source_hash
from iblbake.io import images, memory
from iblbake.bake import dfg
from iblbake.bake import layouts
from iblbake.bake import mips
from iblbake.bake import prefilter
from iblbake.bake import radiance
from iblbake.bake import spectral
from iblbake.errors import InputError

FORMAT = "iblbake.mips"
FORMAT_VERSION = 1
DEFAULT_SAMPLES = 256
DEFAULT_LOD_BIAS = 1.0
# Weight evaluations of `convolve` allowed per level before `auto` switches to FIS: about half a
# second on each kind of device (measured: ~2.6e8/s on 2 CPU cores with PoCL; the H100 runs the
# whole face-128 chain, 7e9 evaluations, in 0.16 s).
CONVOLVE_BUDGET = {"CPU": 1.5e8, "GPU": 2e10}
DEFAULT_CONVOLVE_BUDGET = CONVOLVE_BUDGET["CPU"]


@dataclass
class PrefilterOptions:
    layout: str = "equirect"
    size: int | None = None
    levels: int | None = None
    min_size: int = layouts.MIN_LEVEL_SIZE
    method: str = "auto"
    samples: int = DEFAULT_SAMPLES
    lod_bias: float = DEFAULT_LOD_BIAS
    fis: bool = True
    convolve_budget: float | None = None   # None: CONVOLVE_BUDGET of the device kind
    level_sizes: str = "halving"           # halving: base >> k (a mip chain); lobe: layouts.lobe_sizes

    def resolved(self, src_height: int) -> dict:
        base = self.size or layouts.default_base_size(self.layout, src_height)
        sizes = layouts.prefiltered_sizes(base, self.levels, self.min_size)
        if self.level_sizes == "lobe":
            sizes = layouts.lobe_sizes(base, len(sizes), self.min_size)
        return {"layout": self.layout, "base_size": base, "sizes": sizes,
                "roughness": layouts.level_roughness(len(sizes)), "method": self.method,
                "samples": self.samples, "lod_bias": self.lod_bias, "fis": self.fis,
                "convolve_budget": self.convolve_budget}


# What a prefiltered bake holds on the host: every level of the chain as float32 RGB, and while its
# largest level bakes, that level's float64 texel directions and float32 results. Measured peak
# resident size: about 45 bytes per level-0 texel over the fixed start-up (mips --size 1024 and 2048,
# equirect and cube map); the device's largest buffer is one level as float4.
CHAIN_BYTES_PER_TEXEL = 12
WORK_BYTES_PER_TEXEL = 48
DEVICE_BYTES_PER_TEXEL = 16


def chain_bytes(layout: str, sizes) -> tuple[int, int]:
    """(host bytes, largest device buffer) of baking a prefiltered chain of these level sizes."""
    texels = [math.prod(layouts.layout_shape(layout, s)) for s in sizes]
    return (CHAIN_BYTES_PER_TEXEL * sum(texels) + WORK_BYTES_PER_TEXEL * max(texels),
            DEVICE_BYTES_PER_TEXEL * max(texels))


def check_chain_fits(layout: str, size: int, sizes_of, rt, flag: str, candidates=None) -> None:
    """Before any work: InputError naming `flag` and the largest size that fits where the chain of
    base `size` (level sizes `sizes_of(size)`) needs more host memory than is available or a
    larger buffer than the device `rt` allocates (rt None: the numpy backend, host only).
    `candidates`: the sizes the option allows, ascending (default every size up to `size`)."""
    host = memory.host_bytes_available()
    max_alloc = rt.info.device.max_mem_alloc_size if rt is not None else None

    def need(s):
        h, d = chain_bytes(layout, sizes_of(s))
        if host is not None and h > host:
            return f"{h / 2**30:.1f} GiB on the host, more than the {max(host, 0) / 2**30:.1f} GiB available"
        if max_alloc is not None and d > max_alloc:
            return (f"a {d / 2**30:.1f} GiB buffer on {rt.device_label}, over its largest allocation of "
                    f"{max_alloc / 2**30:.1f} GiB")
        return None

    why = need(size)
    if why is None:
        return
    allowed = candidates if candidates is not None else range(1, size + 1)
    # bisect for the last allowed size that fits (a range's length, not len(): 10^30 sizes overflow it)
    lo, hi = 0, (size if candidates is None else len(allowed)) - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        lo, hi = (mid, hi) if need(allowed[mid]) is None else (lo, mid - 1)
    fits = f"the largest that fits is {allowed[lo]}" if need(allowed[lo]) is None else "no size fits"
    raise InputError(f"{flag} {size}: the {layout} chain needs {why}; {fits}")


CONVOLVE_RESOLUTIONS = (12.0, 6.0)   # texels per lobe scale, finest first (see prefilter.TEXELS_PER_LOBE)


def plan_methods(chain_sizes, opts: dict, method_name: str = "method") -> list[str]:
    """Per level: 'resample' (mirror), 'spectral', 'convolve@T' (T texels per lobe scale) or
    'fis'. auto takes spectral (exact, fastest) where the lobe is wide enough for it, else the
    finest convolution that fits the budget, else FIS."""
    out = []
    for k, (s, r) in enumerate(zip(opts["sizes"], opts["roughness"])):
        if r == 0.0:
            out.append("resample")
        elif opts["method"] in ("auto", "spectral") and spectral.applicable(r * r):
            out.append("spectral")
        elif opts["method"] == "spectral":
            raise InputError(f"{method_name} spectral: level {k} (roughness {r:g}) is too sharp for the SH "
                             f"convolution (it needs bands beyond {spectral.MAX_LMAX}); use {method_name} auto, "
                             f"which bakes such levels with convolve or fis")
        elif opts["method"] == "convolve":
            out.append(f"convolve@{CONVOLVE_RESOLUTIONS[0]:g}")
        elif opts["method"] == "fis":
            out.append("fis")
        else:
            shape = layouts.layout_shape(opts["layout"], s)
            n = shape[0] * shape[1]
            fits = [t for t in CONVOLVE_RESOLUTIONS
                    if prefilter.convolve_cost(chain_sizes, n, r * r, t) <= opts["convolve_budget"]]
            out.append(f"convolve@{fits[0]:g}" if fits else "fis")
    return out


# A prefilter's host memory besides the output chain (chain_bytes): the source's radiance chain
# (on the numpy backend float64, its float32 copy and the float64 copy the twins read, 4/3 of the
# texels each; on OpenCL the float32 copy read back), and the largest level's work: the spectral
# method's projection of the source and its RGB coefficients (complex128, up to
# spectral.MAX_LMAX, a few copies; on either backend), and on the numpy backend FIS's float64
# directions, frames and sums per output texel or convolve_twin's sub-texel grid
# (prefilter.convolve_twin_bytes). Measured with tracemalloc on 64x32 and 256x128 sources and
# every method: the estimate is 1.0 to 2 times the peak.
SOURCE_BYTES_PER_TEXEL = {"numpy": 80, "opencl": 16}
TWIN_FIS_BYTES_PER_TEXEL = 400
SPECTRAL_BYTES_PER_TEXEL = 200


def prefilter_host_bytes(src_size, opts: dict, methods, backend: str) -> int:
    """Host bytes of a prefilter of a source (w, h) with these options and methods
    (Baker.plan) on `backend`, all told."""
    chain_sizes = layouts.radiance_chain_sizes(*src_size)
    n0 = src_size[0] * src_size[1]
    work = 0
    for s, r, how in zip(opts["sizes"], opts["roughness"], methods):
        n = math.prod(layouts.layout_shape(opts["layout"], s))
        if how == "spectral":
            lmax = len(spectral.zonal_coefficients(r * r)) - 1
            work = max(work, SPECTRAL_BYTES_PER_TEXEL * (n0 + n) + 4 * 48 * (lmax + 1) * (lmax + 2) // 2)
        elif backend != "numpy":
            continue
        elif how.startswith("convolve"):
            work = max(work, prefilter.convolve_twin_bytes(chain_sizes, r * r, float(how.split("@")[1])))
        else:
            work = max(work, TWIN_FIS_BYTES_PER_TEXEL * n + 64 * opts["samples"])
    return SOURCE_BYTES_PER_TEXEL[backend] * n0 + chain_bytes(opts["layout"], opts["sizes"])[0] + work


class OpenCLBaker:
    """Runs kernels/mips.cl on one device (iblbake.device.runtime.Runtime)."""

    def __init__(self, rt):
        self.rt = rt

    def radiance_chain(self, image):
        """Every level as float32 (h, w, 3), views of one array back to back, and the device
        buffer of the chain (RGB, 3 floats a texel)."""
        rt = self.rt
        sizes = layouts.radiance_chain_sizes(image.shape[1], image.shape[0])
        offsets = np.cumsum([0] + [w * h for w, h in sizes])
        buf = rt.empty(int(offsets[-1]) * 12)
        rt.cl.enqueue_copy(rt.queue, buf, np.ascontiguousarray(np.asarray(image)[..., :3], np.float32))
        for lvl in range(1, len(sizes)):
            (sw, sh), (dw, dh) = sizes[lvl - 1], sizes[lvl]
            rt.launch("mips.cl", "downsample", None, (dw, dh), chain=buf, src_off=offsets[lvl - 1], sw=sw, sh=sh,
                      dst_off=offsets[lvl], dw=dw, dh=dh)
        flat = rt.read(buf, (int(offsets[-1]), 3))
        levels = [flat[offsets[i]:offsets[i + 1]].reshape(h, w, 3) for i, (w, h) in enumerate(sizes)]
        return levels, (buf, offsets, sizes)

    def _chain_args(self, device_chain) -> dict:
        """CHAIN_PARAMS (kernels/envmap.h) of a device chain, by name."""
        buf, offsets, sizes = device_chain
        rt = self.rt
        return {"chain": buf, "off": rt.to_device(np.asarray(offsets[:-1], np.int32)),
                "lw": rt.to_device(np.asarray([w for w, _ in sizes], np.int32)),
                "lh": rt.to_device(np.asarray([h for _, h in sizes], np.int32)), "nlev": len(sizes)}

    def prefilter_level(self, device_chain, layout: str, s: int, roughness: float, n_samples: int,
                        lod_bias: float = 0.0, fis: bool = True):
        rt = self.rt
        shape = layouts.layout_shape(layout, s)
        n = shape[0] * shape[1]
        out = rt.empty(n * 16)
        defines = {"LAYOUT": layouts.LAYOUT_IDS[layout]}
        chain_args = self._chain_args(device_chain)
        global_size = (-(-n // 64) * 64,)
        if roughness == 0.0:
            rt.launch("mips.cl", "resample", defines, global_size, chain_args, size=s, ntexels=n, out=out)
        else:
            ss = prefilter.ggx_sample_set(roughness * roughness, n_samples)
            rt.launch("mips.cl", "prefilter", defines, global_size, chain_args, samples=rt.to_device(ss.rows),
                      nsamples=len(ss.rows), lod_bias=lod_bias, use_fis=1 if fis else 0, size=s, ntexels=n, out=out)
        return rt.read(out, (n, 4))[:, :3].reshape(shape + (3,))

    def convolve_level(self, chain_levels, layout: str, s: int, roughness: float,
                       texels_per_lobe: float = prefilter.TEXELS_PER_LOBE):
        """One prefiltered level by the deterministic `convolve` kernel."""
        rt = self.rt
        alpha = roughness * roughness
        sizes = [(c.shape[1], c.shape[0]) for c in chain_levels]
        lvl, sub = prefilter.convolve_level_choice(sizes, alpha, texels_per_lobe)
        src = chain_levels[lvl]
        shape = layouts.layout_shape(layout, s)
        n = shape[0] * shape[1]
        out = rt.empty(n * 16)
        col = prefilter.column_sin_cos(src.shape[1] * sub).astype(np.float32)
        rt.launch("mips.cl", "convolve", {"LAYOUT": layouts.LAYOUT_IDS[layout]}, (-(-n // 64) * 64,),
                  level=rt.to_device(radiance.to_rgba(src)), w=src.shape[1], h=src.shape[0], col_sc=rt.to_device(col),
                  sub=sub, alpha=alpha, cos_cut=prefilter.lobe_cutoff(alpha), size=s, ntexels=n, out=out)
        return rt.read(out, (n, 4))[:, :3].reshape(shape + (3,))

    def dfg(self, size: int, n_samples: int, multiscatter: bool = False):
        rt = self.rt
        out = rt.empty(size * size * 8)
        defines = {"MULTISCATTER": 1} if multiscatter else {}
        # a band of rows a launch, waited for: Ctrl-C lands between bands (the whole table is one
        # launch of seconds on a CPU), and no launch runs into a GPU's watchdog
        band = max(1, (1 << 22) // max(size * n_samples, 1))
        for y0 in range(0, size, band):
            rt.launch("mips.cl", "dfg", defines, (size, min(band, size - y0)), n=size, y0=y0, nsamples=n_samples,
                      out=out)
            rt.finish()
        return rt.read(out, (size, size, 2))


    def dfg_sheen(self, size: int, n_samples: int):
        rt = self.rt
        out = rt.empty(size * size * 4)
        rt.launch("mips.cl", "dfg_sheen", None, (size, size), n=size, nsamples=n_samples, out=out)
        return rt.read(out, (size, size))


class Baker:
    """Bakes on the OpenCL device (backend 'opencl') or with the numpy twins (backend 'numpy')."""

    def __init__(self, backend: str = "opencl", device: str | None = None, rt=None):
        self.backend = backend
        self.rt = rt or (cl.Runtime(device) if backend == "opencl" else None)
        self.gpu = mips.OpenCLBaker(self.rt) if self.rt else None
        self._device_chain = None

    @property
    def device_label(self) -> str:
        return self.rt.device_label if self.rt else "numpy (float64, host)"

    def radiance_chain(self, image):
        if self.gpu:
            levels, self._device_chain = self.gpu.radiance_chain(image)
            return levels
        return [c.astype(np.float32) for c in radiance.radiance_chain_twin(image)]

    def convolve_budget(self, opts: dict) -> float:
        if opts.get("convolve_budget") is not None:
            return opts["convolve_budget"]
        kind = self.rt.info.kind if self.rt else "CPU"
        return CONVOLVE_BUDGET.get(kind, DEFAULT_CONVOLVE_BUDGET)

    def plan(self, chain_sizes, opts: dict) -> list[str]:
        """plan_methods on this baker: the numpy backend's auto bakes a level by FIS where
        convolve_twin's sub-texel grid would not fit the host's memory (the kernel needs no grid)."""
        methods = plan_methods(chain_sizes, {**opts, "convolve_budget": self.convolve_budget(opts)},
                               opts.get("method_name", "method"))
        if self.gpu or opts["method"] != "auto":
            return methods
        free = memory.host_bytes_available()
        return ["fis" if how.startswith("convolve") and free is not None
                and prefilter.convolve_twin_bytes(chain_sizes, r * r, float(how.split("@")[1])) > free / 2 else how
                for how, r in zip(methods, opts["roughness"])]

    def prefilter(self, chain, opts: dict, progress=None):
        """Levels of the prefiltered chain (float32 images) and the method used for each."""
        sizes = [(c.shape[1], c.shape[0]) for c in chain]
        methods = self.plan(sizes, opts)
        layout = opts["layout"]
        # every spectral level from one projection of the source (host, float64, either backend)
        todo = [(s, r) for s, r, how in zip(opts["sizes"], opts["roughness"], methods) if how == "spectral"]
        done = iter(spectral.prefilter_levels(chain[0], [layouts.layout_dirs(layout, s) for s, _ in todo],
                                              [r for _, r in todo]) if todo else [])
        out = []
        chain64 = None if self.gpu else [c.astype(np.float64) for c in chain]
        for s, r, how in zip(opts["sizes"], opts["roughness"], methods):
            if how == "spectral":
                img = next(done)
            elif self.gpu:
                if self._device_chain is None:
                    _, self._device_chain = self.gpu.radiance_chain(chain[0])
                if how.startswith("convolve"):
                    img = self.gpu.convolve_level(chain, layout, s, r, float(how.split("@")[1]))
                else:
                    img = self.gpu.prefilter_level(self._device_chain, layout, s, 0.0 if how == "resample" else r,
                                                   opts["samples"], opts["lod_bias"], opts["fis"])
            else:
                dirs = layouts.layout_dirs(layout, s)
                if how.startswith("convolve"):
                    img = prefilter.convolve_twin(chain64, dirs, r, float(how.split("@")[1]))
                else:
                    img = prefilter.prefilter_twin(chain64, dirs, 0.0 if how == "resample" else r,
                                                   opts["samples"], opts["lod_bias"], opts["fis"])
            out.append(np.asarray(img, np.float32))
            if progress:
                progress(1)
        return out, methods

    def dfg(self, size: int, samples: int, multiscatter: bool):
        if self.gpu:
            return self.gpu.dfg(size, samples, multiscatter)
        return dfg.dfg_twin(size, samples, multiscatter).astype(np.float32)


    def dfg_sheen(self, size: int, samples: int):
        if self.gpu:
            return self.gpu.dfg_sheen(size, samples)
        return dfg.sheen_twin(size, samples).astype(np.float32)


def _check_finite(name, img):
    if not np.all(np.isfinite(img)):
        raise ValueError(f"{name}: non-finite values produced")


def bake_radiance(baker: Baker, image, info, root: Path, policies: dict, warn=None):
    key = cache.content_key({"format": FORMAT, "v": FORMAT_VERSION, "kind": "radiance",
                             "input": info.sha256, "policies": policies,
                             "kernel": source_hash("mips.cl")})
    state = {}

    def build(tmp: Path):
        t0 = time.perf_counter()
        chain = baker.radiance_chain(image)
        state["chain"] = chain
        files = []
        for k, lvl in enumerate(chain):
            _check_finite(f"radiance level {k}", lvl)
            name = f"radiance_{k:02d}.exr"
            images.write_exr(tmp / name, lvl, compression=images.CACHE_COMPRESSION)
            files.append({"name": name, "level": k, "width": lvl.shape[1], "height": lvl.shape[0]})
        return {"format": FORMAT, "format_version": FORMAT_VERSION, "kind": "radiance",
                "layout": "equirect", "files": files, "input": info.to_json(), "parameters": policies,
                "kernel_source_sha256": source_hash("mips.cl"), "device": baker.device_label,
                "timings": {"bake_s": time.perf_counter() - t0},
                "filter": "each texel is the solid-angle-weighted mean of the texels it covers"}

    manifest, cached = cache.get_or_build(root, key, build, warn=warn)
    return manifest, cached, state.get("chain")


def load_chain(root: Path, manifest: dict):
    """The entry's levels, float32 (h, w, 3), read back to back into one array (a renderer's
    chain table then uploads that array as it is)."""
    entry = Path(root) / manifest["key"]
    return images.read_exrs_back_to_back([entry / f["name"] for f in manifest["files"]])


def chain_loader(root: Path, manifest: dict, chain=None):
    """bake_prefiltered's `chain`: the radiance chain bake_radiance gave back (None where it came
    from the cache), read from the cache on first use only (a cached prefiltered entry needs none)."""
    state = {"chain": chain}

    def levels():
        if state["chain"] is None:
            state["chain"] = load_chain(root, manifest)
        return state["chain"]

    return levels


IRRADIANCE_LMAX = 256      # city at face 32: 1.6e-4 of the peak from the exact sum at worst, 0.07 s


def bake_irradiance_cube(image, info, root: Path, policies: dict, size: int, lmax: int = IRRADIANCE_LMAX,
                         warn=None):
    """The Lambert irradiance E(n) = int L max(0, n.w) dw at the texel centres of a cube map
    (faces +X -X +Y -Y +Z -Z stacked, 6s x s): the spectral route at band lmax (host, ducc0),
    its error against the exact float64 sum over every texel measured at 256 fixed normals and
    kept in the manifest. Cached like the chains. (manifest, cached, faces (6s, s, 3))."""
    from iblbake.bake import sh as shbake

    key = cache.content_key({"format": FORMAT, "v": FORMAT_VERSION, "kind": "irradiance-cube", "input": info.sha256,
                             "policies": policies, "size": size, "lmax": lmax, "spectral": spectral.source_hash()})
    holder = {}

    def build(tmp: Path):
        t0 = time.perf_counter()
        src = np.asarray(image, np.float64)
        faces = spectral.irradiance(src, layouts.layout_dirs("cubemap", size), lmax)
        normals = shbake.fibonacci_normals()
        exact = shbake.exact_irradiance(src, normals)
        got = spectral.irradiance(src, normals, lmax)
        err = np.abs(got - exact) / max(float(np.abs(exact).max()), 1e-300)
        holder["faces"] = faces.astype(np.float32)
        images.write_exr(tmp / "irradiance.exr", holder["faces"])
        return {"kind": "irradiance-cube", "layout": "cubemap", "size": size, "lmax": lmax,
                "files": [{"name": "irradiance.exr"}], "input": info.to_json(), "parameters": policies,
                "error": {"against": "sum over every texel of L max(0, n.d) dOmega, float64", "normals": len(normals),
                          "max_relative_to_peak": float(err.max()), "rms_relative_to_peak": float(np.sqrt((err ** 2).mean()))},
                "seconds": round(time.perf_counter() - t0, 4)}

    manifest, cached = cache.get_or_build(root, key, build, warn=warn)
    faces = holder.get("faces")
    if faces is None:
        faces = images.read_exr(Path(root) / manifest["key"] / "irradiance.exr")[..., :3]
    return manifest, cached, faces


def write_irradiance_ktx2(path: Path, faces, fmt: str, batch=None) -> None:
    """The irradiance cube map (6s x s faces, stacked) as a one-level KTX2 cube map (atomic: with
    `batch`'s other outputs, atomic.Batch, where given)."""
    from iblbake import __version__
    from iblbake.io import atomic, ktx2

    s = faces.shape[1]
    meta = {"iblbake.content": "Lambert irradiance E(n) = int L max(0, n.w) dw (divide by pi for an albedo-1 "
                               "surface's radiance)"}
    atomic.write_bytes(path, ktx2.cube_bytes([np.asarray(faces).reshape(6, s, s, -1)], fmt, meta,
                                             writer=f"iblbake {__version__}"), batch)


def check_ktx2_chain(path, opts: dict) -> None:
    """Fail before baking unless the chain is what KTX2 stores: cube faces, level k of size s >> k."""
    sizes = opts["sizes"]
    if opts["layout"] != "cubemap" or sizes != [max(1, sizes[0] >> k) for k in range(len(sizes))]:
        raise InputError(f"{path}: KTX2 stores a mip chain of cube faces (level k of size s >> k); the chain "
                         f"would have layout {opts['layout']} and sizes {sizes}: lower --levels or --min-size")


def write_ktx2(path: Path, root: Path, manifest: dict, opts: dict, fmt: str,
               content: str = "GGX-prefiltered radiance", batch=None) -> None:
    """The prefiltered cube-map chain of `manifest` as a KTX2 file (atomic: with `batch`'s other
    outputs, where given). Its roughness per level (k / (K - 1)) goes in the key/value data as
    iblbake.roughness (JSON)."""
    import json

    from iblbake import __version__
    from iblbake.io import atomic, ktx2

    check_ktx2_chain(path, opts)
    sizes = opts["sizes"]
    levels = [lv.reshape(6, s, s, -1) for lv, s in zip(load_chain(root, manifest), sizes)]
    meta = {"iblbake.roughness": json.dumps([round(r, 6) for r in opts["roughness"]]),
            "iblbake.layout": f"{content}; level k's roughness in iblbake.roughness; axes: +y up, faces in Vulkan orientation"}
    atomic.write_bytes(path, ktx2.cube_bytes(levels, fmt, meta, writer=f"iblbake {__version__}"), batch)


def bake_prefiltered(baker: Baker, chain, info, root: Path, policies: dict, opts: dict, warn=None,
                     progress=None):
    # the budget decides each level's method, so the resolved value is part of the key
    opts = {**opts, "convolve_budget": baker.convolve_budget(opts)}
    # what a plan error calls the method option (render: the scene key) is not part of the bake
    keyed = {k: v for k, v in opts.items() if k != "method_name"}
    key = cache.content_key({"format": FORMAT, "v": FORMAT_VERSION, "kind": "prefiltered",
                             "input": info.sha256, "policies": policies, "options": keyed,
                             "kernel": source_hash("mips.cl"), "spectral": spectral.source_hash()})

    def build(tmp: Path):
        t0 = time.perf_counter()
        levels, methods = baker.prefilter(chain(), opts, progress)
        files = []
        for k, (lvl, r, s, how) in enumerate(zip(levels, opts["roughness"], opts["sizes"], methods)):
            _check_finite(f"prefiltered level {k}", lvl)
            name = f"prefiltered_{k:02d}.exr"
            images.write_exr(tmp / name, lvl, compression=images.CACHE_COMPRESSION)
            files.append({"name": name, "level": k, "roughness": r, "alpha": r * r, "size": s,
                          "width": lvl.shape[1], "height": lvl.shape[0], "method": how})
        return {"format": FORMAT, "format_version": FORMAT_VERSION, "kind": "prefiltered",
                "layout": opts["layout"],
                "layout_description": {
                    "equirect": "2s x s latitude-longitude, u = 0.5 - atan2(x, z)/(2 pi), v = acos(y)/pi",
                    "cubemap": "faces +X -X +Y -Y +Z -Z of s x s stacked top to bottom (s x 6s image)",
                    "octahedral": "s x s octahedral map, +y at the centre"}[opts["layout"]],
                "roughness_mapping": "level k of K has perceptual roughness r_k = k / (K - 1), alpha = r^2",
                "files": files, "input": info.to_json(), "parameters": {**policies, **keyed},
                "kernel_source_sha256": source_hash("mips.cl"), "device": baker.device_label,
                "timings": {"bake_s": time.perf_counter() - t0}}

    return cache.get_or_build(root, key, build, warn=warn)


_DFG_TABLES: dict = {}      # (device, size, samples, multiscatter) -> the table this process baked


def dfg_table(baker: Baker, size: int, samples: int, multiscatter: bool):
    """The DFG table, baked once per process and device (a second cache folder gets the same
    table written into its entry, not baked again: 67M samples, 5 s on a 2-core CPU)."""
    key = (baker.device_label, size, samples, multiscatter)
    if key not in _DFG_TABLES:
        _DFG_TABLES[key] = baker.dfg(size, samples, multiscatter)
    return _DFG_TABLES[key].copy()


def bake_dfg(baker: Baker, root: Path, size: int, samples: int, multiscatter: bool, warn=None):
    params = {"size": size, "samples": samples, "multiscatter": multiscatter}
    key = "dfg-" + cache.content_key({"format": FORMAT, "v": FORMAT_VERSION, "kind": "dfg", **params,
                                      "kernel": source_hash("mips.cl")})

    def build(tmp: Path):
        t0 = time.perf_counter()
        table = dfg_table(baker, size, samples, multiscatter)
        _check_finite("dfg", table)
        channels = ("B", "A+B") if multiscatter else ("A", "B")
        images.write_exr(tmp / "dfg.exr", table, channels=("R", "G"), compression=images.CACHE_COMPRESSION,
                         attributes={"iblbake:channels": ",".join(channels)})
        return {"format": FORMAT, "format_version": FORMAT_VERSION, "kind": "dfg",
                "files": [{"name": "dfg.exr", "width": size, "height": size, "channels": list(channels)}],
                "parameters": params,
                "axes": "x: NoV = i/(size-1) (clamped to >= 1e-4), y: perceptual roughness r = j/(size-1), "
                        "both grids include 0 and 1; sample at ((x*(size-1)+0.5)/size)",
                "use": ("specular = prefiltered * mix(R, G, F0): R = B, G = A + B; energy compensation "
                        "1 + F0 * (1/G - 1) (Filament)") if multiscatter else
                       "specular = prefiltered * (F0 * R + F90 * G): R = A (scale), G = B (bias)",
                "kernel_source_sha256": source_hash("mips.cl"), "device": baker.device_label,
                "timings": {"bake_s": time.perf_counter() - t0}}

    return cache.get_or_build(root, key, build, warn=warn)


# Charlie's lobe collapses onto the horizon ring as roughness -> 0 (beyond any band limit); the
# sheen's own albedo (the sheen table) goes to 0 there, so level 0 holds this roughness's lobe
SHEEN_R_MIN = 0.07


def sheen_roughness(roughness) -> list:
    return [max(float(r), SHEEN_R_MIN) for r in roughness]


def bake_sheen(image, info, root: Path, policies: dict, opts: dict, warn=None):
    """The Charlie-prefiltered chain (KHR_materials_sheen's IBL lobe, as glTF-IBL-Sampler filters
    it: N = V = R, h from D_charlie (n.h), weight NoL), level k of roughness max(k/(K-1), 0.07),
    in the prefiltered chain's layout and sizes: the spectral route (host, ducc0)."""
    sizes, layout = opts["sizes"], opts["layout"]
    rough = sheen_roughness(opts["roughness"])
    key = cache.content_key({"format": FORMAT, "v": FORMAT_VERSION, "kind": "sheen", "input": info.sha256,
                             "policies": policies, "layout": layout, "sizes": sizes, "roughness": rough,
                             "spectral": spectral.source_hash()})

    def build(tmp: Path):
        t0 = time.perf_counter()
        dirs = [layouts.layout_dirs(layout, s) for s in sizes]
        levels = spectral.prefilter_levels(np.asarray(image, np.float64), dirs, rough, ndf="charlie")
        files = []
        for k, lvl in enumerate(levels):
            name = f"sheen_{k:02d}.exr"
            images.write_exr(tmp / name, lvl.astype(np.float32), compression=images.CACHE_COMPRESSION)
            files.append({"name": name, "size": sizes[k], "roughness": rough[k], "method": "spectral"})
        return {"format": FORMAT, "format_version": FORMAT_VERSION, "kind": "sheen", "layout": layout,
                "files": files, "input": info.to_json(), "parameters": policies,
                "timings": {"bake_s": round(time.perf_counter() - t0, 4)}}

    return cache.get_or_build(root, key, build, warn=warn)


def bake_sheen_dfg(baker: Baker, root: Path, size: int, samples: int, warn=None):
    """The sheen albedo table E(NoV, r) = int D_charlie V_ashikhmin NoL dl on the DFG's grid."""
    params = {"size": size, "samples": samples}
    key = "dfg-sheen-" + cache.content_key({"format": FORMAT, "v": FORMAT_VERSION, "kind": "dfg-sheen", **params,
                                            "kernel": source_hash("mips.cl")})

    def build(tmp: Path):
        t0 = time.perf_counter()
        table = baker.dfg_sheen(size, samples)
        _check_finite("dfg-sheen", table)
        images.write_exr(tmp / "dfg_sheen.exr", table[..., None], channels=("Y",),
                         compression=images.CACHE_COMPRESSION)
        return {"format": FORMAT, "format_version": FORMAT_VERSION, "kind": "dfg-sheen",
                "files": [{"name": "dfg_sheen.exr", "width": size, "height": size}], "parameters": params,
                "axes": "x: NoV = i/(size-1) (clamped to >= 1e-4), y: sheen roughness r = j/(size-1)",
                "use": "sheen = sheenColor * sheen_chain(R, r) * E(NoV, r); albedo scaling 1 - max(sheenColor) E",
                "device": baker.device_label, "timings": {"bake_s": time.perf_counter() - t0}}

    return cache.get_or_build(root, key, build, warn=warn)


def verification_texels(source, layout: str, sizes, roughness, texels: int, seed: int = 0) -> list:
    """(texel indices, float64 brute-force values) per level: `texels` texels of each level drawn
    with one seeded generator, their ground truth by prefilter.prefilter_bruteforce (every source
    texel, split finer than the lobe, exact solid angles). What `mips --verify` and
    benchmarks/bench_mips.py compare the bakes with."""
    from iblbake.bake import prefilter

    rng = np.random.default_rng(seed)
    src = np.asarray(source, np.float64)
    out = []
    for s, r in zip(sizes, roughness):
        dirs = layouts.layout_dirs(layout, s).reshape(-1, 3)
        idx = rng.choice(len(dirs), size=min(len(dirs), texels), replace=False)
        out.append((idx, prefilter.prefilter_bruteforce(src, dirs[idx], r, max_sub=4)))
    return out


def level_errors(levels, picks) -> list:
    """Relative RMSE of each level at its verification texels."""
    from iblbake.core.metrics import relative_rmse
    return [relative_rmse(np.asarray(lvl)[..., :3].reshape(-1, 3)[idx], ref) for lvl, (idx, ref) in zip(levels, picks)]


def verify_prefiltered(root: Path, manifest: dict, source, texels: int, seed: int = 0) -> dict:
    """Measure a prefiltered entry's levels against the brute force and store the figures in its
    manifest (atomically; the files and their hashes are untouched)."""
    from iblbake.io.atomic import write_json

    files = manifest["files"]
    entry = Path(root) / manifest["key"]
    levels = [images.read_exr(entry / f["name"]) for f in files]
    t0 = time.perf_counter()
    picks = verification_texels(source, manifest["layout"], [f["size"] for f in files],
                                [f["roughness"] for f in files], texels, seed)
    errs = level_errors(levels, picks)
    block = {"texels_per_level": texels, "seed": seed, "relative_rmse": [float(e) for e in errs],
             "against": "float64 brute force: every source texel, split finer than the lobe, exact solid angles",
             "seconds": round(time.perf_counter() - t0, 3)}
    write_json(entry / cache.MANIFEST, {**manifest, "verify": block})
    return block
