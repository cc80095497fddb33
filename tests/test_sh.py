"""Spherical harmonics: basis, Ahat, projection (numpy oracle and OpenCL) against closed forms."""

import math

import numpy as np
import pytest
from numpy.polynomial import legendre as npleg

from iblbake.core import conventions as cv
from iblbake.core import sh
from iblbake.bake import sh as shbake

from tests.helpers import gauss_sphere, rel_err


def test_basis_is_seed_000_for_l_le_2():
    d = np.random.default_rng(0).normal(size=(100, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    x, y, z = d.T
    pi = math.pi
    seed = np.stack([0.5 * np.sqrt(1 / pi) + 0 * x, 0.5 * np.sqrt(3 / pi) * y, 0.5 * np.sqrt(3 / pi) * z,
                     0.5 * np.sqrt(3 / pi) * x, 0.5 * np.sqrt(15 / pi) * x * y, 0.5 * np.sqrt(15 / pi) * y * z,
                     0.25 * np.sqrt(5 / pi) * (3 * z * z - 1), 0.5 * np.sqrt(15 / pi) * x * z,
                     0.25 * np.sqrt(15 / pi) * (x * x - y * y)], 1)
    assert np.abs(sh.sh_basis(d, 3) - seed).max() < 1e-12


@pytest.mark.parametrize("bands", [1, 3, 8, 12])
def test_basis_orthonormal(bands):
    d, w = gauss_sphere()
    y = sh.sh_basis(d, bands)
    gram = (y * w[:, None]).T @ y
    assert np.abs(gram - np.eye(bands * bands)).max() < 1e-10


def test_ahat_closed_forms():
    expect = [math.pi, 2 * math.pi / 3, math.pi / 4, 0.0, -math.pi / 24, 0.0, math.pi / 64]
    assert np.allclose([sh.truncated_cos_sh(l) for l in range(7)], expect, rtol=1e-12, atol=1e-15)
    # Ahat_l is the clamped cosine's Legendre coefficient: Ahat_l = 2 pi int_0^1 t P_l(t) dt
    t, wt = npleg.leggauss(64)
    t, wt = 0.5 * (t + 1), 0.5 * wt
    for l in range(12):
        pl = npleg.legval(t, [0] * l + [1])
        assert abs(2 * math.pi * np.sum(wt * t * pl) - sh.truncated_cos_sh(l)) < 1e-12


@pytest.mark.parametrize("bands", [1, 2, 3, 5, 8])
def test_opencl_basis_matches_numpy(rt, bands):
    d = np.random.default_rng(bands).normal(size=(2000, 3))
    d = np.concatenate([d / np.linalg.norm(d, axis=1, keepdims=True), np.eye(3), -np.eye(3)])
    prg = rt.program("selftest.cl", {"SH_BANDS": bands})
    out = rt.empty(len(d) * bands * bands * 4)
    rt.run(prg.t_sh, (len(d),), None, rt.to_device(d.astype(np.float32)), out)
    got = rt.read(out, (len(d), bands * bands))
    assert np.abs(got - sh.sh_basis(d, bands)).max() < 2e-5


@pytest.mark.slow
@pytest.mark.parametrize("w,h", [(1, 1), (2, 1), (7, 3), (50, 24)])
def test_separable_form_equals_direct_texel_quadrature(w, h):
    img = np.random.default_rng(1).random((h, w, 3))
    for bands in (1, 3, 8):
        direct = sh.project_direct(img, bands, rotate_y_deg=33.0, nodes=8)
        separable = sh.project(img, bands, 33.0)
        assert rel_err(separable, direct) < 1e-9


BACKENDS = ["numpy", "opencl"]


def project(image, bands, backend, rt, rot=0.0):
    return shbake.project(np.asarray(image, np.float32), bands, backend, rt if backend == "opencl" else None,
                          rot)[0]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("w,h", [(1, 1), (2, 1), (4, 2), (7, 3), (64, 32), (1024, 512)])
def test_constant_panorama(rt, backend, w, h):
    c = 2.5
    coeffs = project(np.full((h, w, 3), c), 3, backend, rt)
    assert np.all(np.isfinite(coeffs))
    assert np.allclose(coeffs[0], c * math.sqrt(4 * math.pi), rtol=1e-6)
    assert np.abs(coeffs[1:]).max() < 1e-6 * c * math.sqrt(4 * math.pi)
    irr = coeffs * sh.ahat(3)[:, None]
    e = sh.irradiance(irr, cv.equirect_texel_dirs(16, 8).reshape(-1, 3), 3)
    assert np.abs(e / (math.pi * c) - 1).max() < 1e-5


@pytest.mark.parametrize("backend", BACKENDS)
def test_basis_function_panoramas_project_to_unit_vectors(rt, backend):
    """A panorama equal to Y_lm at texel centres (512x256) projects to 1 on that coefficient and
    < 2e-3 on every other, for every l <= 7. Three basis functions ride in R, G, B at a time."""
    w, h, bands = 512, 256, 8
    y = sh.sh_basis(cv.equirect_texel_dirs(w, h), bands)  # (h, w, 64)
    n = bands * bands
    for k0 in range(0, n, 3):
        ks = [k % n for k in range(k0, k0 + 3)]
        coeffs = project(y[..., ks], bands, backend, rt)
        for c, k in enumerate(ks):
            col = coeffs[:, c]
            assert abs(col[k] - 1) < 2e-3, (k, col[k])
            others = np.delete(col, k)
            assert np.abs(others).max() < 2e-3, (k, np.abs(others).max())


def analytic_band_limited_irradiance(cos_gamma, bands):
    """sum_l Ahat_l (2l+1)/(4 pi) P_l(cos gamma): the clamped cosine lobe of a unit delta light,
    band-limited (addition theorem), independent of the Y_lm code."""
    c = [sh.truncated_cos_sh(l) * (2 * l + 1) / (4 * math.pi) for l in range(bands)]
    return npleg.legval(cos_gamma, c)


def texel_patch_irradiance(normals, w, h, i, j, bands, nodes=10):
    """Band-limited irradiance at `normals` from texel (i, j) of unit radiance: the kernel
    sum_l Ahat_l (2l+1)/(4 pi) P_l(n . w) (addition theorem, independent of the Y_lm code)
    integrated over the texel's exact extent by Gauss-Legendre in (theta, phi)."""
    x, wx = npleg.leggauss(nodes)
    a, b = math.pi * j / h, math.pi * (j + 1) / h
    theta = 0.5 * (a + b) + 0.5 * (b - a) * x
    phi_c = 2 * math.pi * (0.5 - (i + 0.5) / w)
    phi = phi_c + (math.pi / w) * x
    wt = 0.5 * (b - a) * wx * np.sin(theta)
    wp = (math.pi / w) * wx
    st = np.sin(theta)[:, None]
    dirs = np.stack(np.broadcast_arrays(st * np.sin(phi), np.cos(theta)[:, None], st * np.cos(phi)), -1)
    weights = (wt[:, None] * wp[None, :]).reshape(-1)
    return analytic_band_limited_irradiance(normals @ dirs.reshape(-1, 3).T, bands) @ weights


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("bands", [3, 5])
def test_single_bright_texel(rt, backend, bands):
    w, h = 64, 32
    i, j, value = 10, 9, 1000.0
    img = np.zeros((h, w, 3), np.float32)
    img[j, i] = value
    d = cv.equirect_texel_dirs(w, h)[j, i]
    irr = project(img, bands, backend, rt) * sh.ahat(bands)[:, None]
    normals = cv.equirect_texel_dirs(256, 128).reshape(-1, 3)
    e = sh.evaluate(irr, normals, bands)[:, 0]
    expect = value * texel_patch_irradiance(normals, w, h, i, j, bands)
    assert rel_err(e, expect) < 1e-4
    # the patch is a small disc: against a delta of the same power at its centre, 1%
    delta = value * cv.equirect_row_solid_angles(w, h)[j] * analytic_band_limited_irradiance(normals @ d, bands)
    assert rel_err(e, delta) < 1e-2
    # largest at the normal pointing at the texel (the "rotated against itself" trap)
    assert normals[np.argmax(e)] @ d > math.cos(math.radians(2.0))
    # rotating the panorama by 90 degrees about +y moves the peak by 90 degrees
    for rotated in (project(img, bands, backend, rt, rot=90.0),
                    project(np.roll(img, -w // 4, axis=1), bands, backend, rt)):
        e_rot = sh.evaluate(rotated * sh.ahat(bands)[:, None], normals, bands)[:, 0]
        peak = normals[np.argmax(e_rot)]
        assert peak @ cv.rotate_y(d, 90.0) > math.cos(math.radians(2.0))
        turned = math.degrees(math.atan2(peak[0], peak[2]) - math.atan2(d[0], d[2])) % 360
        assert abs(turned - 90) < 3 and abs(peak[1] - d[1]) < 0.05


@pytest.mark.external
@pytest.mark.external
@pytest.mark.parametrize("bands", [3, 8])
def test_opencl_matches_numpy_on_real_panoramas(rt, load_panorama, bands):
    from tests.helpers import PANORAMA_NAMES
    for name in PANORAMA_NAMES:
        img = load_panorama(name)
        a = project(img, bands, "opencl", rt)
        b = project(img, bands, "numpy", rt)
        assert rel_err(a, b) < 1e-5, name


def test_band0_is_solid_angle_weighted_mean():
    img = np.random.default_rng(5).random((13, 27, 3)) * 10
    coeffs = sh.project(img, 2)
    wgt = cv.equirect_solid_angles(27, 13)
    mean = (img * wgt[..., None]).sum((0, 1)) / wgt.sum()
    assert np.allclose(coeffs[0], mean * 2 * math.sqrt(math.pi), rtol=1e-12)


# --- the error block of `iblbake sh` ----------------------------------------------------------------

def brute_force_irradiance(img, normals, rotate_y):
    """Independent: every texel against every normal, no arcs, no prefix sums."""
    h, w = img.shape[:2]
    d = cv.equirect_texel_dirs(w, h, rotate_y).reshape(-1, 3)
    om = cv.equirect_solid_angles(w, h).reshape(-1)
    return np.maximum(normals @ d.T, 0.0) @ (img.reshape(-1, img.shape[2]).astype(np.float64) * om[:, None])


@pytest.mark.parametrize("w,h,rot", [(64, 32, 0.0), (96, 48, 37.0), (33, 17, -120.0), (8, 4, 200.0)])
def test_exact_irradiance_against_brute_force(w, h, rot):
    rng = np.random.default_rng(w)
    img = rng.gamma(0.5, 1.0, (h, w, 3))
    img[h // 3, w // 2] = 500.0                                  # a sun: arcs end inside its row
    n = shbake.fibonacci_normals()
    assert rel_err(shbake.exact_irradiance(img, n, rot), brute_force_irradiance(img, n, rot)) < 1e-12


def test_error_block_against_float64_evaluation():
    """Every figure of the error block against its independent float64 evaluation (1e-6), on a
    panorama with a sun (the SH rings below zero), rotated and scaled."""
    rng = np.random.default_rng(3)
    img = 0.01 + 0.01 * rng.random((48, 96, 3))
    img[10:12, 30:32] = 2000.0
    rot, k, bands = 25.0, 1.7, 3
    coeffs = sh.project(img, bands, rot) * k * sh.ahat(bands)[:, None]
    got = shbake.irradiance_error(img, coeffs, bands, rot, k)
    n = shbake.fibonacci_normals()
    lum = np.array([0.2126, 0.7152, 0.0722])
    exact = brute_force_irradiance(img, n, rot) @ lum * k
    raw = np.stack([sum(coeffs[i, c] * sh.sh_basis(n, bands)[:, i] for i in range(bands * bands))
                    for c in range(3)], -1)
    approx = np.maximum(raw, 0) @ lum
    assert raw.min() < 0                                        # the test exercises the ringing figure
    want_rmse = math.sqrt(np.mean((approx - exact) ** 2) / np.mean(exact ** 2))
    want_max = np.max(np.abs(approx - exact) / (exact + 1e-3 * exact.mean()))
    assert got["relative_rmse"] == pytest.approx(want_rmse, rel=1e-6)
    assert got["max_relative_error"] == pytest.approx(want_max, rel=1e-6)
    assert got["most_negative"] == pytest.approx(raw.min(), rel=1e-6)
    assert got["most_negative_relative"] == pytest.approx(raw.min() / exact.mean(), rel=1e-6)


def test_error_falls_with_bands_on_a_smooth_panorama():
    d = cv.equirect_texel_dirs(128, 64)
    img = (np.exp(3.0 * (d @ np.array([0.6, 0.64, 0.48]) - 1)) + 0.2)[..., None] * np.ones(3)
    errs = [shbake.irradiance_error(img, sh.project(img, b) * sh.ahat(b)[:, None], b)["relative_rmse"]
            for b in (1, 2, 3, 5, 7)]
    assert all(b < a for a, b in zip(errs, errs[1:])), errs
    assert errs[-1] < 1e-3, errs
