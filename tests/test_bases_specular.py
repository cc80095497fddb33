"""Specular from a directional basis (`effects.specular: sg | ambient_dice`, core/bases SPECULAR):
the warped GGX lobe's radiance against the float64 quadrature of the GGX lobe on the basis's own
radiance (the approximation's error measured), ambient dice's lobe averaged over the warped lobe
(its table against the series, the series against direct quadrature), the kernel headers against
the twins, a rough metal sphere rendered by kernel and twin, and the load's check of one basis a
frame. The probes' specular: tests/test_probes_specular.py."""

from pathlib import Path

import numpy as np
import pytest

from iblbake.core import bases, brdf
from iblbake.core.bases import common
from iblbake.errors import InputError
from iblbake.render.plan import plan
from tests.helpers import load_scene

SG = bases.BASES["sg"]
AD = bases.BASES["ambient_dice"]


def lobed_image():
    v, u = np.meshgrid((np.arange(32) + 0.5) / 32, (np.arange(64) + 0.5) / 64, indexing="ij")
    return np.stack([1 + 0.8 * np.cos(2 * np.pi * u), 1 + 0.6 * np.cos(np.pi * v), 1 + 0.5 * np.sin(2 * np.pi * u)], -1)


def views(rng, nov, count):
    """count (n, v) pairs with n.v = nov, n uniform."""
    n = rng.normal(size=(count, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t = np.cross(n, rng.normal(size=(count, 3)))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return n, nov * n + np.sqrt(1 - nov * nov) * t


def lobe_errors(name, opts, rough):
    """The split sum with basis `name` (the lobe's exact albedo, F = 1, times the basis's radiance
    along the warped lobe) against int D V (n.l) L(l) dl over 2^18 Fibonacci directions of the
    basis's own radiance L of the lobed sky, 12 views of n.v 0.2, 0.5, 0.9: (relative errors with
    the dominant direction, with the mirror direction), worst channel."""
    m = bases.BASES[name]
    c = m.project(lobed_image(), opts)
    d = common.fibonacci_sphere(1 << 18)
    w = 4 * np.pi / len(d)
    L = m.radiance(c, d, opts)
    a = rough * rough
    rng = np.random.default_rng(3)
    errs, mirror = [], []
    for nov in (0.2, 0.5, 0.9):
        ns, vs = views(rng, nov, 4)
        for n, v in zip(ns, vs):
            nl = d @ n
            h = d + v
            h /= np.linalg.norm(h, axis=1, keepdims=True)
            f = np.where(nl > 0, brdf.d_ggx(np.clip(h @ n, 0, 1), a)
                         * brdf.v_smith_ggx_correlated(nov, np.clip(nl, 1e-9, 1), a) * nl, 0.0)
            exact = (f[:, None] * L).sum(0) * w
            albedo = f.sum() * w
            lw = np.atleast_1d(common.warp_sharpness(a, nov))
            got = albedo * bases.specular_radiance(name, c, common.lobe_axis(n[None], v[None], np.array([a])), lw,
                                                   opts)[0]
            errs.append(np.abs(got / exact - 1).max())
            r = 2 * nov * n - v
            mirror.append(np.abs(albedo * bases.specular_radiance(name, c, r[None], lw, opts)[0] / exact - 1).max())
    return errs, mirror


# measured (the lobed sky, 12 views of n.v 0.2, 0.5, 0.9; worst channel): mean and worst relative
# error per roughness. SG K = 9 least squares: 0.3: 6.5%, 21%; 0.5: 12.1%, 45%; 0.7: 13.1%, 32%;
# 1: 23.7%, 54% (the mirror direction instead: mean 7.8%, 20%, 32%, 47%). Ambient dice: see AD_BOUNDS.
BOUNDS = {0.3: (0.09, 0.3), 0.5: (0.17, 0.6), 0.7: (0.19, 0.45), 1.0: (0.33, 0.7)}


@pytest.mark.parametrize("rough", sorted(BOUNDS))
def test_sg_specular_against_the_ggx_lobe_quadrature(rough):
    """SG9's error against the GGX lobe's quadrature is the approximation's (the warp, the split),
    within BOUNDS (1.3-1.5x the measured); the mirror direction instead of the dominant one is worse
    at roughness 0.7 and 1."""
    errs, mirror = lobe_errors("sg", {"sg_lobes": 9, "sg_fit": "least_squares"}, rough)
    mean_bound, max_bound = BOUNDS[rough]
    assert np.mean(errs) < mean_bound and max(errs) < max_bound, (np.mean(errs), max(errs))
    if rough >= 0.5:
        assert np.mean(mirror) > 1.5 * np.mean(errs)


# ambient dice, measured as SG9 above: 0.3: 6.5%, 23%; 0.5: 12.3%, 32%; 0.7: 15.5%, 35%; 1: 27.3%, 62%
# (the mirror direction: mean 6.8%, 17.7%, 34.9%, 54.8%): the warp's error, which both bases share
AD_BOUNDS = {0.3: (0.09, 0.3), 0.5: (0.17, 0.43), 0.7: (0.21, 0.47), 1.0: (0.36, 0.8)}


@pytest.mark.parametrize("rough", sorted(AD_BOUNDS))
def test_ambient_dice_specular_against_the_ggx_lobe_quadrature(rough):
    errs, mirror = lobe_errors("ambient_dice", {"ad_fit": "least_squares"}, rough)
    mean_bound, max_bound = AD_BOUNDS[rough]
    assert np.mean(errs) < mean_bound and max(errs) < max_bound, (np.mean(errs), max(errs))
    if rough >= 0.5:
        assert np.mean(mirror) > 1.3 * np.mean(errs)


def test_ambient_dice_lobe_over_the_warped_lobe():
    """h(mu, lambda), the lobe averaged over the normalised SG: the Funk-Hecke series against direct
    quadrature over 2^20 Fibonacci directions (measured 2e-7 of the peak at lambda <= 40; the
    quadrature's own error grows with lambda); its limits (lambda -> inf: the lobe itself at mu; the
    vertices' h summing to 1 for any axis and sharpness, the lobes' partition of unity); and the
    kernel's table against the series (measured 3.2e-4, 5.4e-4 of the peak 0.6; bound 1e-3 of it)."""
    d = common.fibonacci_sphere(1 << 20)
    v = np.array([0.0, 1.0, 0.0])
    for lam, mu in [(0.3, -0.4), (1.0, 0.1), (5.0, 0.0), (5.0, 0.6), (40.0, 0.3), (40.0, 0.95)]:
        r = np.array([np.sqrt(1 - mu * mu), mu, 0.0])
        g = np.exp(lam * (d @ r - 1))
        want = (AD.lobe(d @ v) * g).sum() / g.sum()
        assert abs(AD.lobe_convolved([mu], [lam])[0, 0] - want) < 2e-6 * 0.6, (lam, mu)
    mu = np.linspace(-1, 1, 41)
    assert np.abs(AD.lobe_convolved(mu, [1e5])[0] - AD.lobe(mu)).max() < 4e-5     # measured 1.7e-5: width 3e-3 rad
    rng = np.random.default_rng(2)
    axes = common.fibonacci_sphere(50) @ np.linalg.qr(rng.normal(size=(3, 3)))[0]
    for lam in (0.25, 2.0, 30.0, 3000.0):
        total = AD.lobe_convolved((axes @ AD.vertices().T).ravel(), [lam])[0].reshape(50, 12).sum(1)
        assert np.abs(total - 1).max() < 1e-9, lam
    lam = 2.0 ** rng.uniform(-2, 14, 300)
    mu = rng.uniform(-1, 1, 300)
    series = np.diag(AD.lobe_convolved(mu, lam))           # every (lam_i, mu_j): the pairs on the diagonal
    assert np.abs(AD.table_lookup(mu, lam) - series).max() < 1e-3 * 0.6


def test_sg_inner_product_against_quadrature():
    """The normalised inner product's closed form (stable for any sharpness) against quadrature,
    and its mirror limit: a sharp warped lobe reads the SG at r."""
    lam = SG.sharpness(9)
    d = common.fibonacci_sphere(1 << 18)
    mu = np.array([0.0, 1.0, 0.0])
    for lw, t in [(0.8, 0.3), (5.0, -0.2), (40.0, 0.9)]:
        r = np.array([np.sqrt(1 - t * t), t, 0.0])
        gw = np.exp(lw * (d @ r - 1))
        want = (np.exp(lam * (d @ mu - 1)) * gw).sum() / gw.sum()
        assert abs(SG.sg_inner_normalised(t, lam, lw) / want - 1) < 1e-6
    assert abs(SG.sg_inner_normalised(0.5, lam, 1e7) / np.exp(lam * (0.5 - 1)) - 1) < 1e-5


KERNEL_CASES = [("sg", {"sg_lobes": 5, "sg_fit": "least_squares"}), ("sg", {"sg_lobes": 12, "sg_fit": "least_squares"}),
                ("ambient_dice", {})]


@pytest.mark.parametrize("name, opts", KERNEL_CASES, ids=["sg5", "sg12", "ambient_dice"])
def test_kernel_matches_twin(rt, name, opts):
    """kernels/bases.h basis_specular_radiance (each header's basis_specular_weights; ambient dice's
    from its table) and basis_warp_sharpness against the twin over random axes, roughness 0.05-1
    and n.v 0.01-1: measured 4e-7 (SG5), 8e-7 (SG12), 3e-7 (ambient dice) of the largest (float32)."""
    from iblbake.render.sources.basis import table_args
    m = bases.BASES[name]
    rng = np.random.default_rng(5)
    c = m.project(lobed_image(), opts)
    r = rng.normal(size=(4000, 3))
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    an = np.stack([rng.uniform(0.05, 1, 4000) ** 2, rng.uniform(0.01, 1, 4000)], 1)
    want = bases.specular_radiance(name, c, r, common.warp_sharpness(an[:, 0], an[:, 1]), opts)
    out = rt.empty(12 * len(r))
    rt.launch("selftest.cl", "t_basis_specular", m.defines(opts), (len(r),), {},
              basis_coeffs=rt.to_device(m.pack(c, opts)), **table_args(rt, name, opts),
              r=rt.to_device(np.pad(r.astype(np.float32), ((0, 0), (0, 1)))),
              an=rt.to_device(an.astype(np.float32)), e=out)
    got = rt.read(out, (len(r), 3)).astype(np.float64)
    assert np.abs(got - want).max() / want.max() < 4e-6


def metal_scene(folder, sky, specular="sg", diffuse="sg"):
    return load_scene(folder, f"metal_{specular}_{diffuse}", {
        "camera": {"perspective": {"position": [0, 0, 3], "look_at": [0, 0, 0], "fov_y": 40}, "resolution": [24, 24]},
        "environment": {"path": str(sky)},
        "materials": {"m": {"base_color": [0.9, 0.7, 0.5], "metallic": 1, "roughness": 0.6}},
        "objects": [{"sphere": {"center": [0, 0, 0], "radius": 0.8}, "material": "m"}],
        "effects": {"diffuse": diffuse, "specular": specular, "ao": "off"}})


@pytest.fixture(scope="module")
def sky(tmp_path_factory):
    from iblbake.io import images
    p = tmp_path_factory.mktemp("lobed") / "sky.exr"
    images.write_exr(p, lobed_image().astype(np.float32))
    return p


@pytest.mark.slow           # over 3 s on the 2-core CPU: make test, not make check
def test_rough_metal_sphere_kernel_matches_twin(tmp_path, rt, sky):
    """A rough metal sphere, diffuse and specular sg end to end (schema, plan, the `basis` and
    `dfg` bakes, the source, SPECULAR_BASIS in the shade kernel): the frame's hit pixels against the
    shade twin on the float64 projection and the frame's DFG table: lit everywhere (the sky
    reflected without a chain), within 5e-6 of the brightest (measured 1.2e-6, float32)."""
    from iblbake.render import render
    from iblbake.render import twin as rr
    from iblbake.render.bakes import Bakes
    from iblbake.render.plan import plan
    from iblbake.scene import pack
    sc = metal_scene(tmp_path, sky)
    pl = plan(sc)
    assert "dfg" in pl.bakes and "prefiltered" not in pl.bakes
    bakes = Bakes(tmp_path / "cache")
    frame = render(sc, runtime=rt, cache=bakes)
    dfg = bakes.result("dfg")
    arrays = pack.scene_arrays(sc)
    gb = rr.primary(sc["camera"], arrays)
    hit = gb["hit"]
    opts = {k: sc["effects"][k] for k in SG.OPTIONS}
    c = SG.project(lobed_image().astype(np.float32).astype(np.float64), opts)
    want = rr.shade(gb, arrays, sc["effects"], sc["environment"], basis_coeffs=c, dfg=dfg)[hit]
    got = frame.hdr[..., :3].reshape(-1, 3)[hit]
    assert hit.sum() > 150 and got.min() > 0.05 * got.max()
    err = np.abs(got - want).max() / want.max()
    assert err < 5e-6, err


def test_one_basis_a_frame(tmp_path, sky):
    with pytest.raises(InputError, match="effects.specular: sg beside effects.diffuse: zh3: a frame lights from one"):
        metal_scene(tmp_path, sky, "sg", "zh3")
    sc = metal_scene(tmp_path, sky, "sg", "off")           # the study's specular term alone
    assert plan(sc).defines["shade"]["SG_LOBES"] == 9


@pytest.mark.external
def test_specular_lobes_are_fitted_without_negative_light_by_default(tmp_path, panoramas):
    """`specular: sg | ambient_dice` with the default least-squares fit under a sky with a sun: the
    fit rings negative, the lobe clamps it to black, and metals show black patches beside white
    ones (the sphere grid under city at 320 x 180: 3.2% of the metal pixels black with SG9, 12%
    with ambient dice; NNLS none, the metal pixels' min 0.069 and 0.042). The fit defaults to
    NNLS where the lobes serve the specular term; the irradiance fit stays the diffuse default of
    both (issue 62), and a fit is kept where given."""
    import yaml

    from iblbake.render import render
    from iblbake.scene import load as scene_load
    doc = yaml.safe_load((Path(__file__).parents[1] / "examples" / "scenes" / "sphere_grid.yaml").read_text())
    doc["environment"].update(path=str(panoramas["city"]), background="hide")
    doc["camera"]["resolution"] = [160, 90]
    doc["output"] = {"frame": "x.exr", "albedo": "a.exr"}          # the object AOV: which sphere is metal
    mins = {}
    for name, key in (("sg", "sg_fit"), ("ambient_dice", "ad_fit")):
        for fit in (None, "least_squares"):
            fx = {**doc["effects"], "diffuse": "off", "specular": name, **({key: fit} if fit else {})}
            sc = scene_load.load_data({**doc, "effects": fx}, tmp_path)
            assert sc.data["effects"][key] == (fit or "nnls")
            f = render(sc)
            metal = (f.hdr[..., 3] >= 0.999) & (f.aovs["object"] >= 5)
            lum = f.hdr[..., :3][metal] @ [0.2126, 0.7152, 0.0722]
            mins[name, fit] = (float(lum.min()), float((lum < 0.01 * lum.mean()).mean()))
    assert mins["sg", None][0] > 0.03 and mins["ambient_dice", None][0] > 0.02, mins         # measured 0.069, 0.042
    assert mins["sg", "least_squares"][1] > 0.01 and mins["ambient_dice", "least_squares"][1] > 0.05, mins
    diffuse = scene_load.load_data({**doc, "effects": {**doc["effects"], "diffuse": "sg"}}, tmp_path)
    assert diffuse.data["effects"]["sg_fit"] == "irradiance"
    probes = scene_load.load_data({**doc, "effects": {**doc["effects"], "diffuse": "probes", "specular": "probes"},
                                   "probes": {"irradiance": "ambient_dice"}}, tmp_path)
    assert probes.data["probes"]["ad_fit"] == "nnls" and probes.data["effects"]["ad_fit"] == "irradiance"
