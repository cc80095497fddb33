"""The public API (iblbake.api, docs/api.md): its names are frozen, `import iblbake` stays cheap,
the docs reach help(), and it gives what the command line gives."""

import json
import statistics
import subprocess
import sys

import numpy as np
import pytest

import iblbake
from tests.helpers import run_cli, write_exr

# semantic versioning (docs/api.md): a public name may be added here, never taken away
PUBLIC = {
    "Accuracy", "Basis", "Chain", "DeviceError", "Error", "Frame", "InputError", "Panorama", "ProbeVolume",
    "Renderer", "SH", "Scene", "UsageError", "accuracy", "bake_probes", "basis", "dfg", "load_panorama",
    "load_scene", "prefilter", "render", "sh",
}
HEAVY = ("numpy", "pyopencl", "OpenImageIO", "OpenEXR", "trimesh", "yaml", "click", "matplotlib")


def test_no_public_name_disappears():
    missing = PUBLIC - set(iblbake.__all__)
    assert not missing, f"public names removed from iblbake.__all__ (a major version): {sorted(missing)}"
    for name in iblbake.__all__:
        assert getattr(iblbake, name) is not None, name


def test_every_public_name_is_documented():
    for name in iblbake.__all__:
        doc = getattr(iblbake, name).__doc__
        assert doc and len(doc.split()) >= 8, f"iblbake.{name} has no docstring worth the name"


def test_import_is_under_a_tenth_of_a_second_and_loads_nothing_heavy():
    code = ("import sys, time\nt = time.perf_counter()\nimport iblbake\ns = time.perf_counter() - t\n"
            f"print(s, sorted(m for m in {HEAVY!r} if m in sys.modules))")
    times = []
    for _ in range(5):
        p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
        assert p.returncode == 0, p.stderr
        seconds, loaded = p.stdout.split(" ", 1)
        assert loaded.strip() == "[]", loaded
        times.append(float(seconds))
    assert statistics.median(times) < 0.1, times


def test_the_library_knows_no_command_line():
    """iblbake.api (and what it calls) never imports click: importing it and calling a function
    loads none of it."""
    code = ("import sys, numpy as np, iblbake\n"
            "iblbake.sh(iblbake.Panorama.from_pixels(np.ones((4, 8, 3))), error=False)\n"
            "try:\n    iblbake.load_scene({'camera': {}})\nexcept iblbake.Error:\n    pass\n"
            "print('click' in sys.modules)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert p.stdout.strip() == "False", p.stdout + p.stderr


def test_help_shows_the_docstring():
    p = subprocess.run([sys.executable, "-c", "import iblbake; help(iblbake.render)"], capture_output=True,
                       text=True, timeout=60, env={"PAGER": "cat", "TERM": "dumb", "PATH": ""})
    assert p.returncode == 0, p.stderr
    assert "render(scene" in p.stdout and "Frame" in p.stdout and "Renderer" in p.stdout, p.stdout


def test_render_stays_the_function_once_the_subpackage_loads():
    """iblbake.render is the public function though a subpackage shares its name: loading the
    subpackage (as every render does) leaves the function in place."""
    code = ("import iblbake, iblbake.render.frame\nfrom iblbake.render import Bakes\n"
            "print(callable(iblbake.render), iblbake.render.__module__)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert p.stdout.split() == ["True", "iblbake.api"], p.stdout + p.stderr


def test_errors_are_the_command_lines(tmp_path):
    missing = tmp_path / "missing.exr"
    with pytest.raises(iblbake.InputError) as e:
        iblbake.load_panorama(missing)
    p = run_cli("sh", missing)
    assert p.stderr.strip() == f"Error: {e.value}"
    bad = write_exr(tmp_path / "nan.exr", np.full((8, 16, 3), np.nan))
    with pytest.raises(iblbake.Error) as e:
        iblbake.load_panorama(bad, names={"nonfinite": "--nonfinite"})
    assert run_cli("sh", bad).stderr.strip() == f"Error: {e.value}"
    with pytest.raises(iblbake.InputError, match="unknown key"):
        iblbake.load_scene({"camera": {"resolution": [8, 8]}, "environment": {"path": "x.exr"},
                            "effects": {"difuse": "sh"}})


def test_sh_is_what_the_command_writes(tmp_path):
    rng = np.random.default_rng(1)
    env = write_exr(tmp_path / "env.exr", rng.uniform(0, 2, (16, 32, 3)))
    coeffs = iblbake.sh(iblbake.load_panorama(env), bands=3, window="lanczos")
    out = tmp_path / "sh.json"
    assert run_cli("sh", env, "--window", "lanczos", "-o", out, "-q").returncode == 0
    doc = json.loads(out.read_text())
    assert np.array_equal(np.asarray(doc["irradiance"]), coeffs.irradiance)
    assert doc["error"] == coeffs.error
    for fmt in ("filament", "threejs", "gltf", "glsl"):
        p = run_cli("sh", env, "--window", "lanczos", "--format", fmt, "-q")
        assert p.stdout == coeffs.export(fmt), fmt
    assert np.allclose(coeffs.to_gltf(), json.loads(coeffs.export("gltf"))["irradianceCoefficients"], atol=1e-8)


def test_panorama_from_pixels_and_bad_arguments():
    pano = iblbake.Panorama.from_pixels(np.ones((8, 16, 3)))
    assert pano.layout == "equirect" and pano.width == 16
    lit = iblbake.sh(pano, bands=1, error=False)
    assert np.allclose(lit.irradiance[0] * 0.5 / np.sqrt(np.pi), np.pi)      # E = pi under a uniform sky of 1
    for call in (lambda: iblbake.sh(pano, bands=0), lambda: iblbake.sh(pano, window="box"),
                 lambda: iblbake.prefilter(pano, layout="sphere"), lambda: iblbake.dfg(1),
                 lambda: iblbake.Panorama.from_pixels(np.ones((4, 4)))):
        with pytest.raises(iblbake.InputError):
            call()
    with pytest.raises(iblbake.InputError, match="non-finite"):
        iblbake.Panorama.from_pixels(np.full((4, 8, 3), np.inf))


def test_the_band_energy_example_plots_two_panoramas(tmp_path):
    """examples/sh_band_energy.py over a folder of two tiny panoramas: a uniform sky (all its
    energy in band 0) and a sky with one bright texel (a sun: energy in every band)."""
    from tests.helpers import ROOT
    folder = tmp_path / "panoramas"
    folder.mkdir()
    write_exr(folder / "overcast.exr", np.ones((16, 32, 3)))
    sun = np.full((16, 32, 3), 0.1)
    sun[3, 10] = 500.0
    write_exr(folder / "sun.exr", sun)
    out = tmp_path / "bands.png"
    p = subprocess.run([sys.executable, str(ROOT / "examples" / "sh_band_energy.py"), str(folder), "-o", str(out),
                        "--bands", "6"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    lines = dict(line.split(": ", 1) for line in p.stdout.splitlines() if not line.startswith("wrote"))
    assert float(lines["overcast"].split("%")[0]) < 1e-6
    assert float(lines["sun"].split("%")[0]) > 20
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("dither", [False, True])
def test_tonemapped_without_a_png_output_is_the_devices(tmp_path, dither):
    """A scene that writes no PNG is not tone-mapped on the device: Frame.tonemapped applies the
    same operator and dither on the host, within one 8-bit step of the device's (float32 there)."""
    sky = write_exr(tmp_path / "sky.exr", np.linspace(0.05, 3, 16 * 32 * 3).reshape(16, 32, 3))
    scene = {"camera": {"perspective": {"position": [0, 0, 3], "fov_y": 40}, "resolution": [24, 16]},
             "environment": {"path": sky}, "materials": {"m": {"base_color": [0.7, 0.6, 0.5]}},
             "objects": [{"sphere": {"radius": 1}, "material": "m"}],
             "effects": {"diffuse": "sh", "specular": "off", "tonemap": "hable", "exposure": 0.5},
             "output": {"dither": dither}}
    renderer = iblbake.Renderer(cache=tmp_path / "cache", reuse=False)
    host = renderer.render(iblbake.load_scene(scene))
    device = renderer.render(iblbake.load_scene(scene, outputs=[str(tmp_path / "f.png")]))
    assert host.png is None and device.png is not None
    assert np.array_equal(host.hdr, device.hdr)
    step = np.abs(host.tonemapped.astype(int) - device.tonemapped.astype(int))
    assert step.max() <= 1 and (step == 0).mean() > 0.99


@pytest.mark.slow       # two kernel builds: make test
def test_a_renderer_sees_a_panorama_rewritten_in_place(tmp_path):
    """A Renderer reuses the passes whose inputs did not change; a panorama rewritten at the same
    path is a new bake with the same scene values, and the passes reading it run again (a new
    user's notebook got the previous frame back: the report said the bakes ran)."""
    import os
    sky = tmp_path / "sky.exr"
    write_exr(sky, np.full((16, 32, 3), [0.6, 0.8, 1.0], np.float32))
    scene = {"camera": {"perspective": {"position": [0, 0, 3], "fov_y": 40}, "resolution": [16, 12]},
             "environment": {"path": str(sky), "background": "hide"}, "materials": {"m": {"roughness": 0.5}},
             "objects": [{"sphere": {"radius": 1}, "material": "m"}],
             "effects": {"diffuse": "sh", "specular": "prefiltered"}}
    renderer = iblbake.Renderer(cache=tmp_path / "cache")
    first = renderer.render(iblbake.load_scene(scene)).hdr.copy()
    write_exr(sky, np.full((16, 32, 3), [2.0, 0.1, 0.1], np.float32))
    os.utime(sky, ns=(os.stat(sky).st_atime_ns, os.stat(sky).st_mtime_ns + 10**9))   # a new mtime, surely
    again = renderer.render(iblbake.load_scene(scene)).hdr
    fresh = iblbake.render(iblbake.load_scene(scene), cache=tmp_path / "cache").hdr
    assert not np.allclose(again, first) and np.array_equal(again, fresh)


def test_dir_and_help_show_the_api_alone():
    """dir(iblbake) listed the package's machinery (sys, types, the errors submodule) and
    help(iblbake) listed __dir__ and __getattr__ as its first FUNCTIONS."""
    code = ("import iblbake, iblbake.errors, iblbake.render.frame\n"
            "print(sorted(n for n in dir(iblbake) if not n.startswith('__')))\n"
            "help(iblbake)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                       env={"PAGER": "cat", "TERM": "dumb", "PATH": ""})
    assert p.returncode == 0, p.stderr
    listed, help_text = p.stdout.split("\n", 1)
    assert eval(listed) == sorted(iblbake.__all__), listed
    functions = help_text.split("\nFUNCTIONS\n", 1)[1].split("\nDATA\n", 1)[0]
    assert "__getattr__" not in functions and "__dir__" not in functions, functions[:300]
    assert iblbake.errors.InputError is iblbake.InputError       # the submodule is still reachable


def test_the_command_line_says_its_flags_and_the_api_its_arguments(tmp_path):
    """One message, two wordings: the command line passes its flags as `names` (its messages as
    they were), the API says its arguments' names (it said --max-pixels, --input-layout, --set)."""
    env = write_exr(tmp_path / "env.exr", np.ones((8, 16, 3)))
    scene = tmp_path / "scene.yaml"
    scene.write_text(f"camera: {{resolution: [8, 8]}}\nenvironment: {{path: {env}}}\n")
    for argv, call, flag, argument in (
            (["sh", env, "--max-pixels", "10"], lambda: iblbake.load_panorama(env, max_pixels=10),
             "raise it with --max-pixels or", "raise it with max_pixels or"),
            (["sh", env, "--input-layout", "hcross"], lambda: iblbake.load_panorama(env, layout="hcross"),
             "give --input-layout (environment.layout) for what it is", "give layout for what it is"),
            (["deps", scene, "--set", "effects"], lambda: iblbake.load_scene(scene, "effects"),
             "--set 'effects': expected KEY.PATH=VALUE", "overrides 'effects': expected KEY.PATH=VALUE")):
        with pytest.raises(iblbake.InputError) as e:
            call()
        p = run_cli(*argv)
        assert p.returncode == e.value.exit_code and flag in p.stderr, p.stderr
        assert str(e.value) == p.stderr.strip().removeprefix("Error: ").replace(flag, argument), (str(e.value), p.stderr)
