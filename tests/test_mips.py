"""Radiance chain, prefiltered chain, DFG: kernels against numpy twins and closed forms."""

import numpy as np
import pytest

from iblbake import mips, mipsbake

from .conftest import rel_err


@pytest.fixture(scope="module")
def baker(rt):
    return mips.OpenCLBaker(rt)


@pytest.mark.parametrize("w,h", [(64, 32), (7, 3), (1, 1), (2, 1), (30, 17)])
def test_radiance_chain_constant_and_mean_preserving(baker, w, h):
    img = np.full((h, w, 3), 2.0, np.float32)
    levels, _ = baker.radiance_chain(img)
    ref = mips.radiance_chain_reference(img)
    assert [l.shape for l in levels] == [r.shape for r in ref]
    assert levels[-1].shape[0] == 1
    for l in levels:
        assert np.abs(l / 2.0 - 1).max() < 1e-4
    rnd = np.random.default_rng(0).random((h, w, 3)).astype(np.float32) * 5
    levels, _ = baker.radiance_chain(rnd)
    ref = mips.radiance_chain_reference(rnd)
    m0 = mips.solid_angle_mean(ref[0])
    for a, b in zip(levels, ref):
        assert rel_err(a, b) < 1e-5
        assert np.abs(mips.solid_angle_mean(b) / m0 - 1).max() < 1e-12
        assert np.abs(mips.solid_angle_mean(a) / m0 - 1).max() < 1e-5


@pytest.mark.assets
def test_radiance_chain_mean_on_real_panoramas(baker, load_panorama):
    for name in ("city", "studio", "sunset", "night"):
        levels, _ = baker.radiance_chain(load_panorama(name))
        m0 = mips.solid_angle_mean(levels[0])
        for l in levels[1:]:
            assert np.abs(mips.solid_angle_mean(l) / m0 - 1).max() < 1e-5, name


@pytest.mark.parametrize("layout", ["equirect", "cubemap", "octahedral"])
@pytest.mark.parametrize("method", ["fis", "convolve"])
def test_prefiltered_constant_environment_every_layout(rt, layout, method):
    img = np.full((32, 64, 3), 1.5, np.float32)
    b = mipsbake.Baker("opencl")
    b.rt, b.gpu = rt, mips.OpenCLBaker(rt)
    opts = mipsbake.PrefilterOptions(layout, 8, 4, method=method, samples=64).resolved(32)
    chain = b.radiance_chain(img)
    levels, methods = b.prefilter(chain, opts)
    assert methods[0] == "resample"
    for lvl in levels:
        assert lvl.shape[:2] == mips.layout_shape(layout, lvl.shape[1] if layout != "equirect" else lvl.shape[0])
        assert np.abs(lvl / 1.5 - 1).max() < 1e-4


@pytest.mark.parametrize("layout", ["equirect", "cubemap", "octahedral"])
def test_mirror_level_is_the_source_resampled(baker, layout):
    img = np.random.default_rng(1).random((32, 64, 3)).astype(np.float32)
    _, dev = baker.radiance_chain(img)
    got = baker.prefilter_level(dev, layout, 16, 0.0, 1)
    dirs = mips.layout_dirs(layout, 16)
    from iblbake import conventions as cv
    u, v = cv.equirect_uv_from_dir(dirs)
    assert np.abs(got - cv.bilinear_equirect(img.astype(np.float64), u, v)).max() < 1e-3
    if layout == "equirect":
        same = baker.prefilter_level(dev, "equirect", 32, 0.0, 1)
        assert np.abs(same - img).max() < 1e-5


@pytest.mark.parametrize("roughness", [0.25, 0.6, 1.0])
def test_opencl_prefilter_matches_numpy(baker, roughness):
    img = np.random.default_rng(2).random((16, 32, 3)).astype(np.float32) * 3
    img[4, 7] = 500.0
    levels, dev = baker.radiance_chain(img)
    chain64 = [l.astype(np.float64) for l in levels]
    for layout in ("equirect", "cubemap"):
        dirs = mips.layout_dirs(layout, 8)
        got = baker.prefilter_level(dev, layout, 8, roughness, 64, 1.0, True)
        ref = mips.prefilter_reference(chain64, dirs, roughness, 64, 1.0, True)
        assert rel_err(got, ref) < 1e-4
        got = baker.convolve_level(levels, layout, 8, roughness)
        ref = mips.convolve_reference(chain64, dirs, roughness)
        # float32 sums of ~1e4 weighted terms around a 500x spike: measured <= 1.8e-4
        assert rel_err(got, ref) < 5e-4


@pytest.mark.assets
@pytest.mark.parametrize("name", ["city", "studio", "sunset"])
def test_default_chain_against_bruteforce_at_64x32(baker, load_panorama, name):
    """Every default level of a 64x32 source within 2% relative RMSE of the brute-force reference
    (every source texel, exact solid angles)."""
    levels, _ = baker.radiance_chain(load_panorama(name))
    small = levels[4]                        # 64x32, the solid-angle-exact reduction of the source
    b = mipsbake.Baker("opencl")
    b.rt, b.gpu = baker.rt, baker
    opts = mipsbake.PrefilterOptions("equirect").resolved(32)
    chain = b.radiance_chain(small)
    out, methods = b.prefilter(chain, opts)
    for lvl, s, r in zip(out, opts["sizes"], opts["roughness"]):
        ref = mips.prefilter_bruteforce(small.astype(np.float64), mips.layout_dirs("equirect", s), r)
        assert mips.relative_rmse(lvl, ref) < 0.02, (name, r, mips.relative_rmse(lvl, ref))


def test_prefiltered_mean_close_to_source_mean(baker, load_panorama):
    for name in ("studio", "sunset"):
        levels, dev = baker.radiance_chain(load_panorama(name))
        small = levels[3]   # 128x64
        b = mipsbake.Baker("opencl")
        b.rt, b.gpu = baker.rt, baker
        chain = b.radiance_chain(small)
        opts = mipsbake.PrefilterOptions("equirect").resolved(64)
        out, _ = b.prefilter(chain, opts)
        m0 = mips.solid_angle_mean(small)
        for lvl in out:
            assert np.abs(mips.solid_angle_mean(lvl) / m0 - 1).max() < 0.01, name


def test_dfg_table(baker):
    t = baker.dfg(64, 512)
    ref = mips.dfg_reference(64, 512)
    assert np.all(np.isfinite(t)) and np.all(t >= 0) and np.all(t <= 1)
    assert np.all(t.sum(-1) <= 1 + 1e-6)
    assert np.abs(t[0, -1] - [1, 0]).max() < 1e-3          # NoV = 1, r = 0
    assert np.all(np.isfinite(t[:, 0])) and np.all(np.isfinite(t[0, :]))   # NoV = 0, r = 0
    assert np.abs(t - ref).max() < 1e-4
    # r = 0 row is Schlick's split exactly: A = 1 - (1-NoV)^5, B = (1-NoV)^5
    nov = np.maximum(np.arange(64) / 63, 1e-4)
    assert np.abs(t[0, :, 1] - (1 - nov) ** 5).max() < 1e-4
    ms = baker.dfg(64, 512, multiscatter=True)
    assert np.abs(ms[..., 0] - t[..., 1]).max() < 1e-5 and np.abs(ms[..., 1] - t.sum(-1)).max() < 1e-5


def test_dfg_white_furnace_energy_below_one_and_converges(baker):
    """A + B is the single-scattering directional albedo of a white (F0 = 1) GGX surface: <= 1,
    1 at r = 0, and falls with roughness at grazing angles; the table converges with samples."""
    lo = baker.dfg(32, 4096)          # the default sample count (measured max error: 64: 5.5%, 256: 2.6%, 1024: 1.2%, 4096: 0.5%)
    hi = baker.dfg(32, 65536)
    assert np.abs(lo - hi).max() < 0.01
    e = hi.sum(-1)
    assert np.all(e <= 1 + 1e-4) and np.abs(e[0, 1:] - 1).max() < 1e-3
    assert e[-1, 5] < e[0, 5]
