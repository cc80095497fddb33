"""OpenCL runtime: find a device that really works, build kernels/ with defines, cache programs.

A device counts only after it has built and run a tiny probe kernel (a broken ICD such as
PyPI's pocl-binary-distribution 3.0, "unknown target CPU 'generic'", lists devices that fail
at the first build). GPUs are preferred over CPUs. pyopencl is imported here only, so commands
that need no device never pay for it.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import re
import sys
import time
import warnings
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from iblbake.device.launch import SPLIT_KERNELS, build_options, cpu_group
from iblbake.errors import DeviceError, IblbakeError

FIX_HINT = (
    "fix: on Debian/Ubuntu run `sudo apt-get install pocl-opencl-icd` (PoCL 3.1, a CPU device "
    "that works on these CPUs), or install your GPU vendor's OpenCL driver; do not use PyPI's "
    "pocl-binary-distribution 3.0, which fails on recent CPUs with \"unknown target CPU 'generic'\""
)

PROBE_SOURCE = """
__kernel void probe(__global float *x) { int i = get_global_id(0); x[i] = x[i] * 2.0f + (float)i; }
"""

_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$', re.M)


@functools.lru_cache(maxsize=None)
def kernel_folder():
    """Where kernels/ is: inside the installed package (iblbake.kernels, wheel or editable), else
    the source checkout's top-level kernels/ (running with PYTHONPATH=. and no install)."""
    try:
        return resources.files("iblbake.kernels")
    except ModuleNotFoundError:
        return Path(__file__).resolve().parents[2] / "kernels"


def kernel_source(name, _seen=None) -> str:
    """Source of kernels/NAME with its `#include "x.h"` lines inlined (once each), so that the
    text we hash and build is exactly what the compiler sees. NAME may be a tuple of files: one
    program of them all (each header still once), which loads as one binary instead of several."""
    seen = set() if _seen is None else _seen
    if isinstance(name, tuple):
        return "\n".join(f"// ==== {n}\n" + kernel_source(n, seen) for n in name)
    text = kernel_folder().joinpath(name).read_text(encoding="utf-8")

    def inline(m):
        inc = m.group(1)
        if inc in seen:
            return ""
        seen.add(inc)
        return f"// ---- {inc}\n" + kernel_source(inc, seen) + f"\n// ---- end {inc}\n"

    return _INCLUDE.sub(inline, text)


_DEFINE = re.compile(r"^\s*#\s*define\s+(\w+)[ \t]+((?:[^\n\\]|\\\n)*)$", re.M)
_SCALARS = {"int": np.int32, "uint": np.uint32, "float": np.float32}


@functools.lru_cache(maxsize=None)
def _signature(name, function: str) -> tuple:
    """The parameter declarations of `function` in kernels/NAME as word lists, object-like macros
    such as SCENE_PARAMS expanded."""
    src = kernel_source(name)
    macros = {m.group(1): m.group(2).replace("\\\n", " ") for m in _DEFINE.finditer(src)}
    m = re.search(rf"__kernel\s+void\s+{function}\s*\(([^)]*)\)", src)
    if m is None:
        raise KeyError(f"kernels/{name}: no kernel {function}")
    sig = m.group(1)
    for _ in range(4):                       # macros inside macros
        sig = re.sub(r"\b([A-Z_][A-Z0-9_]*)\b", lambda x: macros.get(x.group(1), x.group(1)), sig)
    return tuple(tuple(decl.replace("*", " * ").split()) for decl in sig.split(","))


@functools.lru_cache(maxsize=None)
def kernel_params(name, function: str) -> tuple:
    """((parameter name, converter), ...) of `function` in kernels/NAME, read from its signature,
    so the host binds arguments by name: a buffer as it is, a scalar cast to its OpenCL type, a
    float2/float4 to a float32 vector."""
    params = []
    for words in _signature(name, function):
        pname, kind = words[-1], [w for w in words[:-1] if w not in ("const", "__global", "__constant", "__local")]
        if "*" in kind:
            conv = None
        elif kind[0] in _SCALARS:
            conv = _SCALARS[kind[0]]
        else:                                # float2, float4: a float32 vector
            conv = functools.partial(np.asarray, dtype=np.float32)
        params.append((pname, conv))
    return tuple(params)


@functools.lru_cache(maxsize=None)
def kernel_buffers(name, function: str) -> dict:
    """{parameter name: written} of the pointer parameters of `function` in kernels/NAME: a
    `const` or `__constant` pointer is read, any other written (and maybe read)."""
    return {w[-1]: not ("const" in w or "__constant" in w) for w in _signature(name, function) if "*" in w}


@functools.lru_cache(maxsize=None)
def source_hash(name) -> str:
    return hashlib.sha256(kernel_source(name).encode()).hexdigest()[:16]


@dataclass
class DeviceInfo:
    index: str           # "platform:device"
    platform: str
    name: str
    kind: str            # "GPU" | "CPU" | "other"
    ok: bool = False
    reason: str = ""
    probe_s: float = 0.0
    device: object = field(default=None, repr=False)

    @property
    def label(self) -> str:
        return f"{self.name} ({self.platform}, {self.kind}, {self.index})"


def _kind(cl, dev) -> str:
    if dev.type & cl.device_type.GPU:
        return "GPU"
    if dev.type & cl.device_type.CPU:
        return "CPU"
    return "other"


@functools.lru_cache(maxsize=None)
def register_drivers():
    """Drivers that come as wheels (the intel-cpu extra: iblbake/device/icd.py) made known to the
    ICD loader, once per process, before pyopencl loads it."""
    from iblbake.device import icd
    return icd.register()


def _import_cl():
    register_drivers()
    try:
        import pyopencl as cl
    except Exception as e:  # a missing or broken libOpenCL surfaces here
        raise DeviceError(f"cannot import pyopencl ({e}); {FIX_HINT}") from None
    return cl


def enumerate_devices() -> tuple[list[DeviceInfo], list[str]]:
    """Every (platform, device) pair, unprobed, and the platform-level errors met."""
    cl = _import_cl()
    errors = []
    try:
        platforms = cl.get_platforms()
    except Exception as e:
        return [], [f"no OpenCL platform ({_one_line(e)})"]
    out = []
    for pi, p in enumerate(platforms):
        try:
            devs = p.get_devices()
        except Exception as e:
            errors.append(f"platform {p.name!r}: cannot list devices ({_one_line(e)})")
            continue
        for di, d in enumerate(devs):
            out.append(DeviceInfo(f"{pi}:{di}", p.name.strip(), d.name.strip(), _kind(cl, d), device=d))
    return out, errors


@contextlib.contextmanager
def _quiet_build_log(cl):
    """Successful builds can log (NVIDIA notes every inlined kernel) and pyopencl turns that log
    into a multi-line CompilerWarning on stderr; failures raise and are reported, the rest is noise.
    PoCL's clang also writes its count ("13 warnings generated.": sh_project.cl's float16 ABI
    notes, about its own builtins) straight to file descriptor 2, past Python, on every cold
    build (-q, --json and the API's "prints nothing"): those lines are dropped, anything else
    written there meanwhile is passed on."""
    import tempfile

    with warnings.catch_warnings(), tempfile.TemporaryFile() as tmp:
        warnings.simplefilter("ignore", cl.CompilerWarning)
        try:
            sys.stderr.flush()
            saved = os.dup(2)
        except (OSError, ValueError):          # no descriptor 2 (a service, an embedding)
            yield
            return
        os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            text = tmp.read().decode(errors="replace")
            rest = "".join(ln for ln in text.splitlines(True) if not re.fullmatch(r"\d+ warnings? generated\.\s*", ln))
            if rest:
                sys.stderr.write(rest)


def _context(cl, info: DeviceInfo):
    """An OpenCL context of one device. Intel's CPU runtime installs LLVM's crash handlers for 15
    signals when its first context is made, over Python's own: SIGXFSZ, which Python ignores so
    that a write past the file-size limit fails with EFBIG (a one-line error), then printed
    "PLEASE submit a bug report to ..." first. Every signal Python handles or ignores is handed
    back its handler; those left at their default keep LLVM's (a real crash's report)."""
    ctx = cl.Context([info.device])
    if _is_intel_cpu(info):
        import signal
        for sig in (signal.SIGHUP, signal.SIGINT, signal.SIGTERM, signal.SIGUSR1, signal.SIGUSR2,
                    signal.SIGXFSZ, signal.SIGXCPU, signal.SIGQUIT):
            try:
                h = signal.getsignal(sig)
                if h not in (signal.SIG_DFL, None):
                    signal.signal(sig, h)
            except (ValueError, OSError):     # not the main thread: its handlers are the main thread's
                pass
    return ctx


def probe(info: DeviceInfo) -> DeviceInfo:
    """Build and run the probe kernel; fill info.ok / info.reason."""
    cl = _import_cl()
    t0 = time.perf_counter()
    try:
        ctx = _context(cl, info)
        queue = cl.CommandQueue(ctx)
        with _quiet_build_log(cl):
            prg = cl.Program(ctx, PROBE_SOURCE).build()
        x = np.arange(64, dtype=np.float32)
        buf = cl.Buffer(ctx, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=x)
        prg.probe(queue, (64,), None, buf)
        y = np.empty_like(x)
        cl.enqueue_copy(queue, y, buf)
        queue.finish()
        expect = x * 2 + np.arange(64, dtype=np.float32)
        if not np.array_equal(y, expect):
            raise RuntimeError("probe kernel returned wrong values")
        info.ok, info.reason = True, "probe kernel built and ran"
    except Exception as e:
        info.ok, info.reason = False, _one_line(e)
    info.probe_s = time.perf_counter() - t0
    return info


def _one_line(e: Exception) -> str:
    text = " ".join(str(e).split())
    m = re.search(r"unknown target CPU '[^']*'", text)
    if m:
        return f"kernel build fails: {m.group(0)} (a PoCL built for another CPU)"
    return (text[:240] + "...") if len(text) > 240 else (text or type(e).__name__)


def _is_intel_cpu(info: DeviceInfo) -> bool:
    from iblbake.device.icd import INTEL_PLATFORM
    return info.kind == "CPU" and info.platform == INTEL_PLATFORM


def _matches(info: DeviceInfo, spec: str) -> bool:
    s = spec.strip().lower()
    if s in ("gpu", "cpu"):
        return info.kind.lower() == s
    if s == "intel-cpu":                     # Intel's CPU runtime (the intel-cpu extra), not PoCL on an Intel CPU
        return _is_intel_cpu(info)
    if s == "pocl":
        return info.platform == "Portable Computing Language"
    if re.fullmatch(r"\d+:\d+", s):
        return info.index == s
    if re.fullmatch(r"\d+", s):
        return info.index.split(":")[0] == s
    return s in info.name.lower() or s in info.platform.lower()


def _preference(info: DeviceInfo) -> int:
    """GPUs, then CPUs, Intel's CPU runtime after other CPU drivers (PoCL stays the default CPU
    device where both are installed: it is faster on the BVH-heavy scenes, docs/benchmarks.md)."""
    if _is_intel_cpu(info):
        return 2
    return {"GPU": 0, "CPU": 1}.get(info.kind, 3)


def _verdict_path() -> str:
    return os.path.join(os.path.dirname(_cache_dir()), "probe-verdicts.json")


def _verdict_key(info: DeviceInfo) -> str:
    """What a verdict holds for: the platform, the device and its driver (a new driver probes again)."""
    d = info.device
    return "|".join(str(x).strip() for x in (d.platform.name, d.platform.version, d.name, d.version,
                                             d.driver_version))


def _load_verdicts() -> dict:
    import json
    try:
        from iblbake.io import reads
        v = json.loads(reads.read_text(_verdict_path(), reads.JSON_BYTES, "the device verdicts"))
        return v if isinstance(v, dict) else {}
    except (OSError, ValueError, IblbakeError):     # missing or unreadable: probe again
        return {}


def _save_verdicts(verdicts: dict) -> None:
    from iblbake.io.atomic import write_json
    try:
        write_json(_verdict_path(), verdicts)
    except Exception:          # a read-only home costs a probe per run, nothing else
        pass


def _candidates(devices: list[DeviceInfo], spec: str | None) -> list[DeviceInfo]:
    """The devices `spec` names, in the order they are tried (_preference, then enumeration)."""
    nth = re.fullmatch(r"(gpu|cpu):(\d+)", spec.strip().lower()) if spec else None
    if nth:                          # the N-th device of a kind, in enumeration order (--devices gpu:0,gpu:1)
        same = [d for d in devices if d.kind.lower() == nth[1]]
        return same[int(nth[2]):int(nth[2]) + 1]
    return sorted((d for d in devices if spec is None or _matches(d, spec)), key=_preference)


def select_device(spec: str | None = None, name: str = "--device") -> DeviceInfo:
    """The device to use: `spec` (--device), else $IBLBAKE_DEVICE, else the first working GPU,
    else the first working CPU. Probes candidates in that order and stops at the first that works;
    a device whose driver passed the probe before (verdicts kept per platform, device and driver
    version beside the kernel cache) is not probed again. `iblbake devices` always probes. `name`
    is what a message calls the spec's setting (a flag, an argument)."""
    spec = spec or os.environ.get("IBLBAKE_DEVICE") or None
    devices, errors = enumerate_devices()
    candidates = _candidates(devices, spec)
    if spec and not candidates and devices:
        listed = ", ".join(d.label for d in devices) or "none"
        raise DeviceError(f"no OpenCL device matches {name}/IBLBAKE_DEVICE {spec!r}; devices: {listed}")
    tried = []
    verdicts = _load_verdicts()
    for info in candidates:
        key = _verdict_key(info)
        known = verdicts.get(key)
        if known and known.get("ok"):     # this device and driver built and ran the probe before
            info.ok, info.reason = True, "probe verdict of an earlier run (same device and driver)"
            return info
        probe(info)
        verdicts[key] = {"ok": info.ok, "reason": info.reason}
        _save_verdicts(verdicts)
        if info.ok:
            return info
        tried.append(f"{info.label}: {info.reason}")
    detail = "; ".join(errors + tried) or "no OpenCL device found"
    raise DeviceError(f"no working OpenCL device (tried: {detail}); {FIX_HINT}")


def probe_all() -> tuple[list[DeviceInfo], list[str], DeviceInfo | None]:
    """Every device probed, platform errors, and the one select_device() would use."""
    devices, errors = enumerate_devices()
    verdicts = _load_verdicts()
    for d in devices:
        probe(d)
        verdicts[_verdict_key(d)] = {"ok": d.ok, "reason": d.reason}
    _save_verdicts(verdicts)
    working = [d for d in _candidates(devices, os.environ.get("IBLBAKE_DEVICE") or None) if d.ok]
    return devices, errors, (working[0] if working else None)


def _cache_dir() -> str:
    path = os.environ.get("IBLBAKE_KERNEL_CACHE")
    if not path:
        import platformdirs
        path = os.path.join(platformdirs.user_cache_dir("iblbake"), "kernels")
    os.makedirs(path, exist_ok=True)
    return path


# Subnormal floats flushed to zero, in and out (FTZ and DAZ on a CPU, .ftz on a GPU). The packed
# records keep integers in the w lane of float4s (a plane's and a triangle's material and object;
# kernels/layout.h) whose bit patterns are subnormal floats, and a compiler does a float3's
# arithmetic on all four lanes: on CPUs that handle a subnormal operand by a microcode assist (100+
# cycles) every ray-plane test (and ray-box test, when the BVH's nodes had them too) paid one, and
# the reference ran 1.2-3.7x slower (docs/benchmarks.md "Subnormal floats"). Embree asks its users
# for FTZ and DAZ for the same reason. tests/test_conventions.py checks that a kernel flushes.
DENORMS = "-cl-denorms-are-zero"

# The BVH a device's kernels traverse (kernels/scene.h, scene/bvh.py): the 4-wide tree on a CPU,
# where its float4 box and triangle tests run as SIMD (the knot's reference 1.2-1.35x faster),
# the binary tree on a GPU, where the wide one was 1.2-1.4x slower (an H100; docs/benchmarks.md
# "A 4-wide BVH"). device_scene.geometry_tables uploads the one named here.
WIDE_BVH = "-DIBL_WIDE_BVH=1"
# The panorama's texels prefetched ahead of their use, on a CPU (kernels/paths/paths.h env_prefetch)
PREFETCH = "-DIBL_PREFETCH=1"


def device_options(info: DeviceInfo) -> list[str]:
    """Build options one runtime needs. Every CPU: the 4-wide BVH (WIDE_BVH), and the panorama's
    texels prefetched ahead of their use (PREFETCH: a work item there has no other path to run
    while a load misses; a GPU hides the miss with other warps). Intel's CPU
    runtime: every function inlined (kernels/inline.h: it passes float3 arguments of out-of-line
    calls from vectorised kernels wrongly), and the reference kept scalar where it traces triangles
    (kernels/paths/reference.cl: divergent BVH lanes)."""
    cpu = [WIDE_BVH, PREFETCH] if info.kind == "CPU" else []
    return cpu + (["-DIBL_ALWAYS_INLINE=1", "-DIBL_SCALAR_BVH=1"] if _is_intel_cpu(info) else [])


class Runtime:
    """One device: its context, queue and built programs (cached per source, defines, device)."""

    def __init__(self, device: str | None = None, name: str = "--device"):
        self.cl = _import_cl()
        self.info = select_device(device, name)
        self.ctx = _context(self.cl, self.info)
        self.queue = self.cl.CommandQueue(self.ctx)
        self._programs: dict = {}
        self._kernels: dict = {}
        self._host_arrays: list = []   # zero-copy host arrays of queued work (see to_device)
        self.builds: list[dict] = []  # what was built, with times, for reports
        self.device_options = device_options(self.info)
        # PoCL's own choice runs a small launch on one core (device/launch.py cpu_group)
        self._split = self.info.kind == "CPU" and _matches(self.info, "pocl")
        self._cores = self.info.device.max_compute_units if self._split else 1

    @property
    def device_label(self) -> str:
        return self.info.label

    def program(self, name, defines: dict | None = None):
        """Build kernels/NAME with -D defines. In-process cache, plus pyopencl's on-disk binary
        cache keyed by (source, options, device), so a second run spends no time compiling."""
        defines = dict(sorted((defines or {}).items()))
        src = kernel_source(name)
        key = (hashlib.sha256(src.encode()).hexdigest(), tuple(defines.items()))
        if key in self._programs:
            return self._programs[key]
        options = ["-cl-std=CL1.2", DENORMS, *self.device_options, *build_options(self.info, name)] + \
            [f"-D{k}={v}" for k, v in defines.items()]
        t0 = time.perf_counter()
        try:
            with _quiet_build_log(self.cl):
                prg = self.cl.Program(self.ctx, src).build(options=options, cache_dir=_cache_dir())
        except Exception as e:
            log = str(e)
            first = next((ln.strip() for ln in log.splitlines() if "error:" in ln), None)
            shown = "+".join(name) if isinstance(name, tuple) else name
            raise DeviceError(f"kernels/{shown}: build failed on {self.device_label}: "
                              f"{first or _one_line(e)}") from None
        self.builds.append({"kernel": "+".join(name) if isinstance(name, tuple) else name, "defines": defines,
                            "seconds": time.perf_counter() - t0})
        self._programs[key] = prg
        return prg

    def kernel(self, name, function: str, defines: dict | None = None):
        """A kernel object of kernels/NAME, built once and reused (pyopencl warns that
        `prg.function` creates a new kernel object every time)."""
        key = (name, function, tuple(sorted((defines or {}).items())))
        k = self._kernels.get(key)
        if k is None:
            k = self._kernels[key] = self.cl.Kernel(self.program(name, defines), function)
        return k

    # -- buffers ---------------------------------------------------------------------
    def to_device(self, array, read_only: bool = True):
        """A device buffer holding `array`. On CPU devices a read-only array is used in place
        (USE_HOST_PTR: no copy). The runtime keeps the array alive: a buffer passed straight into
        an asynchronous enqueue is dropped by Python at once, OpenCL keeps the memory object for
        the queued kernel, but numpy would free the host memory under it (pyopencl's own
        `hostbuf` reference dies with the Python buffer object). They are forgotten after the next
        blocking read: on this in-order queue every kernel enqueued before it has then finished."""
        mf = self.cl.mem_flags
        array = np.ascontiguousarray(array)
        if read_only and self.info.kind == "CPU":
            buf = self.cl.Buffer(self.ctx, mf.READ_ONLY | mf.USE_HOST_PTR, hostbuf=array)
            self._host_arrays.append(array)
            return buf
        flags = (mf.READ_ONLY if read_only else mf.READ_WRITE) | mf.COPY_HOST_PTR
        return self.cl.Buffer(self.ctx, flags, hostbuf=array)

    def empty(self, nbytes: int):
        return self.cl.Buffer(self.ctx, self.cl.mem_flags.READ_WRITE, size=max(4, int(nbytes)))

    def read(self, buf, shape, dtype=np.float32):
        out = np.empty(shape, dtype=dtype)
        self.cl.enqueue_copy(self.queue, out, buf)   # blocking: all earlier work is done
        self._host_arrays.clear()
        return out

    def read_mapped(self, buf, shape, dtype=np.float32):
        """`buf` as a host array without a copy where the device shares host memory (PoCL's CPU
        device: no second buffer to fault in and fill); blocking. The array keeps the mapping,
        and with it the buffer, alive."""
        out, _ = self.cl.enqueue_map_buffer(self.queue, buf, self.cl.map_flags.READ | self.cl.map_flags.WRITE, 0,
                                            shape, dtype, is_blocking=True)
        self._host_arrays.clear()
        return out

    def launch(self, name, function: str, defines: dict | None, global_size, table: dict | None = None,
               local_size=None, **args):
        """Run `function` of kernels/NAME with every parameter bound by name: from `args`, else
        from `table` (the caller's named buffers and values). A name in neither is an error
        that names it, not a silently shifted argument list."""
        table = table or {}
        values = []
        for pname, conv in kernel_params(name, function):
            if pname in args:
                v = args[pname]
            elif pname in table:
                v = table[pname]
            else:
                raise KeyError(f"kernels/{name} {function}: no value bound to parameter {pname!r}")
            values.append(v if conv is None else conv(v))
        k = self.kernel(name, function, defines)
        return self.run(k, tuple(global_size), local_size, *values)

    def read_into(self, buf, out):
        """Blocking copy of `buf` into the contiguous array `out` (rows of a frame, say)."""
        self.cl.enqueue_copy(self.queue, out, buf)
        self._host_arrays.clear()
        return out

    def run(self, kernel, global_size, local_size, *args):
        if local_size is None and self._split and len(global_size) == 1 and kernel.function_name in SPLIT_KERNELS:
            local_size = (cpu_group(global_size[0], self._cores),)
        try:
            return kernel(self.queue, global_size, local_size, *args)
        except Exception as e:
            raise DeviceError(f"kernel {kernel.function_name} failed on {self.device_label}: {_one_line(e)}") from None

    def finish(self):
        self.queue.finish()
