"""Every kernel program of the test run built with its uninitialised locals poisoned (`make
check-locals`; tests/conftest.py loads this where IBLBAKE_POISON_LOCALS=1).

A kernel function that leaves an out-parameter or a local unwritten on one path reads whatever its
stack or registers held: zero most of the time, so the kernel-vs-twin tests pass, and a NaN when
the bits happen to be one (kernels/probes.h probe_contribution did, for an inactive probe: a NaN
pixel in one first frame of about 60 under other PoCL work-group sizes). Here clang-15 (the
compiler Debian's PoCL is built on, so present wherever PoCL is) compiles each program to SPIR
with -ftrivial-auto-var-init=pattern: every automatic variable starts as 0xFF bytes, a NaN as a
float and -1 as an int, and PoCL (cl_khr_spir) loads the bitcode. A read of an unwritten value
then turns a test's result into NaN (or an index of -1) every time instead of now and then.
clang's static analyzer finds such reads of scalars but not of vector types such as float3
(measured on probe_contribution's old code: no warning), and PoCL rejects the option in a build
from source, hence the bitcode. Programs built in subprocesses (the command-line tests) are
built as usual."""

from __future__ import annotations

import hashlib
import os
import subprocess

import pytest

from iblbake.device import programs, runtime

CLANG = "/usr/bin/clang-15"


class _PoisonedSource:
    """What `cl.Program(ctx, source)` returns in runtime.Runtime.program, built through clang."""

    def __init__(self, cl, ctx, source: str):
        self.cl, self.ctx, self.source = cl, ctx, source

    def build(self, options=(), cache_dir=None):
        # the subnormal flush is a load option (PoCL sets the threads' FTZ and DAZ from it);
        # clang -cc1 spells it otherwise and the bitcode does not need it
        opts = [o for o in options if o.startswith(("-D", "-cl-")) and o != programs.DENORMS]
        folder = os.path.join(programs._cache_dir(), "poisoned-spir")
        os.makedirs(folder, exist_ok=True)
        h = hashlib.sha256((self.source + "\0" + " ".join(opts)).encode()).hexdigest()[:24]
        bc = os.path.join(folder, h + ".bc")
        if not os.path.exists(bc):
            # names of this process's own: `make check-locals` runs on several xdist workers, and one
            # worker's unlink of a shared NAME.cl left another's clang without its source
            own = f"{bc}.{os.getpid()}"
            src = own + ".cl"
            with open(src, "w", encoding="utf-8") as f:
                f.write(self.source)
            # -fgnu89-inline: kernels/inline.h's plain `inline` emits each function's body, as
            # PoCL's own front end does
            r = subprocess.run([CLANG, "-cc1", "-triple", "spir64-unknown-unknown", "-emit-llvm-bc",
                                "-finclude-default-header", "-ftrivial-auto-var-init=pattern", "-O2",
                                "-fgnu89-inline", *opts, src, "-o", own + ".part"], capture_output=True, text=True)
            os.unlink(src)
            if r.returncode:
                raise RuntimeError(f"clang-15 could not build the poisoned program: {r.stderr[-2000:]}")
            os.replace(own + ".part", bc)           # atomic: a reader sees the whole bitcode or none
        with open(bc, "rb") as f:
            binary = f.read()
        return self.cl.Program(self.ctx, list(self.ctx.devices), [binary] * len(self.ctx.devices)).build(
            options=" ".join(["-x spir -spir-std=1.2", *(o for o in options if o == programs.DENORMS)]))


class _PoisonedCL:
    """pyopencl, its Program(ctx, source) built poisoned; everything else as it is."""

    def __init__(self, cl):
        self._cl = cl

    def __getattr__(self, name):
        return getattr(self._cl, name)

    def Program(self, ctx, source, *binaries):  # noqa: N802 (pyopencl's name)
        if binaries:                                        # (ctx, devices, binaries): as it is
            return self._cl.Program(ctx, source, *binaries)
        return _PoisonedSource(self._cl, ctx, source)


def install():
    if not os.path.exists(CLANG):
        pytest.exit(f"IBLBAKE_POISON_LOCALS: {CLANG} is missing: install Debian's clang-15 (PoCL's own compiler)",
                    returncode=2)
    init = runtime.Runtime.__init__

    def poisoned_init(self, *args, **kwargs):
        init(self, *args, **kwargs)
        if "cl_khr_spir" not in self.ctx.devices[0].extensions:
            pytest.exit(f"IBLBAKE_POISON_LOCALS: {self.device_label} loads no SPIR (cl_khr_spir): run it on PoCL",
                        returncode=2)
        self.cl = _PoisonedCL(self.cl)

    runtime.Runtime.__init__ = poisoned_init
