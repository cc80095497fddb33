"""`iblbake sh` end to end: outputs, JSON document, and one-line errors on bad input."""

import json
import math

import numpy as np
import pytest

from iblbake.core import sh

from tests.helpers import run_cli, write_exr


def assert_one_line_error(proc, *needles):
    assert proc.returncode != 0, proc.stdout
    err = proc.stderr.strip()
    assert "Traceback" not in proc.stderr
    lines = [l for l in err.splitlines() if not l.startswith("iblbake: warning")]
    assert len(lines) == 1, err
    for n in needles:
        assert n in lines[0], lines[0]


def test_sh_writes_document(tmp_path):
    img = np.full((32, 64, 3), 0.5, np.float32)
    img[..., 0] = 1.0
    env = write_exr(tmp_path / "const.exr", img)
    out = tmp_path / "sh.json"
    p = run_cli("sh", env, "-o", out, "--bands", "4", "--intensity", "2", "--json")
    assert p.returncode == 0, p.stderr
    doc = json.loads(out.read_text())
    assert doc["format"] == "iblbake.sh" and doc["format_version"] == 1 and doc["bands"] == 4
    assert doc["basis"]["polar_axis"] == "+z" and doc["basis"]["condon_shortley_phase"] is False
    assert len(doc["radiance"]) == 16 and len(doc["irradiance"]) == 16
    # intensity 2, constant radiance (1, .5, .5): L00 = 2 c sqrt(4 pi), E00 = pi L00
    assert np.allclose(doc["radiance"][0], np.array([2, 1, 1]) * math.sqrt(4 * math.pi), rtol=1e-6)
    assert np.allclose(doc["irradiance"][0], np.array(doc["radiance"][0]) * math.pi, rtol=1e-12)
    assert doc["input"]["width"] == 64 and len(doc["input"]["sha256"]) == 64
    summary = json.loads(p.stdout)
    assert summary["bands"] == 4 and summary["output"] == str(out)
    # no temp files left beside the output
    assert sorted(x.name for x in tmp_path.iterdir()) == ["const.exr", "sh.json"]


def test_sh_glsl_snippet_holds_the_coefficients(tmp_path):
    env = write_exr(tmp_path / "c.exr", np.full((8, 16, 3), 1.0, np.float32))
    p = run_cli("sh", env, "--glsl", "-q")
    assert p.returncode == 0, p.stderr
    assert "vec3 shIrradiance(vec3 d)" in p.stdout and "SH_IRRADIANCE[9]" in p.stdout
    first = float(p.stdout.split("vec3(")[1].split(",")[0])
    assert abs(first - math.pi * math.sqrt(4 * math.pi)) < 1e-5


def test_sh_backends_agree_through_cli(tmp_path):
    img = np.random.default_rng(0).random((64, 128, 3)).astype(np.float32) * 5
    env = write_exr(tmp_path / "r.exr", img)
    docs = []
    for backend in ("opencl", "numpy"):
        out = tmp_path / f"{backend}.json"
        p = run_cli("sh", env, "-o", out, "--bands", "8", "--backend", backend, "--window", "hann")
        assert p.returncode == 0, p.stderr
        docs.append(np.array(json.loads(out.read_text())["irradiance"]))
    assert np.abs(docs[0] - docs[1]).max() / np.abs(docs[1]).max() < 1e-5
    expect = sh.project(img, 8) * (sh.window(8, "hann") * sh.ahat(8))[:, None]
    assert np.abs(docs[1] - expect).max() / np.abs(expect).max() < 1e-6


def bad_inputs(tmp_path):
    good = np.ones((32, 64, 3), np.float32)
    cases = {}
    cases["missing"] = (str(tmp_path / "nope.exr"), ["nope.exr", "no such file"], [])
    text = tmp_path / "text.exr"
    text.write_text("this is not an image\n")
    cases["text"] = (str(text), ["text.exr", "cannot read"], [])
    full = write_exr(tmp_path / "full.exr", np.random.default_rng(0).random((128, 256, 3)))
    data = open(full, "rb").read()
    trunc = tmp_path / "trunc.exr"
    trunc.write_bytes(data[: len(data) // 2])
    cases["truncated"] = (str(trunc), ["trunc.exr"], [])
    nan = good.copy()
    nan[3, 5, 1] = np.nan
    nan[7, 9, 0] = np.inf
    cases["nan"] = (write_exr(tmp_path / "nan.exr", nan), ["nan.exr", "2 non-finite", "x=5, y=3", "--nonfinite"], [])
    cases["big"] = (write_exr(tmp_path / "big.exr", good), ["big.exr", "over the limit"], ["--max-pixels", "1000"])
    return cases


@pytest.mark.parametrize("case", ["missing", "text", "truncated", "nan", "big"])
def test_sh_bad_inputs_fail_with_one_line(tmp_path, case):
    path, needles, extra = bad_inputs(tmp_path)[case]
    out = tmp_path / "out.json"
    p = run_cli("sh", path, "-o", out, *extra)
    assert_one_line_error(p, *needles)
    assert not out.exists()
    assert not [x for x in tmp_path.iterdir() if x.name.startswith(".out")]


def test_nonfinite_repair_policies(tmp_path):
    img = np.ones((8, 16, 3), np.float32)
    img[1, 1] = np.nan
    img[2, 2] = np.inf
    env = write_exr(tmp_path / "n.exr", img)
    for policy in ("zero", "clamp"):
        out = tmp_path / f"{policy}.json"
        p = run_cli("sh", env, "-o", out, "--nonfinite", policy)
        assert p.returncode == 0, p.stderr
        assert "repaired 6 non-finite values" in p.stderr
        doc = json.loads(out.read_text())
        assert doc["input"]["nonfinite_texels"] == 6
        assert all(math.isfinite(v) for row in doc["radiance"] for v in row)


def test_tiny_and_odd_sizes_work(tmp_path):
    for w, h in ((1, 1), (2, 1), (3, 1), (4, 2), (7, 3)):
        env = write_exr(tmp_path / f"t{w}x{h}.exr", np.full((h, w, 3), 3.0, np.float32))
        out = tmp_path / f"t{w}x{h}.json"
        p = run_cli("sh", env, "-o", out)
        assert p.returncode == 0, p.stderr
        doc = json.loads(out.read_text())
        assert np.allclose(doc["radiance"][0], 3 * math.sqrt(4 * math.pi), rtol=1e-6)
        assert np.abs(np.array(doc["radiance"][1:])).max() < 1e-5
        if w != 2 * h:
            assert "not 2:1" in p.stderr


def test_internal_errors_are_one_line_unless_debug(tmp_path):
    # an output folder that cannot be made (a file is in the way) is a user error: one line, no traceback
    env = write_exr(tmp_path / "c.exr", np.ones((4, 8, 3), np.float32))
    p = run_cli("sh", env, "-o", tmp_path / "c.exr" / "such" / "dir.json")
    assert_one_line_error(p, "is not a folder")


def test_usage_errors(tmp_path):
    env = write_exr(tmp_path / "c.exr", np.ones((4, 8, 3), np.float32))
    p = run_cli("sh", env, "--bands", "0")
    assert p.returncode == 2 and "Traceback" not in p.stderr and "--bands" in p.stderr
    p = run_cli("sh", env, "--intensity", "nan")
    assert p.returncode == 2 and "not a finite number" in p.stderr


@pytest.mark.parametrize("icd", ["empty", "broken"])
def test_no_working_device_names_the_fix(tmp_path, icd):
    """With no usable OpenCL driver (an empty or broken ICD folder), commands that need a device
    fail with one line naming what was tried and what to install; --backend numpy still works."""
    vendors = tmp_path / "vendors"
    vendors.mkdir()
    if icd == "broken":
        (vendors / "bad.icd").write_text("libdoesnotexist.so\n")
    env = {"OCL_ICD_VENDORS": str(vendors)}
    pano = write_exr(tmp_path / "c.exr", np.ones((4, 8, 3), np.float32))
    p = run_cli("sh", pano, "-o", tmp_path / "x.json", "--backend", "opencl", env=env)
    assert_one_line_error(p, "no working OpenCL device", "tried:", "pocl-opencl-icd")
    assert p.returncode == 3 and not (tmp_path / "x.json").exists()
    p = run_cli("devices", env=env)
    assert p.returncode != 0 and "pocl-opencl-icd" in p.stderr and "Traceback" not in p.stderr
    p = run_cli("sh", pano, "--backend", "numpy", "--json", env=env)
    assert p.returncode == 0, p.stderr
    p = run_cli("sh", pano, "--json", env=env)      # auto: a small panorama needs no device at all
    assert p.returncode == 0 and json.loads(p.stdout)["device"].startswith("numpy"), p.stderr


def test_device_probe_prints_no_compiler_warning(monkeypatch):
    """A probe build that logs (NVIDIA notes every inlined kernel; here a conversion warning)
    still counts and prints nothing: pyopencl's CompilerWarning is suppressed as for every build."""
    import warnings
    from iblbake.device import choice
    devices, _ = choice.enumerate_devices()
    monkeypatch.setattr(choice, "PROBE_SOURCE", choice.PROBE_SOURCE.replace(
        "{ int i", "{ int unused = 1.5; int i"))
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        info = choice.probe(devices[0])
    assert info.ok, info.reason
    assert not [w for w in seen if "compiler" in str(w.category).lower()], [str(w.message) for w in seen]


def test_a_cold_kernel_build_prints_nothing(tmp_path):
    """PoCL's clang writes "13 warnings generated." (its float16 builtins' ABI notes) straight to
    file descriptor 2 on a cold build of sh_project.cl: `-q` printed it on every fresh machine
    (and the API's "prints nothing" broke). The line is dropped; the output is unchanged."""
    from tests.helpers import write_exr
    env = write_exr(tmp_path / "sky.exr", np.full((16, 32, 3), 0.5, np.float32))
    r = run_cli("sh", env, "-q", "-o", tmp_path / "sh.json", "--backend", "opencl",
                env={"POCL_CACHE_DIR": str(tmp_path / "pocl"), "IBLBAKE_KERNEL_CACHE": str(tmp_path / "kernels")})
    assert r.returncode == 0 and r.stderr == "" and r.stdout == "", (r.stdout, r.stderr)


def test_a_panorama_and_output_named_in_no_encoding(tmp_path):
    """A panorama whose file name is not UTF-8 (b'\\xff.exr' on Linux) is read; an output name of
    255 bytes is written (its temporary file was longer than the longest name)."""
    env = write_exr(tmp_path / "\udcff.exr", np.full((16, 32, 3), 0.5, np.float32))
    out = tmp_path / ("o" * 250 + ".json")
    p = run_cli("sh", env, "-o", out)
    assert p.returncode == 0, p.stderr
    assert np.allclose(json.loads(out.read_text())["radiance"][0], [0.5 * math.sqrt(4 * math.pi)] * 3, rtol=1e-6)


def test_a_huge_rotation_is_the_same_turn_mod_360(tmp_path):
    """--rotate-y 1.2345e300 is exactly 352 degrees mod 360: the same coefficients and error as
    --rotate-y 352, and a clean stderr (the angle in radians summed with pi lost every digit: the
    error block said 985% and numpy's cast warnings with their source lines reached stderr)."""
    v = np.linspace(0, 1, 32)[:, None, None]
    u = np.linspace(0, 1, 64)[None, :, None]
    env = write_exr(tmp_path / "e.exr", np.repeat(1 + np.cos(6 * u) * v, 3, axis=-1).astype(np.float32))
    docs = []
    for deg in ("1.2345e300", "352", "-5e30", "-304"):
        p = run_cli("sh", env, "--rotate-y", deg, "--json")
        assert p.returncode == 0 and p.stderr == "", p.stderr
        docs.append(json.loads(p.stdout))
    for a, b in (docs[:2], docs[2:]):
        assert np.allclose(a["irradiance"], b["irradiance"], rtol=1e-12, atol=1e-12)
        assert a["error"]["relative_rmse"] == pytest.approx(b["error"]["relative_rmse"], rel=1e-9)
    assert docs[0]["error"]["relative_rmse"] < 0.2
    assert not np.allclose(docs[0]["irradiance"], docs[2]["irradiance"], rtol=1e-3)    # 352 and -304 differ
