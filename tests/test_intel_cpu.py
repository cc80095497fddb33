"""Intel's OpenCL CPU runtime (the optional extra iblbake[intel-cpu]) as a device next to PoCL:
- iblbake registers its ICD itself (iblbake/device/icd.py): a vendors folder holding the system's
  ICD files and one naming the wheel's libintelocl.so; a user's OCL_ICD_VENDORS and the opt-out win;
- `--device intel-cpu` / `pocl` name the runtimes, and PoCL stays the default CPU device;
- the float3 miscompile of Intel's vectoriser (an out-of-line call's float3 argument or return is
  passed wrongly from a vectorised kernel) and what keeps every kernel clear of it: every function
  of kernels/ is IBL_INLINE, always inlined on that runtime (kernels/inline.h).
Tests that need the runtime itself skip where the extra is not installed (`make intel-cpu`)."""

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from iblbake.device import icd
from iblbake.device import choice as cl
from iblbake.device import programs

from tests.helpers import run_cli

ROOT = Path(__file__).resolve().parents[1]


def _info(platform, name="dev", kind="CPU", index="0:0"):
    return cl.DeviceInfo(index, platform, name, kind)


# --- registration ----------------------------------------------------------------------------------

@pytest.fixture
def fake_wheel(tmp_path, monkeypatch):
    """A system vendors folder with PoCL's ICD file, an 'installed' libintelocl.so, and an
    environment with no ICD variables."""
    system = tmp_path / "etc-vendors"
    system.mkdir()
    (system / "pocl.icd").write_text("libpocl.so.2\n")
    (system / "notes.txt").write_text("not an ICD file\n")
    lib = tmp_path / "lib" / "libintelocl.so"
    lib.parent.mkdir()
    lib.write_bytes(b"\x7fELF")
    monkeypatch.setattr(icd, "SYSTEM_VENDORS", str(system))
    monkeypatch.setattr(icd, "intel_cpu_library", lambda: lib)
    saved = {v: os.environ.pop(v, None) for v in ("OCL_ICD_VENDORS", icd.OPT_OUT, icd.REGISTERED)}
    yield lib
    for var, value in saved.items():          # register() sets them in os.environ itself
        os.environ.pop(var, None)
        if value is not None:
            os.environ[var] = value


def test_register_writes_a_vendors_folder_with_the_system_drivers_and_intels(tmp_path, fake_wheel):
    note = icd.register(tmp_path / "cache")
    folder = Path(os.environ["OCL_ICD_VENDORS"])
    assert folder.parent == tmp_path / "cache" / "opencl-vendors" and os.environ[icd.REGISTERED] == str(folder)
    files = {p.name: p.read_text() for p in folder.iterdir()}
    # PoCL's file as it was; Intel's named last, so the system's platforms keep their indices
    assert files == {"pocl.icd": "libpocl.so.2\n", "zz-iblbake-intel-cpu.icd": f"{fake_wheel}\n"}
    assert sorted(files)[-1].startswith("zz-") and str(fake_wheel) in note
    # the same contents: the same folder, not rewritten (processes agree without a lock)
    os.environ.pop("OCL_ICD_VENDORS")
    mtime = folder.stat().st_mtime_ns
    icd.register(tmp_path / "cache")
    assert os.environ["OCL_ICD_VENDORS"] == str(folder) and folder.stat().st_mtime_ns == mtime
    # a child process inherits the folder and says so
    assert "parent process" in icd.register(tmp_path / "cache")


def test_register_leaves_a_users_choice_alone(tmp_path, fake_wheel, monkeypatch):
    monkeypatch.setenv("OCL_ICD_VENDORS", str(tmp_path / "mine"))
    assert icd.register(tmp_path / "cache") is None and os.environ["OCL_ICD_VENDORS"] == str(tmp_path / "mine")
    monkeypatch.delenv("OCL_ICD_VENDORS")
    monkeypatch.setenv(icd.OPT_OUT, "0")
    assert "not registered" in icd.register(tmp_path / "cache") and "OCL_ICD_VENDORS" not in os.environ


def test_register_without_the_extra_changes_nothing(tmp_path, fake_wheel, monkeypatch):
    monkeypatch.setattr(icd, "intel_cpu_library", lambda: None)
    assert icd.register(tmp_path / "cache") is None and "OCL_ICD_VENDORS" not in os.environ


def test_intel_library_is_found_through_the_wheels_record(tmp_path, monkeypatch):
    """The RECORD of a wheel installed with --prefix or into a venv names the library relative to
    site-packages (../../libintelocl.so); a missing file is not a library."""
    site = tmp_path / "prefix" / "lib" / "python3" / "site-packages"
    info = site / "intel_opencl_rt-2026.2.0.dist-info"
    info.mkdir(parents=True)
    (info / "RECORD").write_text("../../libintelocl.so.2026,sha256=x,1\n../../libintelocl.so,sha256=y,2\n")
    monkeypatch.setattr("sys.path", [str(tmp_path / "nowhere"), str(site)])
    assert icd.intel_cpu_library() is None
    (tmp_path / "prefix" / "lib" / "libintelocl.so").write_bytes(b"\x7fELF")
    assert icd.intel_cpu_library() == tmp_path / "prefix" / "lib" / "libintelocl.so"


# --- device specs ----------------------------------------------------------------------------------

def test_device_specs_name_the_runtimes_and_pocl_stays_the_default():
    pocl_on_intel = _info("Portable Computing Language", "pthread-haswell-Intel(R) Core(TM) i7", index="0:0")
    intel = _info(icd.INTEL_PLATFORM, "Intel(R) Core(TM) i7", index="1:0")
    intel_gpu = _info("Intel(R) OpenCL Graphics", "Intel(R) Arc", kind="GPU", index="2:0")
    devs = [intel, pocl_on_intel, intel_gpu]
    assert cl._candidates(devs, "intel-cpu") == [intel]            # not PoCL on an Intel CPU, not the GPU
    assert cl._candidates(devs, "pocl") == [pocl_on_intel]
    assert cl._candidates(devs, "cpu") == [pocl_on_intel, intel]     # PoCL first, whatever the order listed
    assert cl._candidates(devs, None) == [intel_gpu, pocl_on_intel, intel]
    assert cl._candidates(devs, "cpu:0") == [intel]                  # cpu:N stays enumeration order
    cpu = ["-DIBL_WIDE_BVH=1", "-DIBL_PREFETCH=1"]                    # every CPU
    assert programs.device_options(intel) == cpu + ["-DIBL_ALWAYS_INLINE=1", "-DIBL_SCALAR_BVH=1"]
    assert programs.device_options(pocl_on_intel) == cpu
    assert programs.device_options(intel_gpu) == []


def test_a_device_spec_with_no_devices_at_all_says_what_to_install(tmp_path):
    """--device/IBLBAKE_DEVICE with no OpenCL platform at all: the 'install a driver' message (what
    `make test-intel` gives the empty-ICD tests), not 'no device matches' over an empty list."""
    vendors = tmp_path / "vendors"
    vendors.mkdir()
    p = run_cli("devices", env={"OCL_ICD_VENDORS": str(vendors), "IBLBAKE_DEVICE": "intel-cpu"})
    assert p.returncode != 0 and "pocl-opencl-icd" in p.stderr


# --- the runtime itself ----------------------------------------------------------------------------

def _intel_device():
    devices, _ = cl.enumerate_devices()
    return next((d for d in devices if icd.is_intel_cpu(d)), None)


needs_intel = pytest.mark.skipif(icd.intel_cpu_library() is None,
                                 reason="Intel's CPU runtime is not installed (make intel-cpu)")


@needs_intel
def test_devices_lists_intels_runtime_beside_the_default():
    p = run_cli("devices", "--json", env={"IBLBAKE_DEVICE": ""})
    doc = json.loads(p.stdout)
    intel = [d for d in doc["devices"] if d["platform"] == icd.INTEL_PLATFORM]
    assert p.returncode == 0 and len(intel) == 1 and intel[0]["works"] and intel[0]["type"] == "CPU", doc
    assert "registered" in doc["drivers_registered"]
    if any(d["platform"] == "Portable Computing Language" and d["works"] for d in doc["devices"]):
        assert "Portable Computing Language" in doc["selected"]     # the default stays PoCL
    p = run_cli("devices", "--json", env={"IBLBAKE_DEVICE": "intel-cpu"})
    assert icd.INTEL_PLATFORM in json.loads(p.stdout)["selected"]


FLOAT3_CALL = """
ATTR float4 f(float3 n) { return (float4)(n, 0.0f); }
__kernel void k(__global const float4 *n, __global float4 *out)
{ const int i = get_global_id(0); out[i] = f(n[i].xyz); }
"""


def _float3_call(dev, attr, options=()):
    """Work items of FLOAT3_CALL (a vectorisable kernel calling f with a float3) whose f(n.xyz) is
    not n.xyz; f declared `attr`, after kernels/inline.h."""
    import warnings

    import pyopencl
    ctx = pyopencl.Context([dev.device])
    q = pyopencl.CommandQueue(ctx)
    n = np.arange(64 * 4, dtype=np.float32).reshape(64, 4)
    source = programs.kernel_source("inline.h") + FLOAT3_CALL
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pyopencl.CompilerWarning)
        prg = pyopencl.Program(ctx, source).build(options=[f"-DATTR={attr}", *options], cache_dir=False)
    mf = pyopencl.mem_flags
    src = pyopencl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=n)
    dst = pyopencl.Buffer(ctx, mf.WRITE_ONLY, size=n.nbytes)
    prg.k(q, (64,), None, src, dst)
    got = np.empty_like(n)
    pyopencl.enqueue_copy(q, got, dst)
    return int((got[:, :3] != n[:, :3]).any(axis=1).sum())


@needs_intel
def test_intels_vectoriser_passes_out_of_line_float3_wrongly_and_inline_h_avoids_it():
    """The minimal reproduction of what made the textured GLB's bounces differ on Intel's runtime
    (tests/test_paths.py test_textured_glb_through_paths): a kernel the runtime vectorises 16 wide,
    calling a function it keeps out of line with a float3 argument. Measured on intel-opencl-rt
    2026.2: 60 of 64 work items get other items' components (each 16's first is right); inlined,
    none. PoCL: none either way. kernels/inline.h's IBL_INLINE, with the runtime's own build options
    for that device, gives the inlined form."""
    dev = _intel_device()
    assert dev is not None and cl.probe(dev).ok
    out_of_line = _float3_call(dev, "__attribute__((noinline))")
    print(f"Intel's runtime, float3 through an out-of-line call: {out_of_line} of 64 work items wrong")
    assert _float3_call(dev, "IBL_INLINE", programs.device_options(dev)) == 0
    if out_of_line == 0:
        pytest.skip("this Intel runtime passes out-of-line float3 arguments correctly: kernels/inline.h's "
                    "always_inline may no longer be needed there")


def test_every_kernel_function_is_ibl_inline():
    """No function of kernels/ is declared plain `inline`: each is IBL_INLINE (kernels/inline.h),
    which the runtime makes always_inline on Intel's CPU runtime, and each file that declares one
    reaches inline.h through its includes."""
    from iblbake.device.programs import kernel_source
    plain, unreached = [], []
    for path in sorted((ROOT / "kernels").rglob("*.[ch]*")):
        name, text = path.relative_to(ROOT / "kernels").as_posix(), path.read_text()
        plain += [f"{name}: {ln.strip()}" for ln in text.splitlines() if re.match(r"\s*(static\s+)?inline\b", ln)]
        if "IBL_INLINE " in text and name != "inline.h" and "#define IBL_INLINE" not in kernel_source(name):
            unreached.append(name)
    assert not plain and not unreached, (plain[:5], unreached)


@needs_intel
def test_intels_runtime_hands_python_its_signal_handlers_back():
    """Intel's runtime installs LLVM's crash handlers for 15 signals at its first context: SIGXFSZ
    (a write past the file-size limit, which Python ignores so the write fails with EFBIG and a
    one-line error) printed "PLEASE submit a bug report" first (test_nothing_lost.py
    test_file_size_limit_fails_cleanly on that runtime). The runtime hands Python's handlers back."""
    import subprocess
    import sys
    code = ("import os, signal; from iblbake.device.runtime import Runtime; rt = Runtime('intel-cpu'); "
            "os.kill(os.getpid(), signal.SIGXFSZ); print('alive')")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and p.stdout.strip() == "alive" and "PLEASE" not in p.stderr, (p.stdout, p.stderr)
