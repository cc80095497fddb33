"""Radiance chain, prefiltered chain, DFG: kernels against numpy twins and closed forms."""

import numpy as np
import pytest

from iblbake.bake import dfg
from iblbake.bake import layouts
from iblbake.core import metrics
from iblbake.bake import mips
from iblbake.bake import prefilter
from iblbake.bake import radiance
from iblbake.bake import mips as mipsbake

from tests.helpers import rel_err


@pytest.fixture(scope="module")
def baker(rt):
    return mips.OpenCLBaker(rt)


@pytest.mark.parametrize("w,h", [(64, 32), (7, 3), (1, 1), (2, 1), (30, 17)])
def test_radiance_chain_constant_and_mean_preserving(baker, w, h):
    img = np.full((h, w, 3), 2.0, np.float32)
    levels, _ = baker.radiance_chain(img)
    ref = radiance.radiance_chain_twin(img)
    assert [l.shape for l in levels] == [r.shape for r in ref]
    assert levels[-1].shape[0] == 1
    for l in levels:
        assert np.abs(l / 2.0 - 1).max() < 1e-4
    rnd = np.random.default_rng(0).random((h, w, 3)).astype(np.float32) * 5
    levels, _ = baker.radiance_chain(rnd)
    ref = radiance.radiance_chain_twin(rnd)
    m0 = radiance.solid_angle_mean(ref[0])
    for a, b in zip(levels, ref):
        assert rel_err(a, b) < 1e-5
        assert np.abs(radiance.solid_angle_mean(b) / m0 - 1).max() < 1e-12
        assert np.abs(radiance.solid_angle_mean(a) / m0 - 1).max() < 1e-5


@pytest.mark.external
@pytest.mark.external
def test_radiance_chain_mean_on_real_panoramas(baker, load_panorama):
    for name in ("city", "studio", "sunset", "night"):
        levels, _ = baker.radiance_chain(load_panorama(name))
        m0 = radiance.solid_angle_mean(levels[0])
        for l in levels[1:]:
            assert np.abs(radiance.solid_angle_mean(l) / m0 - 1).max() < 1e-5, name


@pytest.mark.parametrize("layout", ["equirect", "cubemap", "octahedral"])
@pytest.mark.parametrize("method", ["fis", "convolve", "spectral"])
def test_prefiltered_constant_environment_every_layout(rt, layout, method):
    img = np.full((32, 64, 3), 1.5, np.float32)
    b = mipsbake.Baker("opencl")
    b.rt, b.gpu = rt, mips.OpenCLBaker(rt)
    opts = mipsbake.PrefilterOptions(layout, 8, 4, method=method, samples=64).resolved(32)
    chain = b.radiance_chain(img)
    levels, methods = b.prefilter(chain, opts)
    assert methods[0] == "resample" and all(m.startswith(method) for m in methods[1:])
    for lvl in levels:
        assert lvl.shape[:2] == layouts.layout_shape(layout, lvl.shape[1] if layout != "equirect" else lvl.shape[0])
        assert np.abs(lvl / 1.5 - 1).max() < 1e-4


@pytest.mark.parametrize("layout", ["equirect", "cubemap", "octahedral"])
def test_mirror_level_is_the_source_resampled(baker, layout):
    img = np.random.default_rng(1).random((32, 64, 3)).astype(np.float32)
    _, dev = baker.radiance_chain(img)
    got = baker.prefilter_level(dev, layout, 16, 0.0, 1)
    dirs = layouts.layout_dirs(layout, 16)
    from iblbake.core import conventions as cv
    u, v = cv.equirect_uv_from_dir(dirs)
    assert np.abs(got - cv.bilinear_equirect(img.astype(np.float64), u, v)).max() < 1e-3
    if layout == "equirect":
        same = baker.prefilter_level(dev, "equirect", 32, 0.0, 1)
        assert np.abs(same - img).max() < 1e-5


@pytest.mark.slow
@pytest.mark.parametrize("roughness", [0.25, 0.6, 1.0])
def test_opencl_prefilter_matches_numpy(baker, roughness):
    img = np.random.default_rng(2).random((16, 32, 3)).astype(np.float32) * 3
    img[4, 7] = 500.0
    levels, dev = baker.radiance_chain(img)
    chain64 = [l.astype(np.float64) for l in levels]
    for layout in ("equirect", "cubemap"):
        dirs = layouts.layout_dirs(layout, 8)
        got = baker.prefilter_level(dev, layout, 8, roughness, 64, 1.0, True)
        ref = prefilter.prefilter_twin(chain64, dirs, roughness, 64, 1.0, True)
        assert rel_err(got, ref) < 1e-4
        got = baker.convolve_level(levels, layout, 8, roughness)
        ref = prefilter.convolve_twin(chain64, dirs, roughness)
        # float32 sums of ~1e4 weighted terms around a 500x spike: measured <= 1.8e-4
        assert rel_err(got, ref) < 5e-4


@pytest.mark.external
@pytest.mark.external
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
        ref = prefilter.prefilter_bruteforce(small.astype(np.float64), layouts.layout_dirs("equirect", s), r)
        assert metrics.relative_rmse(lvl, ref) < 0.02, (name, r, metrics.relative_rmse(lvl, ref))


@pytest.mark.external
def test_prefiltered_mean_close_to_source_mean(baker, load_panorama):
    for name in ("studio", "sunset"):
        levels, dev = baker.radiance_chain(load_panorama(name))
        small = levels[3]   # 128x64
        b = mipsbake.Baker("opencl")
        b.rt, b.gpu = baker.rt, baker
        chain = b.radiance_chain(small)
        opts = mipsbake.PrefilterOptions("equirect").resolved(64)
        out, _ = b.prefilter(chain, opts)
        m0 = radiance.solid_angle_mean(small)
        for lvl in out:
            assert np.abs(radiance.solid_angle_mean(lvl) / m0 - 1).max() < 0.01, name


def test_dfg_table(baker):
    t = baker.dfg(64, 512)
    ref = dfg.dfg_twin(64, 512)
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


@pytest.mark.slow
def test_dfg_white_furnace_energy_below_one_and_converges(baker):
    """A + B is the single-scattering directional albedo of a white (F0 = 1) GGX surface: <= 1,
    1 at r = 0, and falls with roughness at grazing angles; the table converges with samples."""
    lo = baker.dfg(32, 4096)          # the default sample count (measured max error: 64: 5.5%, 256: 2.6%, 1024: 1.2%, 4096: 0.5%)
    hi = baker.dfg(32, 65536)
    assert np.abs(lo - hi).max() < 0.01
    e = hi.sum(-1)
    assert np.all(e <= 1 + 1e-4) and np.abs(e[0, 1:] - 1).max() < 1e-3
    assert e[-1, 5] < e[0, 5]


# --- spectral: the GGX convolution in the SH domain ----------------------------------------------

def _texel_average_legendre(h: int, w: int):
    """An equirect image whose texels hold the exact texel averages of f(y) = 1 + y + P2(y),
    y = cos(theta): piecewise constant, as every method reads a panorama."""
    t0 = np.pi * np.arange(h) / h
    t1 = np.pi * (np.arange(h) + 1) / h
    c0, c1 = np.cos(t0), np.cos(t1)
    m1 = (c0 ** 2 - c1 ** 2) / 2 / (c0 - c1)          # mean of y over the row's solid angle
    m2 = (c0 ** 3 - c1 ** 3) / 3 / (c0 - c1)          # mean of y^2
    row = 1.0 + m1 + (3.0 * m2 - 1.0) / 2.0
    return np.repeat(row[:, None, None], w, axis=1).repeat(3, axis=2)


def test_spectral_closed_form_at_roughness_one():
    """At alpha = 1, D = 1/pi everywhere, so the lobe is the clamped cosine: its Legendre
    coefficients are k1 = 2/3, k2 = 1/4 (Funk-Hecke). 1 + y + P2(y) must come out as
    1 + (2/3) y + (1/4) P2(y) at every texel of every layout, to 5e-5 absolute at 256 rows:
    the box texels differ from the smooth f by a part the lobe does not average away exactly,
    measured 5.6e-4, 1.4e-4, 3.5e-5, 8.8e-6 at 64, 128, 256, 512 rows (1/h^2, as it must)."""
    from iblbake.bake import spectral
    k = spectral.zonal_coefficients(1.0)
    assert abs(k[1] - 2 / 3) < 1e-9 and abs(k[2] - 0.25) < 1e-9 and abs(k[3]) < 1e-9
    img = _texel_average_legendre(256, 512)
    for layout in ("equirect", "cubemap", "octahedral"):
        dirs = layouts.layout_dirs(layout, 16)
        got = spectral.prefilter_levels(img, [dirs], [1.0])[0]
        y = dirs[..., 1]
        want = 1.0 + (2.0 / 3.0) * y + 0.25 * (3 * y * y - 1) / 2
        assert np.abs(got - want[..., None]).max() < 5e-5, layout


def test_spectral_kernel_coefficients_match_direct_quadrature():
    """k_l against scipy's adaptive quadrature of int K P_l sin / int K sin in float64, for a
    sharp and a medium lobe (1e-10 absolute; measured <= 1e-14)."""
    from scipy import integrate, special
    from iblbake.core import brdf
    from iblbake.bake import spectral
    for r in (0.125, 0.5):
        alpha = r * r
        k = spectral.zonal_coefficients(alpha)
        def kern(t, l):
            return brdf.d_ggx(np.sqrt(0.5 * (1 + np.cos(t))), alpha) * np.cos(t) * np.sin(t) * special.eval_legendre(l, np.cos(t))
        pts = [alpha * f for f in (0.5, 1, 2, 4, 8, 16) if alpha * f < np.pi / 2]
        norm = integrate.quad(kern, 0, np.pi / 2, args=(0,), points=pts, limit=400, epsabs=0, epsrel=1e-12)[0]
        for l in (1, 2, 7, 40, 200):
            if l >= len(k):
                continue
            v = integrate.quad(kern, 0, np.pi / 2, args=(l,), points=pts, limit=2000, epsabs=1e-14, epsrel=1e-11)[0]
            assert abs(k[l] - v / norm) < 1e-10, (r, l)


@pytest.mark.external
@pytest.mark.external
def test_spectral_against_bruteforce(baker, load_panorama):
    """A 32x16 reduction of city (its sun kept: the hardest case) at a sharp, a medium and a rough
    level, one per layout: within 0.3% relative RMSE of the float64 brute force (every texel,
    exact solid angles; measured <= 0.1%, the brute force's own midpoint error)."""
    from iblbake.bake import spectral
    levels, _ = baker.radiance_chain(load_panorama("city"))
    small = levels[5].astype(np.float64)
    for r, layout in ((0.125, "cubemap"), (0.5, "equirect"), (1.0, "octahedral")):
        dirs = layouts.layout_dirs(layout, 8)
        got = spectral.prefilter_levels(small, [dirs], [r])[0]
        ref = prefilter.prefilter_bruteforce(small, dirs, r)
        assert metrics.relative_rmse(got, ref) < 3e-3, (r, layout, metrics.relative_rmse(got, ref))


def test_auto_plan_spectral_then_fallback_and_explicit_error():
    """auto takes spectral for every rough-enough level and falls back where a lobe needs bands
    beyond MAX_LMAX; --method spectral then says which level and what to do."""
    from iblbake.bake import spectral
    from iblbake.errors import InputError
    chain = layouts.radiance_chain_sizes(64, 32)
    opts = mipsbake.PrefilterOptions("equirect", 32, 9).resolved(32)
    methods = mipsbake.plan_methods(chain, {**opts, "convolve_budget": 1e9})
    assert methods == ["resample"] + ["spectral"] * 8
    opts = mipsbake.PrefilterOptions("equirect", 32, 40, min_size=1).resolved(32)   # r_1 = 1/39
    assert not spectral.applicable((1 / 39) ** 2) and spectral.applicable((8 / 39) ** 2)
    methods = mipsbake.plan_methods(chain, {**opts, "convolve_budget": 1e9})
    assert methods[1].startswith("convolve") and methods[-1] == "spectral"
    with pytest.raises(InputError, match="level 1 .*too sharp"):
        mipsbake.plan_methods(chain, {**opts, "method": "spectral", "convolve_budget": 1e9})


def test_spectral_lone_sun_over_black_stays_in_range_and_keeps_energy():
    """One 1e6 texel over black: the exact level is a non-negative mean, so no texel may go below 0
    (the dropped bands ring by ~1e-9 of the sun before the clamp) nor above the sun; the
    solid-angle mean of the sampled level stays the source's (1%; k_0 = 1 keeps it exactly, the
    64x32 level's point samples of a lobe 3 texels wide measure 0.6% at r = 0.125, <= 0.03% from
    r = 0.25) and the brightest texel of each equirect level is the one facing the sun."""
    from iblbake.core import conventions as cv
    from iblbake.bake import spectral
    img = np.zeros((64, 128, 3))
    img[20, 40] = 1e6
    m0 = radiance.solid_angle_mean(img)[0]
    rough = [0.125, 0.25, 0.5, 1.0]
    for layout in ("equirect", "cubemap", "octahedral"):
        out = spectral.prefilter_levels(img, [layouts.layout_dirs(layout, 32)] * 4, rough)
        for r, lvl in zip(rough, out):
            assert lvl.min() >= 0.0 and lvl.max() <= 1e6, (layout, r)
            if layout == "equirect":
                assert abs(radiance.solid_angle_mean(lvl)[0] / m0 - 1) < 0.01, r
                sun = cv.equirect_texel_dirs(128, 64)[20, 40]
                at = np.unravel_index(np.argmax(lvl[..., 0]), lvl.shape[:2])
                assert layouts.layout_dirs("equirect", 32)[at] @ sun > np.cos(np.pi / 32), r


def test_spectral_projects_a_repeated_channel_once():
    """A channel equal to an earlier one (a reflection capture's coverage is prefiltered as grey)
    is projected and synthesised once and copied: channels (a, b, a) give a and b exactly as the
    distinct channels (a, b, c) do, and a again in the third."""
    from iblbake.bake import spectral
    rng = np.random.default_rng(3)
    a, b, c = rng.random((3, 16, 32))
    dirs, rough = [layouts.layout_dirs("equirect", 8)] * 2, [0.5, 1.0]
    twice = spectral.prefilter_levels(np.stack([a, b, a], -1), dirs, rough)
    apart = spectral.prefilter_levels(np.stack([a, b, c], -1), dirs, rough)
    for t, s in zip(twice, apart):
        assert np.abs(t[..., :2] - s[..., :2]).max() <= 1e-12 * s.max()
        assert np.array_equal(t[..., 2], t[..., 0]) and not np.array_equal(s[..., 2], s[..., 0])
