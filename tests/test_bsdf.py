"""The BSDF of every path vertex (kernels/bsdf.h) against its float64 twin (iblbake/core/bsdf.py),
and the twin against what a BSDF must satisfy: Lambert's closed form, each sample's weight and pdf
those of evaluate() at its direction, and the mean sample weight the integral of f NoL over the
hemisphere (importance sampling unbiased for the mixture of lobes)."""

import numpy as np
import pytest

from iblbake.bake import dfg
from iblbake.core import bsdf, conventions
from iblbake.render.twin.surface import diffuse_weight

N = 4096


def unit(x):
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def vertices(seed=3, n=N):
    """Random vertices: materials as the material table holds them (base colour and metallic,
    emission and roughness, the dielectric's F0 and F90), roughness from mirrors (a delta lobe)
    to 1, views from grazing to normal, directions over the whole sphere."""
    rng = np.random.default_rng(seed)
    base = rng.random((n, 3))
    metallic = np.where(rng.random(n) < 0.3, 1.0, np.where(rng.random(n) < 0.5, 0.0, rng.random(n)))
    rough = rng.random(n)
    rough[: n // 16] = 0.005                      # alpha 2.5e-5 < DELTA_ALPHA: mirrors
    rough[n // 16: n // 8] = rng.uniform(0.011, 0.05, n // 16)    # near-mirror lobes
    spec = np.where(rng.random(n) < 0.1, 0.0, 1.0)                # KHR_materials_specular 0: Lambert
    c = np.concatenate([np.full((n, 3), 0.04) * spec[:, None], spec[:, None]], 1)
    mat = np.stack([np.concatenate([base, metallic[:, None]], 1),
                    np.concatenate([np.zeros((n, 3)), rough[:, None]], 1), c], 1)
    nrm = unit(rng.normal(size=(n, 3)))
    t, b = conventions.tangent_frame(nrm)
    cos_v = np.where(rng.random(n) < 0.1, rng.uniform(1e-3, 0.05, n), rng.uniform(0.05, 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(1 - cos_v ** 2)
    v = t * (s * np.cos(phi))[:, None] + b * (s * np.sin(phi))[:, None] + nrm * cos_v[:, None]
    mat32 = mat.astype(np.float32).astype(np.float64)
    v, nrm = v.astype(np.float32).astype(np.float64), nrm.astype(np.float32).astype(np.float64)
    l = unit(rng.normal(size=(n, 3))).astype(np.float32).astype(np.float64)
    u = rng.random((n, 3)).astype(np.float32).astype(np.float64)
    return mat32, v, nrm, l, u


def material(mat, v, n):
    """core/bsdf.py's Material of material rows (kernels/surface.h material_from) at NoV."""
    base, metallic, rough, c = mat[:, 0, :3], mat[:, 0, 3], mat[:, 1, 3], mat[:, 2]
    f0 = c[:, :3] + (base - c[:, :3]) * metallic[:, None]
    f90 = np.repeat((c[:, 3] + (1 - c[:, 3]) * metallic)[:, None], 3, 1)
    nov = np.maximum((n * v).sum(1), 1e-4)
    return bsdf.Material(f0, f90, rough ** 2, diffuse_weight(base, metallic, rough, f0, f90, nov)), nov


def kernel(rt, mat, v, n, l, u, ps, diffuse, specular):
    f4 = lambda a: np.ascontiguousarray(a, np.float32)        # noqa: E731
    vn = np.stack([np.concatenate([v, ps[:, None]], 1), np.concatenate([n, np.zeros((len(n), 1))], 1)], 1)
    lu = np.stack([np.concatenate([l, u[:, :1]], 1), np.concatenate([u[:, 1:], np.zeros((len(u), 2))], 1)], 1)
    out = rt.empty(len(n) * 64)
    rt.launch("selftest.cl", "t_bsdf", {"SH_BANDS": 3}, (len(n),), {}, mat=rt.to_device(f4(mat.reshape(-1, 4))),
              vn=rt.to_device(f4(vn.reshape(-1, 4))), lu=rt.to_device(f4(lu.reshape(-1, 4))), diffuse=int(diffuse),
              specular=int(specular), out=out)
    return rt.read(out, (len(n), 4, 4)).astype(np.float64)


def rel(a, b, floor):
    return np.abs(a - b) / np.maximum(np.abs(b), floor)


@pytest.mark.parametrize("terms", [(1, 1), (1, 0), (0, 1)])
def test_kernel_bsdf_is_the_twins(rt, terms):
    """bsdf_eval, bsdf_pdf, bsdf_sample and specular_probability against the twin on 4096 random
    vertices (mirrors, near-mirror lobes, grazing views, Lambert and metals), each of the terms
    the reference's first vertex asks for and both together. Bounds a few times the measured
    worst (float32 against float64): specular_probability 1e-6 (measured 1.6e-7); f NoL 2e-5
    (measured 5.3e-6) and pdf 6e-5 (measured 1.8e-5) relative where above 1e-3 of their scale; a
    sample's direction 3e-5 (measured 8.5e-6), its pdf 2e-3 (measured 7.5e-4), at grazing views
    (NoV < 0.05) 5e-2 (measured 1.3e-2: there h = normalize(v + l) divides l's float32 error by
    |v + l| = 2 NoV, a percent of a near-mirror lobe's width), its weight f NoL / pdf 2e-4
    relative (measured 4.9e-5) where the sample leaves the surface at NoL > 0.01 (at NoL 3e-4 the
    direction's 6e-6 is 2% of NoL, and of the weight: measured 3.4e-3). Both pick the same lobe
    (the kernel's ps is handed to the twin). The twin's D is the kernel's sin^2 / cos^2 form: with
    1 - NoH, the float32 normal's 6e-8 off unit length made it 10x off on lobes of alpha 1e-4."""
    diffuse, specular = terms
    mat, v, n, l, u = vertices()
    mt, nov = material(mat, v, n)
    ps = bsdf.specular_probability(mt, nov, diffuse, specular)
    got = kernel(rt, mat, v, n, l, u, ps, diffuse, specular)
    e_ps = np.abs(got[:, 3, 3] - ps).max()
    assert e_ps < 1e-6, e_ps
    ps = got[:, 3, 3]                      # the kernel's, so both pick the same lobe
    f, pdf = bsdf.evaluate(mt, v, n, nov, l, ps, diffuse, specular)
    scale_f, scale_p = np.abs(f).max(), pdf.max()
    e_f = rel(got[:, 0, :3], f, 1e-3 * scale_f).max()
    e_p = rel(got[:, 0, 3], pdf, 1e-3 * scale_p).max()
    assert np.array_equal(got[:, 1, 0], got[:, 0, 3])          # bsdf_pdf is bsdf_eval's pdf
    w, ls, ps_ = bsdf.sample(mt, v, n, nov, ps, diffuse, specular, u[:, 0], u[:, 1:])
    e_l = np.abs(got[:, 3, :3] - ls).max()
    mirror = np.isinf(ps_)
    assert np.array_equal(np.isinf(got[:, 2, 3]), mirror)
    away = (n * ls).sum(1) > 1e-2
    e_w = rel(got[away, 2, :3], w[away], 1e-3 * np.abs(w).max()).max()
    e_sp = rel(got[~mirror, 2, 3], ps_[~mirror], 1e-3 * ps_[~mirror].max())
    grazing = nov[~mirror] < 0.05
    e_sp, e_sp_grazing = e_sp[~grazing].max(), e_sp[grazing].max()
    print(f"terms {terms}: ps {e_ps:.2e}, f {e_f:.2e}, pdf {e_p:.2e}, direction {e_l:.2e}, weight {e_w:.2e}, "
          f"sample pdf {e_sp:.2e} (NoV < 0.05: {e_sp_grazing:.2e}; {mirror.sum()} mirrors)")
    assert e_f < 2e-5 and e_p < 6e-5 and e_l < 3e-5 and e_w < 2e-4 and e_sp < 2e-3 and e_sp_grazing < 5e-2


@pytest.mark.parametrize("terms", [(1, 1), (1, 0), (0, 1)])
def test_the_bsdfs_sampling_covers_its_value(rt, terms):
    """Wherever the terms asked for reflect light (f NoL > 0, a delta lobe aside) the BSDF's own
    sampling has a positive pdf, in the kernel and the twin: the panorama's compensated sampling
    draws no texel at or below its mean (core/sampling.py env_sampling_tables) and leaves those to
    the BSDF, so a direction neither strategy can draw would be light lost. The random vertices,
    and a black metal (F0 = 0, F90 = 1) and a dielectric with specular colour 0 seen head-on (NoV
    = 1: F(NoV) = 0, which once gave the specular term alone no sampling of its own)."""
    diffuse, specular = terms
    mat, v, n, l, u = vertices(7, 1024)
    k = 64
    mat[:k] = 0.0
    mat[:k, 0, 3] = np.where(np.arange(k) < k // 2, 1.0, 0.0)          # metallic: black metal, or
    mat[k // 2:k, 2, 3] = 1.0                                             # specular 1, colour 0
    mat[:k, 1, 3] = np.linspace(0.2, 1.0, k)                              # roughness
    n[:k] = v[:k] = [0.0, 1.0, 0.0]
    mt, nov = material(mat, v, n)
    assert (nov[:k] == 1).all() and (bsdf.specular_probability(mt, nov, True, True)[:k] == 0).all()
    ps = bsdf.specular_probability(mt, nov, diffuse, specular)
    got = kernel(rt, mat, v, n, l, u, ps, diffuse, specular)
    f, pdf = bsdf.evaluate(mt, v, n, nov, l, ps, diffuse, specular)
    lit = f.max(1) > 0
    assert lit[:k].sum() > k // 4 if specular else True
    assert (pdf[lit] > 0).all(), np.flatnonzero(lit & ~(pdf > 0))[:8]
    lit_k = got[:, 0, :3].max(1) > 0
    assert (got[lit_k, 0, 3] > 0).all(), np.flatnonzero(lit_k & ~(got[:, 0, 3] > 0))[:8]
    assert np.abs(got[:, 3, 3] - ps).max() < 1e-6


def test_lambert_is_its_closed_form():
    """The diffuse term alone (ps 0): f NoL = kD NoL, pdf NoL / pi, every sample's weight kD pi."""
    mat, v, n, l, u = vertices(5, 512)
    mt, nov = material(mat, v, n)
    f, pdf = bsdf.evaluate(mt, v, n, nov, l, 0.0, True, False)
    nol = np.maximum((n * l).sum(1), 0)
    assert np.allclose(f, mt.kd * nol[:, None], rtol=1e-13, atol=0) and np.allclose(pdf, nol / np.pi, rtol=1e-13)
    w, ls, p = bsdf.sample(mt, v, n, nov, 0.0, True, False, u[:, 0], u[:, 1:])
    up = (n * ls).sum(1) > 0
    assert np.allclose(w[up], mt.kd[up] * np.pi, rtol=1e-9) and np.allclose(p, np.maximum((n * ls).sum(1), 0) / np.pi)


def test_samples_carry_evaluate_s_weight_and_pdf():
    """A sample's weight is evaluate()'s f NoL over its pdf at the sample's direction and its pdf
    is pdf() there (the mixture of both lobes at specular_probability), mirrors apart (pdf inf,
    weight F(NoV) / ps)."""
    mat, v, n, l, u = vertices(7)
    mt, nov = material(mat, v, n)
    ps = bsdf.specular_probability(mt, nov, True, True)
    w, ls, p = bsdf.sample(mt, v, n, nov, ps, True, True, u[:, 0], u[:, 1:])
    f, pe = bsdf.evaluate(mt, v, n, nov, ls, ps, True, True)
    fin = np.isfinite(p) & (p > 0)
    assert fin.sum() > N // 2
    assert np.allclose(w[fin] * p[fin, None], f[fin], rtol=1e-10, atol=1e-300)
    assert np.allclose(bsdf.pdf(mt, v, n, nov, ls, ps, True, True)[fin], p[fin], rtol=1e-12)
    mirror = np.isinf(p)
    assert mirror.any() and (mt.alpha[mirror] < bsdf.DELTA_ALPHA).all()
    f_nov = mt.f0[mirror] + (mt.f90[mirror] - mt.f0[mirror]) * (1 - nov[mirror, None]) ** 5
    assert np.allclose(w[mirror], f_nov / ps[mirror, None], rtol=1e-12)


@pytest.mark.parametrize("rough,metallic,cos_v", [(0.3, 0.0, 0.8), (0.6, 1.0, 0.3), (0.15, 0.5, 0.95),
                                                   (1.0, 0.0, 0.1)])
def test_mean_weight_is_the_integral_of_f_nol(rough, metallic, cos_v):
    """Importance sampling the mixture is unbiased: the mean of 200,000 samples' weights equals
    the integral of f NoL over the hemisphere (midpoint quadrature in (cos theta, phi) on
    1024 x 1024 cells, converged to 1e-4) within 4 standard errors."""
    base = np.array([[0.8, 0.5, 0.2]])
    mat = np.array([[[*base[0], metallic], [0, 0, 0, rough], [0.04, 0.04, 0.04, 1.0]]])
    n = np.array([[0.0, 0.0, 1.0]])
    v = np.array([[np.sqrt(1 - cos_v ** 2), 0.0, cos_v]])
    mt, nov = material(mat, v, n)
    ps = bsdf.specular_probability(mt, nov, True, True)
    m = 200_000
    rep = lambda a: np.repeat(a, m, 0)          # noqa: E731
    mtm = bsdf.Material(*(rep(x) for x in mt))
    u = np.random.default_rng(11).random((m, 3))
    w, _, _ = bsdf.sample(mtm, rep(v), rep(n), rep(nov), rep(ps), True, True, u[:, 0], u[:, 1:])
    k = 1024
    z = (np.arange(k) + 0.5) / k
    phi = (np.arange(k) + 0.5) / k * 2 * np.pi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    s = np.sqrt(1 - zz ** 2)
    d = np.stack([s * np.cos(pp), s * np.sin(pp), zz], -1).reshape(-1, 3)
    q = len(d)
    f, _ = bsdf.evaluate(bsdf.Material(*(np.repeat(x, q, 0) for x in mt)), np.repeat(v, q, 0), np.repeat(n, q, 0),
                         np.repeat(nov, q, 0), d, np.repeat(ps, q, 0), True, True)
    integral = f.sum(0) * (2 * np.pi / k / k)
    mean, err = w.mean(0), w.std(0) / np.sqrt(m)
    print(f"rough {rough} metallic {metallic} NoV {cos_v}: mean {mean} integral {integral} "
          f"({np.abs(mean - integral).max() / err.max():.2f} standard errors)")
    assert (np.abs(mean - integral) < 4 * err + 1e-4 * integral).all()


def hemisphere(k):
    """Midpoint cells of (cos theta, phi) about +z, k x 2k: their directions and solid angle (equal,
    2 pi / (2 k^2))."""
    z = (np.arange(k) + 0.5) / k
    phi = (np.arange(2 * k) + 0.5) / (2 * k) * 2 * np.pi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    s = np.sqrt(1 - zz ** 2)
    return np.stack([s * np.cos(pp), s * np.sin(pp), zz], -1).reshape(-1, 3), np.pi / k ** 2


def one_vertex(base, metallic, rough, cos_v, specular=1.0):
    """A vertex with normal +z seen from (sin, 0, cos): its material rows, v, n (1, ...)."""
    mat = np.array([[[*base, metallic], [0, 0, 0, rough], [0.04 * specular] * 3 + [specular]]])
    return mat, np.array([[np.sqrt(1 - cos_v ** 2), 0.0, cos_v]]), np.array([[0.0, 0.0, 1.0]])


def quadrature(mt, v, n, nov, ps, diffuse, specular, k=512):
    """The integrals over the hemisphere of f NoL and of the pdf (one vertex, k x 2k cells)."""
    d, dw = hemisphere(k)
    f, pdf = bsdf.evaluate(mt, v, n, nov, d, ps, diffuse, specular)
    return f.sum(0) * dw, pdf.sum() * dw


WHITE = (1.0, 1.0, 1.0)


@pytest.mark.parametrize("cos_v", [1.0, 0.5, 0.1])
def test_white_furnace_lambert(rt, cos_v):
    """A white Lambert surface (KHR_materials_specular 0: kD = 1 / pi) returns all it receives:
    the quadrature of f NoL is 1 (the midpoint rule is exact in cos theta), and every kernel
    sample's weight f NoL / pdf is 1 to float32 rounding (measured: exactly 1)."""
    mat, v, n = one_vertex(WHITE, 0.0, 0.5, cos_v, specular=0.0)
    mt, nov = material(mat, v, n)
    ps = bsdf.specular_probability(mt, nov, True, True)
    assert ps[0] == 0.0 and np.allclose(mt.kd, 1 / np.pi, rtol=1e-15)
    e, p = quadrature(mt, v, n, nov, ps, True, True, 256)
    assert np.abs(e - 1).max() < 1e-12 and abs(p - 1) < 1e-12
    m = 4096
    u = np.random.default_rng(1).random((m, 3))
    rep = lambda a: np.repeat(a, m, 0)         # noqa: E731
    got = kernel(rt, rep(mat), rep(v), rep(n), rep(v), u, rep(ps), True, True)
    err = np.abs(got[:, 2, :3] - 1).max()
    print(f"NoV {cos_v}: white Lambert, kernel weights within {err:.1e} of 1")
    assert err < 5e-7


@pytest.fixture(scope="module")
def dfg_table():
    return dfg.dfg_twin(5, 1 << 16)              # roughness and NoV at 0, 0.25, ..., 1


@pytest.mark.parametrize("rough", [0.5, 0.75, 1.0])
def test_white_furnace_ggx(rt, dfg_table, rough):
    """A white metal (F = 1) keeps the energy single-scattering GGX keeps, its directional albedo
    E(NoV) = the integral of D V NoL: at most 1, and the same from three estimators: this BSDF's
    quadrature, the split sum's DFG table A + B (bake/dfg.py: half vectors from 2^16 Hammersley
    points, an independent path; within 1e-4, measured 5e-5) and the mean of 65,536 kernel
    samples' weights (4 standard errors). At roughness 1 and NoV 1 (D = 1 / pi, V = 1 / (2 (1 +
    NoL))) E = the integral of NoL / (1 + NoL) over [0, 1] = 1 - ln 2."""
    m = 1 << 16
    u = np.random.default_rng(2).random((m, 3))
    rep = lambda a: np.repeat(a, m, 0)         # noqa: E731
    for cos_v in (1.0, 0.5, 0.25):
        mat, v, n = one_vertex(WHITE, 1.0, rough, cos_v)
        mt, nov = material(mat, v, n)
        ps = bsdf.specular_probability(mt, nov, True, True)
        assert ps[0] == 1.0 and np.allclose(mt.f0, 1) and np.allclose(mt.kd, 0)
        e, _ = quadrature(mt, v, n, nov, ps, True, True)
        want = dfg_table[int(round(rough * 4)), int(round(cos_v * 4))].sum()
        w = kernel(rt, rep(mat), rep(v), rep(n), rep(v), u, rep(ps), True, True)[:, 2, :3]
        mean, se = w.mean(0), w.std(0) / np.sqrt(m)
        print(f"roughness {rough}, NoV {cos_v}: albedo {e[0]:.5f}, DFG A + B {want:.5f}, "
              f"kernel samples {mean[0]:.5f} +- {se[0]:.1e}")
        assert np.allclose(e, e[0], rtol=1e-12) and e[0] <= 1
        assert abs(e[0] - want) < 1e-4
        assert (np.abs(mean - e) < 4 * se + 1e-6).all()
        if rough == 1.0 and cos_v == 1.0:
            assert abs(e[0] - (1 - np.log(2))) < 1e-6


@pytest.mark.parametrize("base,metallic,rough,cos_v", [((0.8, 0.5, 0.2), 0.0, 0.3, 0.8),
                                                       ((0.8, 0.5, 0.2), 0.0, 0.7, 0.2),
                                                       (WHITE, 1.0, 0.5, 0.4), (WHITE, 1.0, 1.0, 0.1)])
def test_pdf_integrates_to_one(base, metallic, rough, cos_v):
    """The pdf of the mixture sample() draws from integrates to 1 over the sphere: its quadrature
    over the hemisphere plus the share of 400,000 samples that leave it (the visible normals'
    reflections below the horizon, returned with weight 0) is 1 within 4 binomial standard
    errors (the quadrature converged to 1e-6); the cosine lobe alone integrates to 1."""
    mat, v, n = one_vertex(base, metallic, rough, cos_v)
    mt, nov = material(mat, v, n)
    ps = bsdf.specular_probability(mt, nov, True, True)
    _, p = quadrature(mt, v, n, nov, ps, True, True)
    _, p_diffuse = quadrature(mt, v, n, nov, 0.0, True, False)
    m = 400_000
    rep = lambda a: np.repeat(a, m, 0)         # noqa: E731
    u = np.random.default_rng(4).random((m, 3))
    w, ls, _ = bsdf.sample(bsdf.Material(*(rep(x) for x in mt)), rep(v), rep(n), rep(nov), rep(ps), True, True,
                           u[:, 0], u[:, 1:])
    below = ((ls * n).sum(1) <= 0).mean()
    assert (w[(ls * n).sum(1) <= 0] == 0).all()
    se = np.sqrt(max(below * (1 - below), 1 / m) / m)
    print(f"ps {ps[0]:.3f}: pdf over the hemisphere {p:.6f}, share below {below:.6f} +- {se:.1e}")
    assert abs(p + below - 1) < 4 * se + 1e-5 and abs(p_diffuse - 1) < 1e-12


@pytest.mark.parametrize("base,metallic,rough,cos_v", [((0.8, 0.5, 0.2), 0.0, 0.4, 0.6), (WHITE, 1.0, 0.35, 0.3)])
def test_kernel_samples_follow_the_pdf(rt, base, metallic, rough, cos_v):
    """The kernel's bsdf_sample draws from the pdf bsdf_pdf states: 2^19 directions binned in 16 x
    32 cells of (cos theta, phi) against the pdf's quadrature over each cell (8 x 8 points),
    Pearson's chi-square within 5 standard deviations of its degrees of freedom; the same counts
    against the pdf of a lobe 10% wider fail it (the test can tell)."""
    mat, v, n = one_vertex(base, metallic, rough, cos_v)
    mt, nov = material(mat, v, n)
    ps = bsdf.specular_probability(mt, nov, True, True)
    m = 1 << 19
    rep = lambda a: np.repeat(a, m, 0)         # noqa: E731
    u = np.random.default_rng(6).random((m, 3))
    ls = kernel(rt, rep(mat), rep(v), rep(n), rep(v), u, rep(ps), True, True)[:, 3, :3]
    up = ls[:, 2] > 0
    kz, kp = 16, 32
    iz = np.minimum((ls[up, 2] * kz).astype(int), kz - 1)
    ip = np.minimum(((np.arctan2(ls[up, 1], ls[up, 0]) % (2 * np.pi)) / (2 * np.pi) * kp).astype(int), kp - 1)
    counts = np.bincount(iz * kp + ip, minlength=kz * kp)
    d, dw = hemisphere(8 * kz)              # 8 x 8 quadrature points per cell, in the cells' order below
    cell = (np.minimum((d[:, 2] * kz).astype(int), kz - 1) * kp
            + np.minimum(((np.arctan2(d[:, 1], d[:, 0]) % (2 * np.pi)) / (2 * np.pi) * kp).astype(int), kp - 1))

    def chi2(alpha_scale):
        mt_ = mt._replace(alpha=mt.alpha * alpha_scale ** 2)
        _, pdf = bsdf.evaluate(mt_, v, n, nov, d, ps, True, True)
        expect = np.bincount(cell, pdf * dw, kz * kp) * m
        ok = expect > 5
        return (((counts - expect) ** 2 / expect)[ok]).sum(), ok.sum() - 1

    c2, dof = chi2(1.0)
    c2_wide, _ = chi2(1.1)
    print(f"chi-square {c2:.0f} on {dof} degrees of freedom (a 10% wider lobe: {c2_wide:.0f})")
    assert abs(c2 - dof) < 5 * np.sqrt(2 * dof) and c2_wide > dof + 10 * np.sqrt(2 * dof)
