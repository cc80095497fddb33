"""Kernel programs: kernels/ sources with their includes inlined (the text hashed and built), each
kernel's parameters read from its signature (arguments bound by name), the build options a device
needs, the on-disk program cache, and a build that keeps the compiler's chatter off stderr."""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import re
import sys
import warnings
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from iblbake.device.icd import is_intel_cpu

if TYPE_CHECKING:
    from iblbake.device.choice import DeviceInfo

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
    return cpu + (["-DIBL_ALWAYS_INLINE=1", "-DIBL_SCALAR_BVH=1"] if is_intel_cpu(info) else [])
