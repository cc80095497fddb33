"""Every warp against its own pdf with a chi-square goodness-of-fit test over the sphere, on the
numpy side and the OpenCL side (as Mitsuba 3's ChiSquareTest): cells of equal solid angle in
(cos theta, phi), expected counts from the pdf integrated over each cell, cells with fewer than 5
expected samples pooled, and a failure on negative or excess mass. The environment sampler runs
on city. The p-value threshold is 0.01 over the whole family (Sidak-corrected per test)."""

import numpy as np
import pytest
from scipy import stats

from iblbake.core import conventions, sampling
from iblbake.core.metrics import LUMINANCE

N = 200_000
CELLS_T, CELLS_P = 24, 48          # cos theta x phi cells over the sphere
SUB = 10                           # pdf quadrature points per cell and axis
TESTS = 12
ALPHA = 1 - (1 - 0.01) ** (1 / TESTS)


def cell_edges():
    return np.linspace(-1, 1, CELLS_T + 1), np.linspace(-np.pi, np.pi, CELLS_P + 1)


def histogram(d):
    ct, ph = cell_edges()
    d = np.asarray(d, np.float64)
    h, _, _ = np.histogram2d(np.clip(d[:, 2], -1, 1), np.arctan2(d[:, 1], d[:, 0]), bins=[ct, ph])
    return h


def expected(pdf):
    """N x the pdf integrated over every cell (midpoint rule on SUB x SUB parts of equal area)."""
    ct, ph = cell_edges()
    dz, dp = (ct[1] - ct[0]) / SUB, (ph[1] - ph[0]) / SUB
    z = (ct[:-1, None] + (np.arange(SUB) + 0.5) * dz).reshape(-1)
    p = (ph[:-1, None] + (np.arange(SUB) + 0.5) * dp).reshape(-1)
    zz, pp = np.meshgrid(z, p, indexing="ij")
    s = np.sqrt(np.maximum(0, 1 - zz ** 2))
    d = np.stack([s * np.cos(pp), s * np.sin(pp), zz], -1)
    vals = pdf(d.reshape(-1, 3)).reshape(zz.shape) * dz * dp
    return vals.reshape(CELLS_T, SUB, CELLS_P, SUB).sum((1, 3)) * N


def chi2_test(observed, exp, name):
    mass = exp.sum() / N
    assert (exp >= 0).all(), f"{name}: negative pdf"
    assert mass < 1.0 + 2e-3, f"{name}: pdf mass {mass} > 1"   # beyond the cell quadrature's own error
    o, e = observed.reshape(-1), exp.reshape(-1)
    order = np.argsort(e)
    o, e = o[order], e[order]
    small = e < 5                    # pooled into one cell
    obs = np.append(o[~small], o[small].sum())
    ex = np.append(e[~small], e[small].sum())
    keep = ex > 0
    obs, ex = obs[keep], ex[keep] * obs.sum() / ex[keep].sum()
    chi2 = ((obs - ex) ** 2 / ex).sum()
    p = stats.chi2.sf(chi2, len(ex) - 1)
    print(f"{name}: chi2 {chi2:.1f} on {len(ex) - 1} dof, p = {p:.3g}, mass {mass:.5f}")
    assert p > ALPHA, f"{name}: samples do not follow the pdf (p = {p:.3g})"
    assert abs(mass - 1) < 5e-3, f"{name}: pdf integrates to {mass}"


def uniforms(n=N, dims=2, seed=5):
    return np.random.default_rng(seed).random((n, dims))


COS_MAX = 1 - 4 / CELLS_T           # on a cell edge: the quadrature sees no partial cell
VIEW = np.array([np.sin(1.1), 0.0, np.cos(1.1)])


def warps(alpha=0.5):
    nov = VIEW[2]

    def vndf_pdf(d):
        h = d + VIEW
        h /= np.linalg.norm(h, axis=-1, keepdims=True)
        voh, noh = h @ VIEW, h[:, 2]
        pdf = sampling.pdf_ggx_vndf(nov, noh, voh, alpha) / (4 * np.maximum(voh, 1e-12))
        return np.where((voh > 0) & (noh > 0), pdf, 0.0)   # reflections below the horizon are samples too

    return {
        "cosine hemisphere": (lambda u: sampling.sample_cosine_hemisphere(u),
                              lambda d: sampling.pdf_cosine_hemisphere(d[:, 2]), 0, 0.0),
        "uniform cone": (lambda u: sampling.sample_uniform_cone(u, COS_MAX),
                         lambda d: np.where(d[:, 2] >= COS_MAX, sampling.pdf_uniform_cone(COS_MAX), 0.0), 1, COS_MAX),
        "GGX half-vector": (lambda u: sampling.sample_ggx_half(u, alpha),
                            lambda d: sampling.pdf_ggx_half(d[:, 2], alpha) * (d[:, 2] > 0), 2, alpha),
        "GGX visible normals": (lambda u: _reflect(sampling.sample_ggx_vndf(np.broadcast_to(VIEW, (len(u), 3)), alpha, u)),
                                vndf_pdf, 3, alpha),
    }


def _reflect(h):
    return 2 * (h @ VIEW)[:, None] * h - VIEW


@pytest.mark.parametrize("name", list(warps()))
def test_warp_numpy_chi2(name):
    sample, pdf, _, _ = warps()[name]
    chi2_test(histogram(sample(uniforms())), expected(pdf), f"numpy {name}")


@pytest.mark.parametrize("name", list(warps()))
def test_warp_opencl_chi2(rt, name):
    sample, pdf, kind, param = warps()[name]
    u = uniforms().astype(np.float32)
    out = rt.empty(N * 16)
    rt.launch("selftest.cl", "t_warp", {"SH_BANDS": 3}, (N,), {}, kind=kind, param=param,
              vl=np.append(VIEW, 0.0), u=rt.to_device(u), out=out)
    d = rt.read(out, (N, 4))[:, :3]
    chi2_test(histogram(d), expected(pdf), f"OpenCL {name}")


def test_warp_pairs_agree_between_numpy_and_opencl(rt):
    u = uniforms(4096).astype(np.float32)
    for name, (sample, _, kind, param) in warps().items():
        out = rt.empty(len(u) * 16)
        rt.launch("selftest.cl", "t_warp", {"SH_BANDS": 3}, (len(u),), {}, kind=kind, param=param,
                  vl=np.append(VIEW, 0.0), u=rt.to_device(u), out=out)
        got = rt.read(out, (len(u), 4))[:, :3]
        assert np.abs(got - sample(u.astype(np.float64))).max() < 2e-5, name


def expected_env(dist):
    """N x the environment's pdf table integrated exactly over every cell: a texel is a rectangle in
    (cos theta, phi) too (rows between cos(pi j / h) and cos(pi (j + 1) / h); the test frame's phi
    = 2 pi u - pi / 2, wrapped), so a cell's probability is the sum over texels of the pdf times
    the solid angle the two share. (The midpoint rule of expected() misses the jumps between the
    compensated pdf's zero and non-zero texels by more than the test's noise.)"""
    ct, ph = cell_edges()
    h, w = dist.height, dist.width

    def overlap(a0, a1, b0, b1):      # lengths shared by intervals [a0, a1] (rows) and [b0, b1] (columns)
        return np.clip(np.minimum(a1[:, None], b1[None, :]) - np.maximum(a0[:, None], b0[None, :]), 0, None)
    z = np.cos(np.pi * np.arange(h + 1) / h)
    rows = overlap(ct[:-1], ct[1:], z[1:], z[:-1])                            # (cells, texel rows)
    p0 = 2 * np.pi * np.arange(w) / w - np.pi / 2
    cols = sum(overlap(ph[:-1], ph[1:], p0 + s, p0 + s + 2 * np.pi / w) for s in (0.0, -2 * np.pi))
    return rows @ dist.pdf.astype(np.float64) @ cols.T * N


@pytest.fixture(scope="module")
def city_small(load_panorama):
    img = load_panorama("city")
    return img[::4, ::4].copy()              # 256 x 128 texels: the sun still dominates


@pytest.mark.external
def test_environment_sampler_numpy_chi2(city_small):
    dist = sampling.EnvironmentDistribution(city_small)
    d, _ = dist.sample(uniforms(dims=4))
    chi2_test(histogram(np.stack([d[:, 0], d[:, 2], d[:, 1]], -1)), expected_env(dist), "numpy environment (city)")


@pytest.mark.external
def test_environment_sampler_opencl_chi2(rt, city_small):
    dist = sampling.EnvironmentDistribution(city_small)
    u = uniforms(dims=4).astype(np.float32)
    out = rt.empty(N * 16)
    rt.launch("selftest.cl", "t_env", {"SH_BANDS": 3}, (N,), {}, marginal=rt.to_device(dist.marginal),
              conditional=rt.to_device(dist.conditional), guide=rt.to_device(dist.guide), w=dist.width, h=dist.height, u=rt.to_device(u), out=out)
    r = rt.read(out, (N, 4))
    d = r[:, :3].astype(np.float64)
    chi2_test(histogram(np.stack([d[:, 0], d[:, 2], d[:, 1]], -1)), expected_env(dist), "OpenCL environment (city)")
    _, texels = dist.sample(u.astype(np.float64))
    assert (r[:, 3].astype(np.int64) == texels).mean() > 0.999     # the same texel choice (float32 CDF ties aside)


def test_guide_tables_pick_the_whole_rows_bin(rt):
    """sample_env searches the marginal and a row between two entries of their guide tables
    (core/sampling.py cdf_guides): for every u the texel is the one a search of the whole CDFs
    finds (the twin's searchsorted), on a panorama with a sun (four texels hold most of the CDF),
    a black row (its uniform CDF) and black columns (flat runs), at random u and at u on the
    guides' own steps."""
    rng = np.random.default_rng(3)
    img = rng.gamma(0.3, size=(64, 96, 3)).astype(np.float32)
    img[10:12, 40:42] = 5e4
    img[30] = 0.0
    img[:, 60:80] = 0.0
    dist = sampling.EnvironmentDistribution(img)
    u = uniforms(n=20_000, dims=4, seed=9).astype(np.float32)
    u[:1024, 1] = np.arange(1024, dtype=np.float32) / 1024          # every step of the guides and between
    u[1024:2048, 0] = np.arange(1024, dtype=np.float32) / 1024
    g = np.minimum((u[:, :2] * sampling.ENV_GUIDE_BINS).astype(np.int64), sampling.ENV_GUIDE_BINS - 1)
    _, texels = dist.sample(u.astype(np.float64))
    rows, cols = texels // dist.width, texels % dist.width
    assert dist.guide.shape == (dist.height + 1, sampling.ENV_GUIDE_BINS + 1)
    assert ((dist.guide[rows, g[:, 1]] <= cols) & (cols <= dist.guide[rows, g[:, 1] + 1])).all()
    marginal = dist.guide[dist.height]
    assert ((marginal[g[:, 0]] <= rows) & (rows <= marginal[g[:, 0] + 1])).all()
    out = rt.empty(len(u) * 16)
    rt.launch("selftest.cl", "t_env", {"SH_BANDS": 3}, (len(u),), {}, marginal=rt.to_device(dist.marginal),
              conditional=rt.to_device(dist.conditional), guide=rt.to_device(dist.guide), w=dist.width,
              h=dist.height, u=rt.to_device(u), out=out)
    got = rt.read(out, (len(u), 4))[:, 3].astype(np.int64)
    assert np.array_equal(got, texels), (got != texels).sum()


def kernel_pdf_env(rt, img, dist):
    """kernels/envmap.h pdf_env of every texel of img (kernels/selftest.cl t_pdf_env), float64."""
    from iblbake.bake.radiance import to_rgba
    rgba = to_rgba(img).reshape(-1, 4)
    out = rt.empty(len(rgba) * 4)
    rt.launch("selftest.cl", "t_pdf_env", {"SH_BANDS": 3}, (len(rgba),), {}, c=rt.to_device(rgba),
              env_norm=dist.norm, out=out)
    return rt.read(out, (len(rgba),)).astype(np.float64)


def test_a_constant_panorama_is_not_compensated(rt):
    """A panorama with nothing above its mean but float32 rounding (constant, or constant to 1e-6)
    is sampled by luminance (offset 0): the kernels' pdf (a float32 difference, off by ~1e-7 of the
    luminance) divided by a compensated total of rounding errors would be off by orders of
    magnitude. Where a tenth of the light stands above the mean it is compensated."""
    rng = np.random.default_rng(2)
    base = np.full((32, 64, 3), 0.5, np.float32)
    for img in (base, base + rng.normal(0, 1e-6, base.shape).astype(np.float32)):
        dist = sampling.EnvironmentDistribution(img)
        assert dist.offset == 0
        got = kernel_pdf_env(rt, img, dist)
        np.testing.assert_allclose(got, dist.pdf.reshape(-1), rtol=1e-6)
        np.testing.assert_allclose(got, 1 / (4 * np.pi), rtol=1e-5)
    lit = base.copy()
    lit[:4] *= 3                               # the top rows: about a tenth of the light above the mean
    assert sampling.EnvironmentDistribution(lit).offset > 0.5


@pytest.mark.parametrize("sun", [3e4, 30.0])
def test_kernel_pdf_from_luminance_is_the_tables(rt, sun):
    """kernels/envmap.h pdf_env ((a texel's luminance - the panorama's mean, floored at 0) / total:
    EnvironmentDistribution.norm) is the float64-built pdf table the sampler's CDFs come from, to
    float32 rounding of the luminance, on a panorama with black texels, negative and mixed-sign ones
    (their luminance is floored at 0 in both) and a sun that holds most of the light (3e4: every
    other texel below the mean, pdf 0) or not (30: a third of the texels above the mean, many
    near it); and the pdf integrates to one over the sphere."""
    rng = np.random.default_rng(5)
    img = rng.gamma(0.5, size=(48, 96, 3)).astype(np.float32)
    img[5:7, 20:22] = sun
    img[30, :40] = 0.0
    img[31, :10] = -1.0
    img[32, :10] = [2.0, -0.5, 0.1]
    dist = sampling.EnvironmentDistribution(img)
    got = kernel_pdf_env(rt, img, dist)
    want = dist.pdf.reshape(-1).astype(np.float64)
    lum = np.maximum(img.reshape(-1, 3).astype(np.float64) @ LUMINANCE, 0.0)
    above = (want > 0).mean()
    assert (0.3 < above < 0.4) if sun == 30 else (above == 4 / want.size)
    # the difference of two float32 luminances: rounding of the luminance, not of the pdf
    err = np.abs(got - want) / (np.maximum(lum, float(dist.offset)) * float(dist.norm[0]))
    assert err.max() < 6e-7, err.max()        # measured 0 (sun 3e4) and 1.8e-7 (sun 30) on PoCL
    omega = conventions.equirect_solid_angles(dist.width, dist.height).reshape(-1)
    assert abs((got * omega).sum() - 1) < 1e-5


@pytest.mark.external
def test_environment_pdf_integrates_to_one(city_small):
    dist = sampling.EnvironmentDistribution(city_small)
    omega = conventions.equirect_solid_angles(dist.width, dist.height)
    assert abs((dist.pdf.astype(np.float64) * omega).sum() - 1) < 1e-5


def test_power_heuristic_weights_sum_to_one():
    a, b = np.random.default_rng(2).random((2, 1000)) * 10
    assert np.allclose(sampling.power_heuristic(a, b) + sampling.power_heuristic(b, a), 1.0)
    assert sampling.power_heuristic(np.inf, 1.0) == 1.0 and sampling.power_heuristic(0.0, 1.0) == 0.0


@pytest.mark.parametrize("replicates", [1, 2])
def test_sampler_kernel_matches_twin(rt, replicates):
    """kernels/sampler.h sampler_replicate and sampler_2d against core/sampling.Sampler: the
    same 24-bit values, bit for bit, for 12 dimensions of samples of several G-buffer samples."""
    rng = np.random.default_rng(3)
    gid = rng.integers(0, 2 ** 32, 500, dtype=np.uint64).astype(np.uint32)
    k = rng.integers(0, 2 ** 20, 500).astype(np.uint32)
    out = rt.empty(4 * 500 * 12)
    rt.launch("selftest.cl", "t_sampler", {}, (500,), {}, seed=np.uint32(12345), gid=rt.to_device(gid),
              k=rt.to_device(k), replicates=np.int32(replicates), ndim=np.int32(12), out=out)
    got = rt.read(out, (500, 12))
    sp = sampling.Sampler.replicate(12345, gid, k, replicates)
    want = np.concatenate([sp.next_2d() for _ in range(6)], -1)
    assert np.array_equal(got.astype(np.float64), want)
