"""OpenCL runtime: one device (device/choice.py) with its context and queue, kernels/ built with
defines (device/programs.py) and cached, buffers, and launches that bind arguments by name."""

from __future__ import annotations

import hashlib
import time

import numpy as np

from iblbake.device import programs
from iblbake.device.choice import _context, _import_cl, _matches, _one_line, select_device
from iblbake.device.launch import SPLIT_KERNELS, build_options, cpu_group
from iblbake.device.programs import _cache_dir, _quiet_build_log, kernel_params, kernel_source
from iblbake.errors import DeviceError


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
        self.device_options = programs.device_options(self.info)
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
        options = ["-cl-std=CL1.2", programs.DENORMS, *self.device_options, *build_options(self.info, name)] + \
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
