"""OpenCL drivers that come as Python wheels, registered by iblbake itself (no root, no shell set-up).

Intel's OpenCL CPU runtime (`pip install 'iblbake[intel-cpu]'`: PyPI's intel-opencl-rt with
intel-cmplr-lib-rt and tbb) installs libintelocl.so under the environment's lib/, and an ICD file
(etc/OpenCL/vendors/intel-cpu.icd) naming a conda build's placeholder path that pip never rewrites,
so no ICD loader finds it. Before pyopencl loads, iblbake writes a vendors folder of its own (beside
the kernel cache, named by its contents) holding a copy of every ICD file of the system's folder
(/etc/OpenCL/vendors: PoCL, a GPU's driver) and one naming the wheel's libintelocl.so, and points
OCL_ICD_VENDORS at it. The loader pyopencl's wheels bundle (ocl-icd) reads OCL_ICD_VENDORS and
ignores OCL_ICD_FILENAMES (measured: a library named only there is not listed), and the Khronos
loader reads both, so OCL_ICD_VENDORS is the variable that works with either.

Nothing changes where the extra is not installed, where OCL_ICD_VENDORS is already set (the user's
choice of drivers stands; a child process inherits the folder written here), or where
IBLBAKE_INTEL_OPENCL=0. The device iblbake picks by default stays the same: among CPU devices PoCL
ranks before Intel's (choice._preference); `--device intel-cpu` (or IBLBAKE_DEVICE=intel-cpu)
picks Intel's.
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

SYSTEM_VENDORS = "/etc/OpenCL/vendors"
INTEL_DIST = "intel-opencl-rt"
INTEL_LIBRARY = "libintelocl.so"
INTEL_PLATFORM = "Intel(R) OpenCL"      # the platform name Intel's CPU runtime reports
OPT_OUT = "IBLBAKE_INTEL_OPENCL"
REGISTERED = "IBLBAKE_ICD_REGISTERED"     # the folder this process pointed OCL_ICD_VENDORS at (children inherit both)

# what register() did, for `iblbake devices`: None (not tried), or a one-line note
note: str | None = None


def is_intel_cpu(info) -> bool:
    """Whether device `info` (a choice.DeviceInfo) is Intel's CPU runtime, not PoCL on an Intel CPU."""
    return info.kind == "CPU" and info.platform == INTEL_PLATFORM


def intel_cpu_library() -> Path | None:
    """libintelocl.so of the installed intel-opencl-rt wheel, found through the wheel's own file
    list (its dist-info RECORD: a venv, --user or --prefix install puts it in a different lib/), or
    None. Read directly (about 0.3 ms) rather than through importlib.metadata, whose import alone
    costs about 20 ms of every command that uses a device."""
    prefix = INTEL_DIST.replace("-", "_") + "-"
    for entry in sys.path:
        try:
            names = [e.name for e in os.scandir(entry or ".") if e.name.startswith(prefix)
                     and e.name.endswith(".dist-info")]
        except OSError:
            continue
        for name in sorted(names):
            try:
                with open(os.path.join(entry or ".", name, "RECORD"), encoding="utf-8") as f:
                    rows = f.read(1 << 20).splitlines()
            except OSError:
                continue
            for row in rows:
                rel = row.split(",", 1)[0]
                if rel.rsplit("/", 1)[-1] == INTEL_LIBRARY:
                    p = Path(os.path.normpath(os.path.join(os.path.abspath(entry or "."), rel)))
                    if p.is_file():
                        return p
    return None


def _system_icds(folder: str | None = None) -> dict[str, str]:
    """{file name: contents} of the system's ICD files (the loader reads those ending in .icd)."""
    folder = folder or SYSTEM_VENDORS
    out = {}
    try:
        names = sorted(os.listdir(folder))
    except OSError:
        return out
    for name in names:
        if not name.endswith(".icd"):
            continue
        try:
            with open(os.path.join(folder, name), encoding="utf-8", errors="replace") as f:
                out[name] = f.read(4096)
        except OSError:
            continue
    return out


def vendors_folder(root: str | os.PathLike, icds: dict[str, str]) -> str:
    """A folder under `root` holding exactly `icds` ({name: contents}), named by its contents so
    that processes agree on it without a lock: written in a fresh folder and renamed into place
    (a concurrent writer's identical folder wins and this one is dropped)."""
    import shutil
    import tempfile

    digest = hashlib.sha256(repr(sorted(icds.items())).encode()).hexdigest()[:16]
    final = os.path.join(root, digest)
    if os.path.isdir(final):
        return final
    os.makedirs(root, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix=".new-", dir=root)
    try:
        for name, text in icds.items():
            with open(os.path.join(tmp, name), "w", encoding="utf-8") as f:
                f.write(text)
        os.chmod(tmp, 0o755)
        try:
            os.rename(tmp, final)
        except OSError:               # another process renamed its identical folder first
            if not os.path.isdir(final):
                raise
    finally:
        if os.path.isdir(tmp):
            shutil.rmtree(tmp, ignore_errors=True)
    return final


def register(cache_root: str | os.PathLike | None = None) -> str | None:
    """Point OCL_ICD_VENDORS at a folder listing the system's drivers and Intel's CPU runtime,
    where the intel-cpu extra is installed and nothing says otherwise. Call before pyopencl is
    imported (the loader reads the variable once, at its first call). Returns the note kept in
    `note`: what was registered, or why not (None where the extra is not installed)."""
    global note
    if os.environ.get(OPT_OUT, "").strip().lower() in ("0", "off", "no", "false"):
        note = f"Intel's CPU runtime not registered ({OPT_OUT}={os.environ[OPT_OUT]})"
        return note
    if os.environ.get("OCL_ICD_VENDORS"):
        folder = os.environ["OCL_ICD_VENDORS"]
        note = (f"Intel's CPU runtime registered by the parent process (OCL_ICD_VENDORS={folder})"
                if os.environ.get(REGISTERED) == folder else None)
        return note
    lib = intel_cpu_library()
    if lib is None:
        note = None
        return None
    icds = _system_icds()
    icds["zz-iblbake-intel-cpu.icd"] = f"{lib}\n"
    if cache_root is None:
        from iblbake.device.programs import _cache_dir
        cache_root = os.path.dirname(_cache_dir())
    try:
        folder = vendors_folder(os.path.join(cache_root, "opencl-vendors"), icds)
    except OSError as e:
        note = f"Intel's CPU runtime ({lib}) not registered: cannot write its ICD folder ({e})"
        return note
    os.environ["OCL_ICD_VENDORS"] = folder
    os.environ[REGISTERED] = folder
    note = f"Intel's CPU runtime registered from {lib} (OCL_ICD_VENDORS={folder})"
    return note
