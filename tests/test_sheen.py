"""Sheen (`iblbake mips --sheen`, KHR_materials_sheen): the Charlie NDF normalised and equal to
the glTF Sample Viewer's D_Charlie and V_Ashikhmin (transcribed from its shader source); the
sheen albedo table (OpenCL kernel and numpy twin) against a float64 quadrature over the light
hemisphere; the Charlie-prefiltered chain: constant in, constant out, and against the float64
brute force over every texel."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from iblbake.bake import dfg, layouts, mips, prefilter, spectral
from iblbake.core import brdf
from iblbake.io import images

from tests.helpers import box_downsample, run_cli


def viewer_d_charlie(sheen_roughness, noh):
    """glTF Sample Viewer, brdf.glsl D_Charlie, line for line."""
    sheen_roughness = max(sheen_roughness, 0.000001)
    alpha_g = sheen_roughness * sheen_roughness
    inv_r = 1.0 / alpha_g
    sin2h = 1.0 - noh * noh
    return (2.0 + inv_r) * np.power(sin2h, inv_r * 0.5) / (2.0 * math.pi)


def viewer_v_ashikhmin(nol, nov):
    return np.clip(1.0 / (4.0 * (nol + nov - nol * nov)), 0.0, 1.0)


def test_charlie_terms_match_the_viewer_and_normalise():
    noh = np.linspace(0, 1, 101)
    for r in (0.1, 0.3, 0.7, 1.0):
        assert np.allclose(brdf.d_charlie(noh, r * r), viewer_d_charlie(r, noh), rtol=1e-12, atol=0)
        # int D(h) (n.h) dw_h = 1, Gauss-Legendre in theta_h (smooth there)
        g, w = np.polynomial.legendre.leggauss(400)
        th, wt = math.pi / 4 * (g + 1), math.pi / 4 * w
        assert abs((brdf.d_charlie(np.cos(th), r * r) * np.cos(th) * np.sin(th) * wt).sum() * 2 * math.pi - 1) < 1e-9
    nl, nv = np.meshgrid(np.linspace(0.01, 1, 50), np.linspace(0.01, 1, 50))
    assert np.allclose(brdf.v_ashikhmin(nv, nl), viewer_v_ashikhmin(nl, nv), rtol=1e-12)


def quadrature_albedo(nov, r, nmu=800, nphi=4096):
    """E = int D_charlie V NoL dl over the light hemisphere in (NoL, phi): Gauss-Legendre in
    sqrt(NoL) (dense near the horizon, where the lobe sits), midpoints in phi."""
    g, w = np.polynomial.legendre.leggauss(nmu)
    t, wt = 0.5 * (g + 1), 0.5 * w
    mu, wmu = t * t, wt * 2 * t
    phi = (np.arange(nphi) + 0.5) / nphi * 2 * math.pi
    m, p = np.meshgrid(mu, phi, indexing="ij")
    vl = nov * m + math.sqrt(1 - nov * nov) * np.sqrt(1 - m * m) * np.cos(p)
    noh = (nov + m) / np.sqrt(2 * (1 + vl))
    f = brdf.d_charlie(noh, r * r) * brdf.v_ashikhmin(nov, m) * m
    return float((f * wmu[:, None]).sum() * 2 * math.pi / nphi)


@pytest.mark.slow
def test_sheen_table_against_the_quadrature(rt):
    """4096 Hammersley samples: within 4e-4 of the converged integral (measured 2.3e-4 worst,
    at r = 1/32, NoV = 1/8), the kernel within 2e-5 of its twin."""
    size = 33
    twin = dfg.sheen_twin(size, 4096)
    cl = mips.OpenCLBaker(rt).dfg_sheen(size, 4096)
    assert np.abs(cl - twin).max() < 2e-5 * max(1.0, twin.max())
    for r in (1 / 32, 1 / 8, 0.25, 0.5, 1.0):
        for nov in (1 / 32, 0.125, 0.5, 0.875):
            j, i = round(r * (size - 1)), round(nov * (size - 1))
            assert abs(twin[j, i] - quadrature_albedo(nov, r)) < 4e-4, (r, nov)


@pytest.mark.external
def test_sheen_chain_constant_and_brute_force(load_panorama):
    const = np.full((32, 64, 3), [0.5, 1.0, 2.0])
    dirs = [layouts.layout_dirs("equirect", 8)]
    for r in (0.07, 0.25, 1.0):
        lvl = spectral.prefilter_levels(const, dirs, [r], ndf="charlie")[0]
        assert np.abs(lvl / [0.5, 1.0, 2.0] - 1).max() < 1e-6
    src = box_downsample(load_panorama("city").astype(np.float64), 4)       # 256x128, its sun kept
    rng = np.random.default_rng(0)
    d = layouts.layout_dirs("equirect", 32).reshape(-1, 3)[rng.choice(64 * 32, 48, replace=False)]
    for r in (0.125, 0.5, 1.0):
        got = spectral.prefilter_levels(src, [d], [r], ndf="charlie")[0]
        ref = prefilter.prefilter_bruteforce(src, d, r, ndf="charlie", max_sub=4)
        err = np.sqrt(((got - ref) ** 2).mean() / (ref ** 2).mean())
        assert err < 1e-3, (r, err)                   # measured 1.8e-4 .. 4.2e-4


@pytest.mark.external
def test_cli_sheen_chain_table_and_ktx2(tmp_path, small_panoramas):
    out = tmp_path / "sheen.ktx2"
    p = run_cli("mips", small_panoramas["city"], "--cache", tmp_path / "c", "--only", "prefiltered", "--sheen",
                "--ktx2-sheen", out, "--size", "16", "--min-size", "1", "--levels", "5", "--dfg-size", "16",
                "--dfg-samples", "512", "--json")
    assert p.returncode == 0, p.stderr
    e = json.loads(p.stdout)["entries"]
    assert e["sheen"]["roughness"] == [0.07, 0.25, 0.5, 0.75, 1.0] and e["sheen"]["layout"] == "cubemap"
    table = images.read_exr(Path(e["dfg_sheen"]["path"]) / "dfg_sheen.exr")[..., 0]
    assert table.shape == (16, 16) and np.allclose(table, dfg.sheen_twin(16, 512), atol=2e-5)
    data = out.read_bytes()
    assert data[:12] == b"\xabKTX 20\xbb\r\n\x1a\n" and b"iblbake.roughness\x00[0.07, 0.25, 0.5, 0.75, 1.0]" in data
    p = run_cli("mips", small_panoramas["city"], "--cache", tmp_path / "c", "--only", "dfg", "--sheen")
    assert p.returncode == 2 and "--only prefiltered" in p.stderr
