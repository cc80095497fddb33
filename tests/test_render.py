"""`iblbake render`: closed forms (white furnace, counting reflections), kernels against the numpy
twin, modes against the converged reference, the effect set, scene validation, outputs."""

import json
import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from iblbake.core import conventions
from iblbake.io import images
from iblbake.bake import dfg
from iblbake.errors import InputError
from iblbake.core import metrics
from iblbake.bake import radiance
from iblbake.render import render
from iblbake.scene import pack
from iblbake.render import twin as rr
from iblbake.scene import load as scene

from tests.helpers import box_downsample, prefiltered_bakes, run_cli, scene_file

LUM = np.array([0.2126, 0.7152, 0.0722])


def make_scene(folder, env_path, materials, *, objects=None, res=64, effects=None, camera=None,
               background="hide", output=None, rotation_y=0.0):
    return scene_file(folder, env_path, materials=materials, objects=objects, effects=effects or {}, output=output,
                      camera=camera or {"perspective": {"position": [0, 0, 3], "fov_y": 45}, "resolution": [res, res]},
                      environment={"background": background, "rotation_y": rotation_y})


def render_scene(path, cache, overrides=()):
    sc = scene.load(path, overrides)
    return sc, render(sc, cache_root=cache)


def sphere_pixels(sc):
    gb = rr.primary(sc["camera"], pack.scene_arrays(sc))
    return gb


@pytest.fixture(scope="module")
def constant_env(tmp_path_factory):
    d = tmp_path_factory.mktemp("env")
    p = d / "one.exr"
    images.write_exr(p, np.ones((32, 64, 3), np.float32))
    return p


@pytest.fixture(scope="module")
def small_panoramas_all(tmp_path_factory, load_panorama):
    """city, studio and courtyard at 512x256 (the oracle's brute force reads every texel)."""
    d = tmp_path_factory.mktemp("small3")
    out = {}
    for name in ("city", "studio", "courtyard"):
        out[name] = d / f"{name}.exr"
        images.write_exr(out[name], box_downsample(load_panorama(name), 2).astype(np.float32))
    return out


@pytest.fixture(scope="module")
def shared_cache(tmp_path_factory):
    return tmp_path_factory.mktemp("bake-cache")


@pytest.fixture(scope="module")
def dfg_fine():
    return dfg.dfg_twin(64, 4096)


# --- white furnace ------------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("metallic", [0.0, 1.0])
@pytest.mark.parametrize("specular", ["importance", "prefiltered", "lobe", "reference"])
def test_white_furnace(tmp_path, constant_env, dfg_fine, metallic, specular):
    """Constant radiance 1, base_color 1: the sphere's mean radiance is kD + F0 A + B (DFG) at
    every roughness, in every specular mode (2%)."""
    for r in (0.0, 0.25, 0.5, 1.0):
        p = make_scene(tmp_path, constant_env, {"base_color": [1, 1, 1], "metallic": metallic, "roughness": r},
                       effects={"specular": specular, "diffuse": "reference" if specular == "reference" else "sh",
                                "samples": 256, "reference": {"max_samples": 256, "target_noise": 0}})
        sc, frame = render_scene(p, tmp_path / "cache")
        gb = sphere_pixels(sc)
        hit = gb["hit"]
        v = -gb["dir"][hit]
        n = rr.facing_normal(gb["normal"][hit], v)
        nov = np.maximum((n * v).sum(1), 1e-4)
        f0 = 0.04 * (1 - metallic) + metallic
        ab = dfg.dfg_lookup(dfg_fine, nov, np.full(len(nov), r))
        kd = (1 - (f0 + (max(1 - r, f0) - f0) * (1 - nov) ** 5)) * (1 - metallic)
        predicted = (kd + f0 * ab[:, 0] + ab[:, 1]).mean()
        got = frame.hdr[..., :3].reshape(-1, 3)[hit].mean()
        assert abs(got / predicted - 1) < 0.02, (r, got, predicted)
        assert np.isfinite(frame.hdr).all()


@pytest.mark.parametrize("specular", ["importance", "prefiltered", "lobe", "reference"])
def test_white_furnace_specular_factor(tmp_path, constant_env, dfg_fine, specular):
    """KHR_materials_specular: a dielectric's F0 = min(0.04 specular_color, 1) specular and F90 =
    specular. Constant radiance 1, base_color 1: per channel kD + F0 A + F90 B in every mode, and
    specular 0 is a Lambert surface, exactly 1 (no lobe, no Fresnel on the diffuse). Bounds: see
    the asserts (measured worst 0.4% at specular 0.5, 1e-6 at specular 0)."""
    r = 0.5
    for spec, colour in ((0.0, [1, 1, 1]), (0.5, [1.0, 0.5, 30.0])):
        p = make_scene(tmp_path, constant_env, {"base_color": [1, 1, 1], "metallic": 0, "roughness": r,
                                                "specular": spec, "specular_color": colour},
                       effects={"specular": specular, "diffuse": "reference" if specular == "reference" else "sh",
                                "samples": 256, "reference": {"max_samples": 256, "target_noise": 0}})
        sc, frame = render_scene(p, tmp_path / "cache")
        gb = sphere_pixels(sc)
        hit = gb["hit"]
        v = -gb["dir"][hit]
        n = rr.facing_normal(gb["normal"][hit], v)
        nov = np.maximum((n * v).sum(1), 1e-4)[:, None]
        f0 = spec * np.minimum(0.04 * np.array(colour), 1.0)
        ab = dfg.dfg_lookup(dfg_fine, nov[:, 0], np.full(len(nov), r))
        kd = 1 - (f0 + (np.maximum(spec - r, f0) - f0) * (1 - nov) ** 5)
        predicted = (kd + f0 * ab[:, 0:1] + spec * ab[:, 1:2]).mean(0)
        got = frame.hdr[..., :3].reshape(-1, 3)[hit].mean(0)
        bound = 1e-5 if spec == 0 and specular != "reference" else 0.01
        assert np.abs(got / predicted - 1).max() < bound, (spec, got, predicted)


# --- counting reflections -----------------------------------------------------------------------

@pytest.fixture(scope="module")
def spot_env(tmp_path_factory):
    img = np.zeros((128, 256, 3), np.float32)
    u, v = conventions.equirect_uv_from_dir(np.array([0, np.sin(0.35), np.cos(0.35)]))
    i, j = int(u * 256), int(v * 128)
    img[j - 1:j + 2, i - 1:i + 2] = 1000.0
    p = tmp_path_factory.mktemp("spot") / "spot.exr"
    images.write_exr(p, img)
    return p


@pytest.mark.parametrize("roughness,samples,blobs", [(0.5, 1, 1), (0.5, 2, 2), (0.5, 3, 3), (0.5, 5, 5), (0.0, 5, 1)])
def test_counting_reflections(tmp_path, spot_env, roughness, samples, blobs):
    """force_mip0, metallic 1: each of the N samples reflects the one bright spot once."""
    from scipy import ndimage

    p = make_scene(tmp_path, spot_env, {"base_color": [1, 1, 1], "metallic": 1, "roughness": roughness}, res=160,
                   effects={"specular": "importance", "diffuse": "off", "samples": samples, "force_mip0": True})
    _, frame = render_scene(p, tmp_path / "cache")
    lum = frame.hdr[..., :3] @ LUM
    _, count = ndimage.label(lum > 1.0)
    assert count == blobs


# --- kernels against the numpy twin -----------------------------------------------------------------

@pytest.fixture(scope="module")
def mesh_file(tmp_path_factory):
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=2, radius=0.5)
    p = tmp_path_factory.mktemp("mesh") / "ico.ply"
    m.export(p)
    return p


def busy_scene(folder, env, mesh, camera=None, effects=None):
    mats = {"gold": {"base_color": [1.0, 0.78, 0.34], "metallic": 1, "roughness": 0.4},
            "red": {"base_color": [0.8, 0.1, 0.1], "roughness": 0.7},
            "floor": {"base_color": [0.5, 0.5, 0.5], "roughness": 0.9, "metallic": 0.2}}
    objs = [{"sphere": {"center": [-0.6, 0, 0], "radius": 0.5}, "material": "gold"},
            {"mesh": {"path": str(mesh), "translate": [0.6, 0, 0], "rotate": [10, 20, 0]}, "material": "red"},
            {"plane": {"point": [0, -0.5, 0], "size": [3, 2]}, "material": "floor"}]
    return make_scene(folder, env, mats, objects=objs, res=48, effects=effects, rotation_y=30,
                      camera=camera or {"perspective": {"position": [0, 1, 3], "fov_y": 50}, "resolution": [64, 48],
                                        "spp": 2})


@pytest.mark.external
@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_gbuffer_matches_numpy(tmp_path, small_panoramas, mesh_file, rt, projection):
    cam = {projection: {"position": [0, 1, 3], **({"fov_y": 50} if projection == "perspective" else {"width": 3})},
           "resolution": [64, 48], "spp": 2}
    p = busy_scene(tmp_path, small_panoramas["city"], mesh_file, camera=cam,
                   effects={"diffuse": "off", "specular": "off"})
    sc = scene.load(p, (), )
    sc.data["output"]["normal"] = str(tmp_path / "n.exr")   # ask for AOVs
    frame = render(sc, cache_root=tmp_path / "cache")
    gb = rr.primary(sc["camera"], pack.scene_arrays(sc))
    cover = gb["hit"].reshape(-1, 2).mean(1).reshape(48, 64)
    # coverage agrees except where a float32 and a float64 ray disagree on an edge
    assert np.mean(np.abs(frame.hdr[..., 3] - cover) > 0) < 0.01
    both = (frame.hdr[..., 3] == 1) & (cover == 1)
    nref = gb["normal"].reshape(48, 64, 2, 3).mean(2)
    err = np.abs(frame.aovs["normal"][..., :3] - nref)[both]
    assert np.quantile(err, 0.99) < 1e-4
    assert both.sum() > 500


@pytest.mark.external
@pytest.mark.parametrize("effects", [
    {"diffuse": "sh", "specular": "off"},
    {"diffuse": "off", "specular": "importance", "samples": 16},
    {"diffuse": "off", "specular": "prefiltered", "prefilter": {"method": "fis", "samples": 64}},
    {"diffuse": "off", "specular": "lobe", "lobe": {"samples": 4}, "prefilter": {"method": "fis", "samples": 64}},
    {"diffuse": "off", "specular": "lobe", "lobe": {"samples": 1}, "prefilter": {"method": "fis", "samples": 64}},
    {"diffuse": "off", "specular": "lobe", "lobe": {"samples": 16, "spread": 8}},
])
def test_shade_matches_numpy(tmp_path, small_panoramas, mesh_file, effects):
    from iblbake.core import sh

    p = busy_scene(tmp_path, small_panoramas["city"], mesh_file, effects=effects)
    sc = scene.load(p)
    frame = render(sc, cache_root=tmp_path / "cache")
    arrays = pack.scene_arrays(sc)
    gb = rr.primary(sc["camera"], arrays)
    image = images.read_panorama(sc["environment"]["path"])[0]
    fx = sc["effects"]
    kw = {}
    if fx["diffuse"] == "sh":
        kw["sh_coeffs"] = sh.project(image, 3) * sh.ahat(3)[:, None]
    if fx["specular"] == "importance":
        kw["chain"] = radiance.radiance_chain_twin(image)
    if fx["specular"] in ("prefiltered", "lobe"):
        kw.update(prefiltered_bakes(frame))
    ref = rr.shade(gb, arrays, fx, sc["environment"], **kw).reshape(48, 64, 2, 3)
    same = (gb["hit"].reshape(48, 64, 2).all(2)) & (frame.hdr[..., 3] == 1)
    got = frame.hdr[..., :3][same]
    want = ref.mean(2)[same]
    rel = np.abs(got - want) / np.maximum(np.abs(want), 1e-3)
    assert np.median(rel) < 1e-4 and np.quantile(rel, 0.98) < 2e-3, (np.median(rel), np.quantile(rel, 0.98))


@pytest.mark.external
def test_reference_converges_to_exact_integral(tmp_path, small_panoramas, load_panorama):
    """The Monte Carlo reference against quadrature over every texel (64x32 city, so the
    quadrature is cheap): relative RMSE < 1% on the sphere for a rough metal and a dielectric."""
    small = box_downsample(load_panorama("city"), 16).astype(np.float32)
    env = tmp_path / "city64.exr"
    images.write_exr(env, small)
    for mat in ({"base_color": [0.9, 0.6, 0.3], "metallic": 1, "roughness": 0.6},
                {"base_color": [0.5, 0.7, 0.9], "metallic": 0, "roughness": 0.5}):
        p = make_scene(tmp_path, env, mat, res=24, rotation_y=40,
                       effects={"diffuse": "reference", "specular": "reference",
                                "reference": {"max_samples": 8192, "target_noise": 0.001, "batch": 256}})
        sc, frame = render_scene(p, tmp_path / "cache")
        gb = sphere_pixels(sc)
        want = rr.exact(gb, pack.scene_arrays(sc), sc["effects"], sc["environment"], small, sub=4)
        hit = gb["hit"].reshape(24, 24)
        got = frame.hdr[..., :3][hit]
        assert metrics.relative_rmse(got, want.reshape(24, 24, 3)[hit]) < 0.01


@pytest.mark.external
@pytest.mark.parametrize("env", ["city", "studio"])
def test_modes_agree_with_reference(tmp_path, panoramas, shared_cache, env):
    """Against the converged reference, relative RMSE on the sphere pixels (metal, r >= 0.25).
    Measured (docs/benchmarks.md, benchmarks/bench_accuracy.py): importance N = 1024: 0.8-4.4% (one fixed
    Hammersley set against the sun), bound 5%; N = 4096: 0.4-2.3%, the 3% check; prefiltered (the
    split sum, an approximation of the integral, not an estimator of it): 11-27%, bound 30%;
    SH diffuse: bound 3%.
    The bounds sit just above the measured values so that a regression fails."""
    path = panoramas[env]
    for r in (0.25, 0.5, 1.0):
        mat = {"base_color": [0.95, 0.95, 0.95], "metallic": 1, "roughness": r}
        common = dict(res=48, rotation_y=70)
        p = make_scene(tmp_path, path, mat, effects={"diffuse": "off", "specular": "reference",
                                                     "reference": {"max_samples": 4096, "target_noise": 0.003,
                                                                   "batch": 256}}, **common)
        sc, ref = render_scene(p, shared_cache)
        hit = ref.hdr[..., 3] == 1
        # importance at N = 4096 meets the 3% check (measured <= 2.3%); N = 1024 keeps a 5% regression bound
        for mode, extra, bound in (("importance", {"samples": 1024}, 0.05), ("importance", {"samples": 4096}, 0.03),
                                   ("prefiltered", {}, 0.30)):
            p = make_scene(tmp_path, path, mat, effects={"diffuse": "off", "specular": mode, **extra}, **common)
            _, got = render_scene(p, shared_cache)
            err = metrics.relative_rmse(got.hdr[..., :3][hit], ref.hdr[..., :3][hit])
            print(f"{env} r={r} {mode} {extra}: relative RMSE {err:.4f}")
            assert err < bound, (env, r, mode, err)
    mat = {"base_color": [0.8, 0.8, 0.8], "metallic": 0, "roughness": 0.5}
    p = make_scene(tmp_path, path, mat, res=48, effects={"diffuse": "reference", "specular": "off",
                                                         "reference": {"max_samples": 4096, "target_noise": 0.003,
                                                                       "batch": 256}})
    _, ref = render_scene(p, shared_cache)
    hit = ref.hdr[..., 3] == 1
    errs = {}
    for bands in (3, 5):
        p = make_scene(tmp_path, path, mat, res=48, effects={"diffuse": "sh", "specular": "off", "sh_bands": bands})
        _, got = render_scene(p, shared_cache)
        errs[bands] = metrics.relative_rmse(got.hdr[..., :3][hit], ref.hdr[..., :3][hit])
        print(f"{env} SH diffuse, {bands} bands: relative RMSE {errs[bands]:.4f}")
    # 3 bands: the band-limit error of the classic 9 coefficients (studio's saturated lights: 7%);
    # 5 bands (l <= 4; Ahat_3 = 0) brings it under 3%
    assert errs[3] < 0.08 and errs[5] < 0.03 and errs[5] < errs[3]


@pytest.mark.external
@pytest.mark.parametrize("k", [1, 4])
def test_lobe_on_a_mirror_is_the_split_sum(tmp_path, small_panoramas, k):
    """Roughness 0: every visible-normal sample is the normal, so `lobe` reads level 0 at R
    times F0 A + B, which is the split sum without the dominant direction: every pixel within
    1e-5 of the frame's peak but the sun's, whose steep bilinear gradient turns the two codes'
    float32 rounding of R into 1e-4 (bound 5e-4 relative)."""
    mat = {"base_color": [1.0, 0.8, 0.4], "metallic": 1, "roughness": 0.0}
    frames = []
    for fx in ({"specular": "lobe", "lobe": {"samples": k}},
               {"specular": "prefiltered", "prefilter": {"dominant_direction": False}}):
        p = make_scene(tmp_path, small_panoramas["city"], mat, res=32, rotation_y=20,
                       effects={"diffuse": "off", **fx})
        frames.append(render_scene(p, tmp_path / "cache")[1].hdr)
    hit = frames[1][..., 3] == 1
    assert hit.sum() > 300
    diff = np.abs(frames[0] - frames[1])[hit][:, :3]
    peak = np.abs(frames[1][hit]).max()
    assert np.mean(diff <= 1e-5 * peak) > 0.995
    assert (diff / np.maximum(np.abs(frames[1][hit][:, :3]), 1e-3)).max() < 5e-4


def exact_dfg(nov, alpha, n_samples=16384):
    """(A, B) of F0 A + B = the directional albedo with Schlick's F, float64, by visible-normal
    quadrature (Hammersley in the VNDF's unit square: the integrand F G2 / G1 is bounded and
    smooth there), independent of the DFG bake's half-vector sampling. nov (P,), alpha scalar."""
    from iblbake.core import brdf, sampling

    pts = sampling.hammersley(n_samples)
    a, b = np.zeros(len(nov)), np.zeros(len(nov))
    vl = np.stack([np.sqrt(1 - nov * nov), np.zeros_like(nov), nov], -1)
    g1 = sampling.g1_smith(nov, alpha)
    for i0 in range(0, n_samples, 1024):
        u = pts[i0:i0 + 1024]
        h = sampling.sample_ggx_vndf(vl[:, None, :], alpha, np.broadcast_to(u, (len(nov),) + u.shape))
        voh = (vl[:, None, :] * h).sum(-1)
        nol = 2 * voh * h[..., 2] - nov[:, None]
        w = np.where(nol > 0, 4 * brdf.v_smith_ggx_correlated(nov[:, None], np.maximum(nol, 0), alpha)
                     * nov[:, None] * np.maximum(nol, 0) / g1[:, None], 0.0)
        fc = (1 - np.clip(voh, 0, 1)) ** 5
        a += (w * (1 - fc)).sum(1)
        b += (w * fc).sum(1)
    return a / n_samples, b / n_samples


@pytest.mark.external
@pytest.mark.parametrize("env", ["city", "studio", "courtyard"])
def test_prefiltered_matches_split_sum_oracle(tmp_path, small_panoramas_all, shared_cache, env):
    """The split sum, computed exactly: per pixel, the float64 prefiltered integral at the
    dominant direction (prefilter_bruteforce: every texel, exact solid angles) times the float64
    directional albedo F0 A + B for its NoV and roughness (exact_dfg); no chain, no table, no
    interpolation. The renderer against it isolates implementation error (chain, lookups, DFG
    table): within 1% relative RMSE on the test sphere at roughness 0.25, 0.5, 1, which sit on
    levels of the 5-level chain (between levels the chain interpolates, which the study shows).
    Measured (512x256 panoramas, lobe-sized levels): 0.03-0.30%; halving levels down to 8 rows
    (256x128): 0.5-3.7%, the reason levels are sized by their lobe."""
    from iblbake.bake import prefilter

    path = small_panoramas_all[env]
    src = images.read_panorama(path)[0].astype(np.float64)
    for r in (0.25, 0.5, 1.0):
        mat = {"base_color": [0.95, 0.95, 0.95], "metallic": 1, "roughness": r}
        p = make_scene(tmp_path, path, mat, res=48, rotation_y=70,
                       effects={"diffuse": "off", "specular": "prefiltered", "prefilter": {"levels": 5}})
        sc, frame = render_scene(p, shared_cache)
        gb = sphere_pixels(sc)
        v, n, nov, _ = rr.surface(gb, pack.scene_arrays(sc))
        alpha = r * r
        refl = 2 * nov[:, None] * n - v
        s = np.clip(1 - alpha, 0, 1)
        dom = n + (refl - n) * (s * (np.sqrt(s) + alpha))
        dom /= np.linalg.norm(dom, axis=1, keepdims=True)
        pre = prefilter.prefilter_bruteforce(src, rr.to_env(dom, 70.0), r)
        a, b = exact_dfg(nov, alpha)
        oracle = pre * (0.95 * a + b)[:, None]
        hit = gb["hit"].reshape(48, 48) & (frame.hdr[..., 3] == 1)
        got = frame.hdr[..., :3][hit]
        want = np.zeros((48 * 48, 3))
        want[gb["hit"]] = oracle
        err = metrics.relative_rmse(got, want.reshape(48, 48, 3)[hit])
        print(f"{env} r={r}: prefiltered against the split-sum oracle, relative RMSE {err:.4f}")
        assert err < 0.01, (env, r, err)


# --- effect set -------------------------------------------------------------------------------------

def bakes_of(frame):
    return {b["name"] for b in frame.report["bakes"]}


def render_defines(frame):
    return [b["defines"] for b in frame.report["kernel_builds"] if "shade.cl" in b["kernel"].split("+")]


@pytest.mark.external
def test_effect_set_bakes_only_what_is_read(tmp_path, small_panoramas):
    env = small_panoramas["studio"]
    mat = {"base_color": [0.8, 0.8, 0.8], "metallic": 0, "roughness": 0.5}
    cache = tmp_path / "cache"

    def run(**fx):
        p = make_scene(tmp_path, env, mat, res=16, effects=fx)
        return render_scene(p, cache)[1]

    f = run(diffuse="sh", specular="off")
    assert bakes_of(f) & {"radiance", "prefiltered", "dfg"} == set() and "sh" in bakes_of(f)
    assert all(d["SPECULAR_MODE"] == 0 for d in render_defines(f))
    assert "shade" in [p["name"] for p in f.report["passes"]]
    assert "background" not in [p["name"] for p in f.report["passes"]]       # background: hide
    f = run(diffuse="off", specular="importance")
    assert "radiance" in bakes_of(f) and not bakes_of(f) & {"sh", "prefiltered", "dfg"}
    f = run(diffuse="off", specular="prefiltered")
    assert {"prefiltered", "dfg"} <= bakes_of(f) and not bakes_of(f) & {"sh"}
    kinds = {json.loads((e / "manifest.json").read_text()).get("kind") for e in cache.iterdir()
             if (e / "manifest.json").exists()}
    # importance wrote a radiance entry; prefiltered did not need one of its own
    assert kinds == {"sh", "radiance", "prefiltered", "dfg"}
    f = run(diffuse="off", specular="off")
    assert [p["name"] for p in f.report["passes"]] == ["gbuffer", "resolve"]
    assert not bakes_of(f) - {"geometry"}
    assert "read_environment" not in bakes_of(f)
    # an all-metal scene needs no SH, whatever diffuse says
    p = make_scene(tmp_path, env, {"base_color": [1, 1, 1], "metallic": 1, "roughness": 0.3}, res=16,
                   effects={"diffuse": "sh", "specular": "off"})
    f = render_scene(p, cache)[1]
    assert "sh" not in bakes_of(f) and f.report["effects"]["diffuse"] == "off"


@pytest.mark.external
def test_report_cli_and_kernel_cache(tmp_path, small_panoramas):
    """--report --json lists passes and bakes; the second run hits every cache and builds
    nothing new on disk (pyopencl's binary cache)."""
    kcache = tmp_path / "kernels"
    envv = {"IBLBAKE_KERNEL_CACHE": str(kcache)}
    p = make_scene(tmp_path, small_panoramas["studio"], {"base_color": [0.8, 0.8, 0.8], "roughness": 0.5}, res=32,
                   effects={"diffuse": "sh", "specular": "prefiltered"})
    out = tmp_path / "a.png"
    r1 = run_cli("render", p, "-o", out, "--cache", tmp_path / "c", "--json", "--report", env=envv)
    assert r1.returncode == 0, r1.stderr
    files = sorted(str(x) for x in kcache.rglob("*"))
    r2 = run_cli("render", p, "-o", out, "--cache", tmp_path / "c", "--json", env=envv)
    assert r2.returncode == 0, r2.stderr
    rep = json.loads(r2.stdout)
    assert all(b["cached"] for b in rep["bakes"] if b["name"] in ("sh", "prefiltered", "dfg"))
    assert sorted(str(x) for x in kcache.rglob("*")) == files
    assert rep["outputs"] == [str(out)]


@pytest.mark.external
def test_determinism_and_outputs(tmp_path, small_panoramas, mesh_file):
    p = busy_scene(tmp_path, small_panoramas["city"], mesh_file,
                   effects={"diffuse": "reference", "specular": "importance", "samples": 8,
                            "reference": {"max_samples": 64}})
    outs = []
    for k in range(2):
        o = tmp_path / f"f{k}.png"
        r = run_cli("render", p, "-o", o, "-o", tmp_path / f"f{k}.exr", "--cache", tmp_path / "c",
                    "--set", "output.depth=depth.exr", "--set", "output.albedo=albedo.exr", "-q")
        assert r.returncode == 0, r.stderr
        outs.append(o.read_bytes())
    assert outs[0] == outs[1]
    exr = images.read_exr(tmp_path / "f0.exr")
    assert exr.shape == (48, 64, 4) and np.isfinite(exr).all()
    depth = images.read_exr(tmp_path / "depth.exr")
    assert np.isfinite(depth).all() and depth.max() > 2.0
    assert not [x for x in os.listdir(tmp_path) if ".tmp-" in x]


# --- scene validation --------------------------------------------------------------------------------

GOOD = """camera:
  perspective: {position: [0, 0, 3], fov_y: 40}
  resolution: [16, 16]
environment:
  path: ENV
materials:
  gold: {base_color: [1, 0.8, 0.3], metallic: 1, roughness: 0.3}
objects:
  - sphere: {center: [0, 0, 0], radius: 1}
    material: gold
effects:
  specular: prefiltered
output:
  frame: out.png
"""


@pytest.mark.parametrize("edit,expected", [
    (("specular: prefiltered", "specullar: prefiltered"), ":12: effects.specullar: unknown key (did you mean 'specular'?)"),
    (("roughness: 0.3", "roughness: 1.5"), ":7: materials.gold.roughness: 1.5 is out of range"),
    (("radius: 1", "radius: -1"), ":9: objects.0.sphere.radius: -1 is out of range; give a value > 0"),
    (("fov_y: 40", "fov_y: 0"), ":2: camera.perspective.fov_y: 0 is out of range"),
    (("material: gold", "material: gld"), ":10: objects.0.material: no material named 'gld' (did you mean 'gold'?)"),
    (("specular: prefiltered", "specular: importnce"), ":12: effects.specular: 'importnce' is not one of"),
    (("path: ENV", "path: nowhere.exr"), ":5: environment.path:"),
    (("frame: out.png", "frame: ../../x.png"), ":14: output.frame: '../../x.png' leaves the scene's folder"),
    (("resolution: [16, 16]", "resolution: [16, 16"), "not valid YAML"),
    (("frame: out.png", "frame: out.jpg"), "output.frame:"),
])
def test_bad_scene_one_line_error(tmp_path, constant_env, edit, expected):
    text = GOOD.replace(*edit).replace("ENV", str(constant_env))
    p = tmp_path / "scene.yaml"
    p.write_text(text)
    r = run_cli("render", p, "--cache", tmp_path / "c")
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert str(p) in lines[0] and expected in lines[0], lines[0]
    assert not (tmp_path / "out.png").exists()


def test_set_overrides(tmp_path, constant_env):
    p = tmp_path / "scene.yaml"
    p.write_text(GOOD.replace("ENV", str(constant_env)))
    sc = scene.load(p, ["materials.gold.roughness=0.7", "effects.samples=12", "objects.0.sphere.radius=2"])
    assert sc["materials"]["gold"]["roughness"] == 0.7 and sc["effects"]["samples"] == 12
    assert sc["objects"][0]["sphere"]["radius"] == 2.0
    r = run_cli("render", p, "--set", "materials.gold.roughness=2", "--cache", tmp_path / "c")
    assert r.returncode != 0 and "--set: materials.gold.roughness: 2 is out of range" in r.stderr
    r = run_cli("render", p, "--set", "objects.5.sphere.radius=2")
    assert r.returncode != 0 and "no item 5" in r.stderr
    # a misspelt section made by --set is the flag's, not the line of the file's section above it
    with pytest.raises(InputError, match=r"scene\.yaml: --set: effects\.referance: unknown key \(did you mean 'reference'\?\)"):
        scene.load(p, ["effects.referance.max_samples=10"])
    # a value of one alternative's kind gets that alternative's complaint alone; of none, what it may be
    with pytest.raises(InputError, match=r"--set: effects\.reference\.bounces: 0 is out of range; give a value >= 1 "
                                         r"and <= 65536$"):
        scene.load(p, ["effects.reference.bounces=0"])
    with pytest.raises(InputError, match=r"'unbouded' is not one of unbounded \(did you mean 'unbounded'\?\)$"):
        scene.load(p, ["effects.reference.bounces=unbouded"])
    with pytest.raises(InputError, match=r"\{'a': 1\} is neither unbounded nor integer \(1 <= x <= 65536\)$"):
        scene.load(p, ["effects.reference.bounces={a: 1}"])
    with pytest.raises(InputError, match=r"environment\.background: \[1, 2\] is not a list of 3 numbers$"):
        scene.load(p, ["environment.background=[1, 2]"])
    # a misspelt section the scene itself holds is the scene's, though --set writes inside it
    doc = yaml.safe_load(p.read_text())
    doc["effects"]["referance"] = {"max_samples": 3}
    with pytest.raises(InputError, match=r"^<scene>: effects\.referance: unknown key"):
        scene.load_data(doc, tmp_path, overrides=["effects.referance.max_samples=10"])


def test_mesh_errors(tmp_path, constant_env):
    bad_index = tmp_path / "bad.obj"
    bad_index.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")
    nan = tmp_path / "nan.obj"
    nan.write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    degenerate = tmp_path / "deg.obj"
    degenerate.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\nf 1 1 3\n")
    garbage = tmp_path / "crate.glb"           # a new user's: it was said as "not glTF JSON: Expecting value"
    garbage.write_bytes(b"not a glb at all" * 8)
    for mesh, expected in ((bad_index, "bad.obj"), (nan, "not finite"), (tmp_path / "missing.ply", "not found"),
                           (garbage, "not a GLB file: its header is b'not '")):
        p = make_scene(tmp_path, constant_env, {"base_color": [1, 1, 1]},
                       objects=[{"mesh": {"path": str(mesh)}, "material": "m"}])
        r = run_cli("render", p, "--cache", tmp_path / "c")
        assert r.returncode != 0 and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert expected in r.stderr and "objects.0.mesh" in r.stderr, r.stderr
    p = make_scene(tmp_path, constant_env, {"base_color": [1, 1, 1]},
                   objects=[{"mesh": {"path": str(degenerate)}, "material": "m"}])
    sc = scene.load(p)
    geo = pack.scene_arrays(sc).geometry_report
    assert geo["triangles"] == 1 and geo["meshes"][0]["dropped_degenerate"] == 2


def test_huge_angles_are_the_same_turn_mod_360(tmp_path, lobed_sky):
    """environment.rotation_y 1.2345e300 is exactly 352 degrees mod 360: the same frame (in
    radians it reached the kernels as float32 inf: another frame), and every angle key of a scene
    is reduced the same way."""
    import iblbake
    frames = []
    for r in (1.2345e300, 352.0):
        sc = scene.load(scene_file(tmp_path, lobed_sky, environment={"rotation_y": r},
                                   camera={"perspective": {"position": [0, 0, 3]}, "resolution": [16, 16]},
                                   materials={"base_color": [0.9, 0.9, 0.9], "metallic": 1, "roughness": 0.2}))
        assert sc.data["environment"]["rotation_y"] == 352.0
        frames.append(iblbake.render(sc).hdr)
    assert np.array_equal(frames[0], frames[1])
    images.write_png(tmp_path / "t.png", np.full((2, 2, 3), 128, np.uint8))
    sc = scene.load(scene_file(tmp_path, lobed_sky, objects=[{"mesh": {
        "path": str(Path(__file__).parents[1] / "examples" / "meshes" / "knot.ply"), "rotate": [7e21, -5e30, 90]},
        "material": "m"}], materials={"base_color": [1, 1, 1], "base_color_map": {"path": "t.png", "uv_rotation": -5e30}}))
    assert sc.data["objects"][0]["mesh"]["rotate"] == [160.0, -304.0, 90.0]
    assert sc.data["materials"]["m"]["base_color_map"]["uv_rotation"] == -304.0
