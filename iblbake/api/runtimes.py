"""The OpenCL runtimes the API's calls run on: one per device spec for the process."""

from __future__ import annotations

import threading

from iblbake.api.guards import _device, _name

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


def _job(sc, rt, cache, warn, progress):
    """A bake's job on runtime `rt` (its store over `cache`), the panorama's read warnings said first,
    as a frame says them (the unit a bake loads does not read the panorama itself)."""
    from iblbake.render import Bakes
    from iblbake.render.units import Job
    bakes = Bakes(cache)
    bakes.runtime = rt
    job = Job(sc, rt, bakes, warn or (lambda _m: None), progress)
    for w in bakes.environment(sc.data["environment"])[1].warnings:
        job.warn(w)
    return job
