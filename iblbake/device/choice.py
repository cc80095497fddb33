"""Device choice: find an OpenCL device that really works.

A device counts only after it has built and run a tiny probe kernel (a broken ICD such as
PyPI's pocl-binary-distribution 3.0, "unknown target CPU 'generic'", lists devices that fail
at the first build). GPUs are preferred over CPUs. pyopencl is imported here only, so commands
that need no device never pay for it.
"""

from __future__ import annotations

import functools
import os
import re
import time
from dataclasses import dataclass, field

import numpy as np

from iblbake.device.icd import is_intel_cpu
from iblbake.device.programs import _cache_dir, _quiet_build_log
from iblbake.errors import DeviceError, IblbakeError

FIX_HINT = (
    "fix: on Debian/Ubuntu run `sudo apt-get install pocl-opencl-icd` (PoCL 3.1, a CPU device "
    "that works on these CPUs), or install your GPU vendor's OpenCL driver; do not use PyPI's "
    "pocl-binary-distribution 3.0, which fails on recent CPUs with \"unknown target CPU 'generic'\""
)

PROBE_SOURCE = """
__kernel void probe(__global float *x) { int i = get_global_id(0); x[i] = x[i] * 2.0f + (float)i; }
"""

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


def _context(cl, info: DeviceInfo):
    """An OpenCL context of one device. Intel's CPU runtime installs LLVM's crash handlers for 15
    signals when its first context is made, over Python's own: SIGXFSZ, which Python ignores so
    that a write past the file-size limit fails with EFBIG (a one-line error), then printed
    "PLEASE submit a bug report to ..." first. Every signal Python handles or ignores is handed
    back its handler; those left at their default keep LLVM's (a real crash's report)."""
    ctx = cl.Context([info.device])
    if is_intel_cpu(info):
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

def _matches(info: DeviceInfo, spec: str) -> bool:
    s = spec.strip().lower()
    if s in ("gpu", "cpu"):
        return info.kind.lower() == s
    if s == "intel-cpu":                     # Intel's CPU runtime (the intel-cpu extra), not PoCL on an Intel CPU
        return is_intel_cpu(info)
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
    if is_intel_cpu(info):
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
