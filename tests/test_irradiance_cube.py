"""The Lambert irradiance cube map (`iblbake mips --irradiance`), computed in the SH domain:
closed forms (a constant panorama gives pi c; a panorama linear in y gives pi + (2 pi / 3) n.y,
to the box texels' own second-order error), the exact float64 sum over every texel on city at
256 normals (what the manifest reports), and its KTX2 file read back by ktx-parse."""

import base64
import json
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from iblbake.bake import layouts, spectral
from iblbake.bake import sh as shbake
from iblbake.core import conventions
from iblbake.io import images

from tests.helpers import run_cli

NODE = Path(__file__).parent / "node"


def test_constant_panorama_is_pi_c():
    img = np.full((64, 128, 3), [0.5, 1.0, 2.0])
    e = spectral.irradiance(img, layouts.layout_dirs("cubemap", 8), 64)
    assert np.abs(e / (math.pi * np.array([0.5, 1.0, 2.0])) - 1).max() < 1e-9


def test_linear_sky_is_pi_plus_two_pi_thirds_y():
    """L = 1 + y held as box texels (each row the mean of y over it): E(n) = pi + (2 pi / 3) n.y
    up to the steps between rows, a second-order error: 8.4e-4, 2.1e-4, 5.2e-5 at 64, 128, 256
    rows (falling 4x per doubling), the same at band 8 and 64."""
    errs = []
    for h in (64, 128, 256):
        edges = np.linspace(0, math.pi, h + 1)
        # mean of cos(theta) over a row's solid angle: (sin^2 b - sin^2 a) / (2 (cos a - cos b))
        mean_y = (np.sin(edges[1:]) ** 2 - np.sin(edges[:-1]) ** 2) / (2 * (np.cos(edges[:-1]) - np.cos(edges[1:])))
        img = np.repeat((1 + mean_y)[:, None, None], 2 * h, axis=1)
        d = layouts.layout_dirs("cubemap", 16)
        errs.append(np.abs(spectral.irradiance(img, d, 8)[..., 0] - (math.pi + 2 * math.pi / 3 * d[..., 1])).max())
    assert errs[-1] < 6e-5 and all(3.8 < a / b < 4.2 for a, b in zip(errs, errs[1:])), errs


@pytest.mark.external
def test_city_against_the_exact_sum(load_panorama):
    img = load_panorama("city").astype(np.float64)
    n = shbake.fibonacci_normals()
    exact = shbake.exact_irradiance(img, n)
    for lmax, bound in ((64, 3e-3), (256, 4e-4)):
        err = np.abs(spectral.irradiance(img, n, lmax) - exact) / np.abs(exact).max()
        assert err.max() < bound, (lmax, err.max())       # measured 1.4e-3 and 1.6e-4


@pytest.mark.external
def test_cli_cube_and_its_ktx2(tmp_path, small_panoramas):
    out = tmp_path / "irr.ktx2"
    p = run_cli("mips", small_panoramas["city"], "--cache", tmp_path / "c", "--only", "radiance", "--irradiance-size",
                "8", "--ktx2-irradiance", out, "--ktx2-format", "rgba32f", "--json")
    assert p.returncode == 0, p.stderr
    rep = json.loads(p.stdout)["entries"]["irradiance"]
    assert rep["error"]["max_relative_to_peak"] < 4e-4 and not rep["cached"]
    faces = images.read_exr(Path(rep["path"]) / "irradiance.exr")[..., :3]
    src, _ = images.read_panorama(small_panoramas["city"])
    want = spectral.irradiance(src.astype(np.float64), conventions.cube_texel_dirs(8).reshape(48, 8, 3), 256)
    assert np.abs(faces - want).max() <= 1e-6 * np.abs(want).max()
    if shutil.which("node") is None or not (NODE / "node_modules" / "ktx-parse").is_dir():
        pytest.skip("the Node readers are not set up: run `make readers` (make test does)")
    got = json.loads(subprocess.run(["node", str(NODE / "read_ktx2.mjs"), str(out)], capture_output=True, text=True,
                                    timeout=120, check=True).stdout)[str(out)]
    assert (got["vkFormat"], got["pixelWidth"], got["faceCount"], len(got["levels"])) == (109, 8, 6, 1)
    texels = np.frombuffer(base64.b64decode(got["levels"][0]["data"]), "<f4").reshape(6, 8, 8, 4)
    assert np.array_equal(texels[..., :3], faces.reshape(6, 8, 8, 3))
    p = run_cli("mips", small_panoramas["city"], "--cache", tmp_path / "c", "--only", "radiance", "--irradiance",
                "--irradiance-size", "8", "--json")
    assert json.loads(p.stdout)["entries"]["irradiance"]["cached"]


