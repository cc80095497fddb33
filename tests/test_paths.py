"""The reference's paths (effects.reference.bounces) against closed forms: a white furnace of
Lambert surfaces (every pixel converges to the environment's 1, however the objects shadow each
other), an enclosure lit by its own emission (E / (1 - a), and E (1 + a + ... + a^k) with k
bounces), what compiles a path and what does not, and bounces: 1 as the direct light of before.
Each closed form runs through both ways of running the paths (effects.reference.paths: the
megakernel and the wavefront of stages), and the two give the same frame to float32 rounding."""

from pathlib import Path

import numpy as np
import pytest

from iblbake.render import render
from iblbake.io import images
from tests.helpers import load_scene


@pytest.fixture(scope="module")
def white(tmp_path_factory):
    p = tmp_path_factory.mktemp("white") / "white.exr"
    images.write_exr(p, np.ones((32, 64, 3), np.float32))
    return p


@pytest.fixture(scope="module")
def black(tmp_path_factory):
    p = tmp_path_factory.mktemp("black") / "black.exr"
    images.write_exr(p, np.zeros((32, 64, 3), np.float32))
    return p


LAMBERT = {"roughness": 1, "specular": 0}
PATHS = ("megakernel", "wavefront")


def ran(f, paths):
    """The reference pass's report, checked to have run its paths the way asked for."""
    ref = next(p for p in f.report["passes"] if p["name"] == "reference")
    assert ref["paths"] == paths, ref
    return ref


write = load_scene


def furnace(folder, env, bounces, samples, paths="auto"):
    """A white Lambert sphere resting on a white Lambert floor (6 x 6) under L = 1."""
    return write(folder, f"furnace_{bounces}_{paths}", {
        "camera": {"perspective": {"position": [0, 1.5, 3], "look_at": [0, 0.4, 0], "fov_y": 50}, "resolution": [24, 24]},
        "environment": {"path": str(env), "background": "hide"},
        "materials": {"white": {"base_color": [1, 1, 1], **LAMBERT}},
        "objects": [{"sphere": {"center": [0, 0.6, 0], "radius": 0.6}, "material": "white"},
                    {"plane": {"point": [0, 0, 0], "size": 6}, "material": "white"}],
        "effects": {"diffuse": "reference", "specular": "reference",
                    "reference": {"max_samples": samples, "target_noise": 0, "batch": 64, "bounces": bounces,
                                  "paths": paths}}})


@pytest.mark.slow
@pytest.mark.parametrize("paths", PATHS)
def test_white_furnace_converges_to_one(tmp_path, white, paths):
    """Unbounded paths: every pixel of the sphere and the floor is 1 (at 1024 samples the mean
    within 0.1%, measured 0.013%; the RMS over the pixels within 1.5%, measured 0.46% (0.44-0.75%
    over seeds 1-6 with the earlier Halton dimensions); 99% of them within 4%, measured 1.5%):
    noise, not bias. The worst pixel is not bounded: in an albedo-1 furnace a path survives
    roulette with 0.95 a bounce and its throughput grows by 1 / 0.95 each time, so a rare long
    path is a firefly (worst pixel 2.9%; 2.7-11.5% over seeds 1-6 with the Halton dimensions). The direct
    light alone (bounces 1) misses what the sphere and the floor send each other: 10% or more at
    the contact."""
    sc = furnace(tmp_path, white, "unbounded", 1024, paths)
    f = render(sc, cache_root=tmp_path / "cache")
    hit = f.hdr[..., 3] > 0.999
    got = f.hdr[..., :3][hit]
    err = np.abs(got - 1)
    rms, p99 = np.sqrt(np.mean(err ** 2)), np.quantile(err, 0.99)
    print(f"furnace ({paths}): mean {got.mean():.5f}, rms {rms:.4f}, 99% {p99:.4f}, worst {err.max():.4f} over {hit.sum()} px")
    assert abs(got.mean() - 1) < 1e-3 and rms < 0.015 and p99 < 0.04
    ref = ran(f, paths)
    assert ref["bounces"] == "unbounded" and "BOUNCES" in f.report["effects"]["defines"]["reference"]
    direct = render(furnace(tmp_path, white, 1, 256), cache_root=tmp_path / "cache").hdr[..., :3][hit]
    print(f"direct only: mean {direct.mean():.4f}, min {direct.min():.4f}")
    assert direct.min() < 0.9 and direct.mean() < got.mean() - 0.02


def enclosure(folder, env, a, e, bounces, samples=128, paths="auto"):
    """The camera inside a sphere of albedo a (Lambert) that emits e: L = e / (1 - a) everywhere."""
    return write(folder, f"enclosure_{bounces}_{paths}", {
        "camera": {"perspective": {"position": [0.3, -0.2, 0.5], "look_at": [0, 0, -1], "fov_y": 90},
                   "resolution": [16, 16]},
        "environment": {"path": str(env), "background": "hide"},
        "materials": {"wall": {"base_color": [a] * 3, "emissive": e, **LAMBERT}},
        "objects": [{"sphere": {"center": [0, 0, 0], "radius": 2}, "material": "wall"}],
        "effects": {"diffuse": "reference", "specular": "reference",
                    "reference": {"max_samples": samples, "target_noise": 0, "batch": 64, "bounces": bounces,
                                  "paths": paths}}})


@pytest.mark.parametrize("paths", PATHS)
@pytest.mark.parametrize("bounces", [1, 2, 4, "unbounded"])
def test_enclosure_is_emission_over_one_minus_albedo(tmp_path, black, bounces, paths):
    """Inside a sphere of albedo 0.5 emitting E: E (1 + a + ... + a^k) after k > 1 bounces, exact (1e-5)
    before Russian roulette starts (paths.h RR_DEPTH, bounce 4): every path's estimate is the sum
    itself; from there on, and unbounded (E / (1 - a)), roulette's noise: mean within 0.5%,
    measured 0.09% unbounded and under 1e-5 at 4 bounces (the roulette's dimension is stratified)."""
    a, e = 0.5, np.array([1.0, 0.5, 0.25])
    f = render(enclosure(tmp_path, black, a, e.tolist(), bounces, paths=paths), cache_root=tmp_path / "cache")
    ran(f, paths if bounces != 1 else "megakernel")       # the direct light alone has no path
    got = f.hdr[..., :3].reshape(-1, 3)
    # bounces 1 is the environment's direct light only: the walls' light reaches nothing
    want = e / (1 - a) if bounces == "unbounded" else e * sum(a ** j for j in range(bounces + 1 if bounces > 1 else 1))
    if bounces in (1, 2):
        assert np.abs(got / want - 1).max() < 1e-5, (got[:2], want)
    else:
        rel = np.abs(got.mean(0) / want - 1)
        print(f"bounces {bounces}: mean {got.mean(0)} against {want}: {rel.max():.5f}")
        assert rel.max() < 5e-3


@pytest.mark.parametrize("paths", PATHS)
def test_no_path_where_light_cannot_pass(tmp_path, white, paths):
    """A lone sphere seen from outside never sees itself, nor anything with visibility off: the
    reference compiles no path code there, as bounces: 1 (the default), whichever way the paths
    are asked to run (the direct light is the megakernel's)."""
    base = {"camera": {"perspective": {"position": [0, 0, 3]}, "resolution": [8, 8]},
            "environment": {"path": str(white)}, "materials": {"m": {}},
            "effects": {"diffuse": "reference", "specular": "reference",
                        "reference": {"max_samples": 2, "bounces": "unbounded", "paths": paths}}}
    lone = write(tmp_path, "lone", {**base, "objects": [{"sphere": {"radius": 1}, "material": "m"}]})
    two = [{"sphere": {"radius": 1}, "material": "m"}, {"plane": {"point": [0, -1, 0]}, "material": "m"}]
    unseen = write(tmp_path, "unseen", {**base, "objects": two,
                                        "effects": {**base["effects"], "reference": {"visibility": False,
                                                                                     "bounces": "unbounded",
                                                                                     "paths": paths}}})
    inside = write(tmp_path, "inside", {**base, "objects": [{"sphere": {"radius": 5}, "material": "m"}]})
    for sc, traced in ((lone, False), (unseen, False), (inside, True)):
        f = render(sc, cache_root=tmp_path / "cache")
        defines = f.report["effects"]["defines"]["reference"]
        assert ("BOUNCES" in defines) == traced, sc.source
        assert ("WAVEFRONT" in defines) == (traced and paths == "wavefront"), sc.source
        ran(f, paths if traced else "megakernel")


@pytest.mark.parametrize("paths", PATHS)
@pytest.mark.parametrize("bounces", [2, "unbounded"])
def test_point_light_in_an_enclosure(tmp_path, black, bounces, paths):
    """A point light of I candela at the centre of a sphere of radius R and albedo a: the walls
    receive E = I / R^2 straight on and send L = (a E / pi)(1 + a + ... + a^(k-1)) after k bounces,
    (a E / pi) / (1 - a) unbounded. Paths sample the light at every later vertex (the lights pass
    lights the first): bounces 2 is exact (1e-5), unbounded roulette's noise (0.1%, measured 0.013%
    at 512 samples)."""
    a, radius, intensity = 0.5, 2.0, 4.0
    sc = enclosure(tmp_path, black, a, [0, 0, 0], bounces, samples=512, paths=paths)
    sc.data["lights"] = [{"point": {"position": [0, 0, 0], "color": [1, 1, 1], "intensity": intensity,
                                    "radius": 0.0, "range": None}, "shadows": "hard", "shadow_samples": 16}]
    f = render(sc, cache_root=tmp_path / "cache")
    ran(f, paths)
    assert "PATH_LIGHTS" in f.report["effects"]["defines"]["reference"]
    direct = a * intensity / radius ** 2 / np.pi
    got = f.hdr[..., :3].reshape(-1, 3)
    if bounces == 2:
        assert np.abs(got / (direct * (1 + a)) - 1).max() < 1e-5, got[:2]
    else:
        rel = abs(got.mean() / (direct / (1 - a)) - 1)
        print(f"unbounded: {got.mean():.5f} against {direct / (1 - a):.5f}: {rel:.5f}")
        assert rel < 1e-3


@pytest.mark.parametrize("paths", PATHS)
def test_shadow_rays_lose_no_light_on_a_lone_sphere(tmp_path, paths):
    """A sphere alone under small bright lamps (near the horizon, where the upper half sees them at
    grazing angles) cannot shadow itself: with visibility on, every shadow ray that leaves the
    surface arrives, so the frame equals the one with visibility off sample for sample (the same
    seeds, the same estimates; measured max relative difference 0)."""
    from iblbake.core import conventions
    d = conventions.equirect_texel_dirs(512, 256)
    img = np.full(d.shape, 0.02, np.float32)
    for az in (0.3, 2.1, 4.0):
        lamp = np.array([np.cos(az), 0.08, np.sin(az)])
        img[(d @ (lamp / np.linalg.norm(lamp))) > np.cos(np.radians(2.5))] = 500.0
    env = tmp_path / "lamps.exr"
    images.write_exr(env, img)
    frames = []
    for visibility in (True, False):
        sc = write(tmp_path, f"lone_{visibility}_{paths}", {
            "camera": {"orthographic": {"position": [0, 5, 7], "look_at": [0, 0, 0], "width": 1.4},
                       "resolution": [48, 48]},
            "environment": {"path": str(env), "background": "hide"},
            "materials": {"m": {"base_color": [0.6, 0.6, 0.6], "roughness": 0.4}},
            "objects": [{"sphere": {"center": [0, 0, 0], "radius": 0.6}, "material": "m"}],
            "effects": {"diffuse": "reference", "specular": "reference",
                        "reference": {"max_samples": 64, "target_noise": 0, "visibility": visibility,
                                      "paths": paths}}})
        f = render(sc, cache_root=tmp_path / "cache")
        ran(f, "megakernel")              # a lone sphere: the direct light, no path to run either way
        frames.append(f.hdr[..., :3])
    hit = frames[1].sum(-1) > 0
    rel = np.abs(frames[0][hit] / frames[1][hit] - 1)
    assert hit.sum() > 1000 and rel.max() < 1e-6, rel.max()


@pytest.mark.slow
def test_kernel_traces_the_twins_paths(tmp_path):
    """The numpy twin (render/twin/paths.py) follows the kernel's paths sample for sample (the same
    dimensions, lobes, roulette): a rough gold sphere on a Lambert floor and a mirror beside it
    under a lamp-lit panorama, unbounded, 32 samples: every pixel within 2.6e-5 of the twin
    (measured; median 1e-7). A path whose float32 and float64 decisions part (a CDF boundary, a
    roulette draw) would differ whole, so the bound leaves 1% of pixels for that: 99% within 1e-4,
    the frame's mean within 1e-4."""
    from iblbake.core import conventions, sampling
    from iblbake.render import twin as rr
    from iblbake.render.twin import paths
    from iblbake.scene import pack
    d = conventions.equirect_texel_dirs(64, 32)
    img = (0.3 + 0.2 * d[..., 1:2] + np.zeros(3)).astype(np.float32)
    img[(d @ np.array([0.6, 0.5, 0.62])) > 0.97] = [40.0, 30.0, 20.0]
    env = tmp_path / "lamp.exr"
    images.write_exr(env, img)
    sc = write(tmp_path, "twin", {
        "camera": {"perspective": {"position": [0, 1.5, 3.5], "look_at": [0, 0.5, 0], "fov_y": 45},
                   "resolution": [32, 24]},
        "environment": {"path": str(env), "background": "hide", "rotation_y": 25},
        "materials": {"gold": {"base_color": [1.0, 0.78, 0.34], "metallic": 1, "roughness": 0.4},
                      "mirror": {"base_color": [0.9, 0.9, 0.9], "metallic": 1, "roughness": 0},
                      "floor": {"base_color": [0.5, 0.45, 0.4], "roughness": 0.8}},
        "objects": [{"sphere": {"center": [-0.5, 0.5, 0], "radius": 0.5}, "material": "gold"},
                    {"sphere": {"center": [0.6, 0.4, 0.2], "radius": 0.4}, "material": "mirror"},
                    {"plane": {"point": [0, 0, 0], "size": 5}, "material": "floor"}],
        "effects": {"diffuse": "reference", "specular": "reference",
                    "reference": {"max_samples": 32, "target_noise": 0, "batch": 16, "bounces": "unbounded"}}})
    got = render(sc, cache_root=tmp_path / "cache").hdr[..., :3].reshape(-1, 3)
    arrays = pack.scene_arrays(sc)
    gb = rr.primary(sc["camera"], arrays)
    want = paths.radiance(gb, arrays, sc["effects"], sc["environment"], img, sampling.EnvironmentDistribution(img), 32)
    hit = gb["hit"]
    rel = (np.abs(got[hit] - want[hit]) / np.maximum(np.abs(want[hit]), 1e-6)).max(1)
    print(f"twin: {np.mean(rel < 1e-4):.3f} of {hit.sum()} px within 1e-4, {np.mean(rel < 1e-3):.3f} within 1e-3; "
          f"worst {rel.max():.2e}, median {np.median(rel):.2e}; means {got[hit].mean():.6f} / {want[hit].mean():.6f}")
    assert np.mean(rel < 1e-4) >= 0.99
    assert abs(got[hit].mean() / want[hit].mean() - 1) < 1e-4


def test_sample_slices_keep_the_frame(tmp_path, white, monkeypatch):
    """A GPU shares each G-buffer sample's batch among several work items (passes/reference.py
    sample_slices): the frame is the one of one item per sample, to float32 summation (measured
    max relative difference 3.6e-7), with the odd sums and the sample count alike."""
    from iblbake.render.passes import reference as ref_pass
    sc = furnace(tmp_path, white, "unbounded", 64)
    one = render(sc, cache_root=tmp_path / "cache")
    monkeypatch.setattr(ref_pass, "sample_slices", lambda rt, n, batch: 5)
    five = render(sc, cache_root=tmp_path / "cache")
    a, b = one.hdr[..., :3], five.hdr[..., :3]
    hit = one.hdr[..., 3] > 0
    rel = np.abs(a[hit] - b[hit]) / np.maximum(a[hit], 1e-6)
    print(f"slices 5 against 1: max relative difference {rel.max():.2e}")
    p1, p5 = (next(p for p in f.report["passes"] if p["name"] == "reference") for f in (one, five))
    assert p5["work_items_per_sample"] == 5 and p1["samples_per_pixel"] == p5["samples_per_pixel"]
    assert rel.max() < 2e-6


def test_every_sample_dimension_is_stratified_owen_sobol():
    """Every dimension pair of a sample (kernels/sampler.h, its twin: the first vertex's too): the
    first 2^m samples of a G-buffer sample put exactly one point in each 1/2^m of each axis and
    one in each cell of a 2^a x 2^(m-a) grid (a (0, m, 2)-net: what Owen-scrambled Sobol keeps),
    also at a count that is not a power of two at most one point a cell; G-buffer samples and
    pairs differ, and every value is in [0, 1). With two replicates (a noise target), each of
    the even and odd samples is such a sequence of its own."""
    from iblbake.core.sampling import Sampler
    k = np.arange(256)

    def pairs(gid, replicates=1, kk=k):
        sp = Sampler.replicate(1, np.full(len(kk), gid), kk, replicates)
        return [sp.next_2d() for _ in range(6)]

    def net(u, m):
        x, y = u[:, 0], u[:, 1]
        assert ((x >= 0) & (x < 1) & (y >= 0) & (y < 1)).all()
        for a in range(m + 1):
            cells = (np.floor(x * 2 ** a) * 2 ** (m - a) + np.floor(y * 2 ** (m - a))).astype(int)
            assert len(np.unique(cells)) == 2 ** m, a

    for gid in (0, 77, 2 ** 31 + 5):
        ps = pairs(gid)
        for u in ps:
            net(u, 8)
            cells = (np.floor(u[:96, 0] * 8) * 16 + np.floor(u[:96, 1] * 16)).astype(int)
            assert np.bincount(cells).max() == 1                    # 96 samples, 128 cells
        assert abs(np.corrcoef(ps[0][:, 0], ps[1][:, 0])[0, 1]) < 0.2
    assert not np.allclose(pairs(0)[0], pairs(1)[0])
    two = pairs(5, replicates=2, kk=np.arange(512))
    for u in two:
        net(u[0::2], 8)
        net(u[1::2], 8)
    assert not np.allclose(two[0][0::2], two[0][1::2])


@pytest.mark.parametrize("paths", PATHS)
def test_textured_glb_through_paths(tmp_path, white, paths):
    """A textured glTF (examples/meshes/tiles.glb: base colour, metallic-roughness and normal maps)
    on a floor: its maps are read at every path vertex (level 0), the frame is finite, and the
    light the tiles and the floor exchange makes it brighter than the direct light alone (measured
    1.11x; bound 1.05x)."""
    mesh = Path(__file__).resolve().parents[1] / "examples" / "meshes" / "tiles.glb"
    frames = {}
    for bounces in (1, "unbounded"):
        sc = write(tmp_path, f"tiles_{bounces}_{paths}", {
            "camera": {"perspective": {"position": [0, 1.2, 2.5], "look_at": [0, 0, 0], "fov_y": 50},
                       "resolution": [24, 16]},
            "environment": {"path": str(white), "background": "hide"},
            "materials": {"floor": {"base_color": [0.7, 0.7, 0.7], **LAMBERT}},
            "objects": [{"mesh": {"path": str(mesh), "rotate": [-90, 0, 0], "translate": [0, 0.05, 0]}},
                        {"plane": {"point": [0, 0, 0], "size": 4}, "material": "floor"}],
            "effects": {"diffuse": "reference", "specular": "reference",
                        "reference": {"max_samples": 16, "target_noise": 0, "bounces": bounces,
                                      "paths": paths}}})
        f = render(sc, cache_root=tmp_path / "cache")
        ran(f, paths if bounces != 1 else "megakernel")
        frames[bounces] = f.hdr[..., :3]
        assert np.isfinite(f.hdr).all()
    defines = f.report["effects"]["defines"]["reference"]
    assert "BOUNCES" in defines and "HAS_TEXTURES" in defines
    print(f"tiles: unbounded / direct {frames['unbounded'].mean() / frames[1].mean():.3f}")
    assert frames["unbounded"].mean() > frames[1].mean() * 1.05


def test_textured_gbuffer_in_a_program_with_paths_matches_the_twin(tmp_path, white):
    """The material pass's normal-mapped normals (the normal AOV) of examples/meshes/tiles.glb in a
    frame whose program also holds the reference's paths, which read the same material_sample at
    every vertex, against the float64 twin (resolve_materials). Intel's CPU runtime left
    material_sample out of line there and passed its float3 normal wrongly from the vectorised
    material pass: normals off by up to 1.8 (unit vectors) and garbage, the bounces' light 1.6%
    instead of 11% (kernels/inline.h). Measured 1.2e-6 at most on PoCL and Intel's runtime alike;
    bound 2e-5."""
    from iblbake.render import twin as rr
    from iblbake.scene import pack
    mesh = Path(__file__).resolve().parents[1] / "examples" / "meshes" / "tiles.glb"
    sc = write(tmp_path, "tiles", {
        "camera": {"perspective": {"position": [0, 1.2, 2.5], "look_at": [0, 0, 0], "fov_y": 50},
                   "resolution": [32, 24]},
        "environment": {"path": str(white), "background": "hide"},
        "materials": {"floor": {"base_color": [0.7, 0.7, 0.7], **LAMBERT}},
        "objects": [{"mesh": {"path": str(mesh), "rotate": [-90, 0, 0], "translate": [0, 0.05, 0]}},
                    {"plane": {"point": [0, 0, 0], "size": 4}, "material": "floor"}],
        "effects": {"diffuse": "reference", "specular": "reference",
                    "reference": {"max_samples": 2, "target_noise": 0, "bounces": "unbounded"}}})
    sc.data["output"]["normal"] = str(tmp_path / "normal.exr")
    f = render(sc, cache_root=tmp_path / "cache")
    assert "BOUNCES" in f.report["effects"]["defines"]["reference"]
    arrays = pack.scene_arrays(sc)
    tex = rr.textures(sc, arrays)
    gb = rr.primary(sc["camera"], arrays, tex)
    rr.gbuffer_coords(gb, arrays, sc["camera"])
    rr.resolve_materials(gb, arrays, tex)
    w, h = sc["camera"]["resolution"]
    spp = sc["camera"]["spp"]
    nrm = np.zeros((len(gb["hit"]), 3))
    nrm[gb["hit"]] = gb["resolved"][4]
    full = (f.hdr[..., 3] == 1) & gb["hit"].reshape(h, w, spp).all(2)
    want = nrm.reshape(h, w, spp, 3).mean(2)[full]
    err = np.abs(f.aovs["normal"][..., :3][full] - want).max(1)
    on_mesh = full & (f.aovs["normal"][..., 1] < 0.999)                # the tiles, not the flat floor
    print(f"gbuffer normals vs twin: max {err.max():.2e}, median {np.median(err):.2e} over {full.sum()} px "
          f"({on_mesh.sum()} on the mesh)")
    assert on_mesh.sum() > 100 and err.max() < 2e-5


@pytest.mark.external
@pytest.mark.slow
def test_glossy_interreflection_passes_mitsubas_acceptance_test(tmp_path):
    """A rough metal sphere (GGX alpha 0.09) on a rough metal floor (alpha 0.25) in a box of
    coloured Lambert walls under courtyard: light reaches the camera by one glossy lobe after
    another, which no closed form above holds. Mitsuba 3's own acceptance test of an integrator
    (benchmarks/mitsuba_paths.py: iblbake's 6 renders of 128 samples per pixel against Mitsuba's
    `path` at 4096 samples per pixel centre, a two-sided z-test per pixel channel, alpha 0.01 with
    Sidak's correction) passes where at least 99.75% of them agree (measured 99.99% at 8 renders;
    iblbake's mean 0.3% above Mitsuba's: Mitsuba's separable Smith G against iblbake's
    height-correlated one). `make peers` installs Mitsuba and Debian's libllvm19."""
    import os
    import sys
    os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM-19.so")
    try:
        import mitsuba as mi
    except ImportError:
        pytest.fail("Mitsuba 3 is not installed: run `make peers`")
    mi.set_variant("llvm_ad_rgb")
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import mitsuba_paths as mp
    from iblbake.render import Bakes
    from iblbake.device.runtime import Runtime

    pano, spread = mp.panorama_pair(tmp_path)
    objects, mats = mp.scenes(tmp_path)["glossy box"]
    res = mp.acceptance(mi, tmp_path, pano, spread, objects, mats, 6, 128, 4096, Runtime(),
                        Bakes(tmp_path / "cache"))
    assert res["rate"] >= 0.9975, res
    assert np.abs(res["ratio"] - 1).max() < 0.01, res


def test_the_paths_register_cap_is_asked_for_on_nvidia_gpus_only():
    """device/launch.py build_options: the programs holding the paths (alone or among a frame's
    kernel files) get NVIDIA's register cap on an NVIDIA GPU; other programs and devices none."""
    from iblbake.device import launch
    from iblbake.device.choice import DeviceInfo

    nv = DeviceInfo("0:0", "NVIDIA CUDA", "NVIDIA H200", "GPU")
    cap = [f"-cl-nv-maxrregcount={launch.PATH_REGISTERS}"]
    assert launch.build_options(nv, ("gbuffer.cl", "paths/reference.cl", "resolve.cl")) == cap
    assert launch.build_options(nv, "paths/probe_trace.cl") == cap
    assert launch.build_options(nv, ("gbuffer.cl", "shade.cl")) == []
    for other in (DeviceInfo("0:0", "Portable Computing Language", "cpu", "CPU"),
                  DeviceInfo("0:0", "AMD Accelerated Parallel Processing", "gfx90a", "GPU")):
        assert launch.build_options(other, ("gbuffer.cl", "paths/reference.cl")) == []


def test_pocl_launches_are_split_into_many_groups(rt):
    """device/launch.py cpu_group: a one-dimensional launch on PoCL is cut into at least
    CPU_GROUPS_PER_CORE groups a core (PoCL's own choice made a 64x48 frame's 3072 paths one group
    on one core), each a divisor of the launch, at most MAX_GROUP; and Runtime.run asks for it for
    the path kernels (SPLIT_KERNELS) alone."""
    from iblbake.device import launch
    assert launch.cpu_group(3072, 2) == 24 and launch.cpu_group(49152, 2) == 384
    assert launch.cpu_group(1 << 20, 2) == launch.MAX_GROUP and launch.cpu_group(97 * 61, 2) == 1
    for items in (1, 7, 3072, 5917, 12288, 65536, 1 << 22):
        for cores in (1, 2, 16):
            g = launch.cpu_group(items, cores)
            assert items % g == 0 and 1 <= g <= launch.MAX_GROUP
            assert g == 1 or items // g >= launch.CPU_GROUPS_PER_CORE * cores or g == launch.MAX_GROUP
    seen = []

    class Kernel:
        function_name = "reference"

        def __call__(self, queue, global_size, local_size, *args):
            seen.append(local_size)

    rt.run(Kernel(), (3072,), None)
    rt.run(Kernel(), (64, 48), None)
    rt.run(Kernel(), (3072,), (8,))
    other = Kernel()
    other.function_name = "shade"
    rt.run(other, (3072,), None)
    from iblbake.device.choice import _matches
    pocl = rt.info.kind == "CPU" and _matches(rt.info, "pocl")      # Runtime's own test (its _split)
    cores = rt.info.device.max_compute_units
    assert seen == [(launch.cpu_group(3072, cores),) if pocl else None, None, (8,), None]


def lamp_panorama(folder):
    """A sky brightening upwards with one bright lamp (the twin test's)."""
    from iblbake.core import conventions
    d = conventions.equirect_texel_dirs(64, 32)
    img = (0.3 + 0.2 * d[..., 1:2] + np.zeros(3)).astype(np.float32)
    img[(d @ np.array([0.6, 0.5, 0.62])) > 0.97] = [40.0, 30.0, 20.0]
    env = folder / "lamp.exr"
    images.write_exr(env, img)
    return env


MESHES = Path(__file__).resolve().parents[1] / "examples" / "meshes"
EQUAL_SCENES = {
    # rough gold, a mirror (a delta lobe) and a glossy floor
    "spheres": ([{"sphere": {"center": [-0.5, 0.5, 0], "radius": 0.5}, "material": "gold"},
                 {"sphere": {"center": [0.6, 0.4, 0.2], "radius": 0.4}, "material": "mirror"}], []),
    # the 102,400-triangle knot (the BVH, interpolated normals) in rough metal
    "knot": ([{"mesh": {"path": str(MESHES / "knot.ply"), "scale": 0.5, "translate": [0, 0.6, 0]},
               "material": "gold"}], []),
    # a textured glTF: base colour, metallic-roughness and normal maps at every vertex
    "textured": ([{"mesh": {"path": str(MESHES / "tiles.glb"), "rotate": [-90, 0, 0], "translate": [0, 0.05, 0]}}], []),
    # analytic lights at every later vertex (PATH_LIGHTS): a sun's disk, a sphere light, a spot
    "lights": ([{"sphere": {"center": [-0.5, 0.5, 0], "radius": 0.5}, "material": "gold"},
                {"sphere": {"center": [0.6, 0.4, 0.2], "radius": 0.4}, "material": "floor"}],
               [{"directional": {"direction": [0.5, -1.0, -0.6], "illuminance": 3.0, "angular_diameter": 2.0},
                 "shadows": "soft", "shadow_samples": 4},
                {"point": {"position": [1.5, 1.5, 1.0], "color": [1.0, 0.8, 0.6], "intensity": 4.0, "radius": 0.1,
                           "range": 10}, "shadows": "hard"},
                {"spot": {"position": [-1.5, 2.0, 1.5], "direction": [0.6, -1.0, -0.3], "intensity": 12.0,
                          "inner_cone_angle": 12, "outer_cone_angle": 22}, "shadows": "hard"}]),
}


def equal_scene_frame(folder, name, paths, rt=None):
    """EQUAL_SCENES[name] under the lamp, unbounded paths, 16 samples in batches of 6 (the
    wavefront's waves forced to 4 samples, so a batch spans waves): the frame and its report."""
    from iblbake.render.passes import reference as ref_pass
    env = lamp_panorama(folder)
    objects, lights = EQUAL_SCENES[name]
    sc = write(folder, f"{name}_{paths}", {
        "camera": {"perspective": {"position": [0, 1.5, 3.5], "look_at": [0, 0.5, 0], "fov_y": 45},
                   "resolution": [24, 18]},
        "environment": {"path": str(env), "background": "hide", "rotation_y": 25},
        "materials": {"gold": {"base_color": [1.0, 0.78, 0.34], "metallic": 1, "roughness": 0.4},
                      "mirror": {"base_color": [0.9, 0.9, 0.9], "metallic": 1, "roughness": 0},
                      "floor": {"base_color": [0.5, 0.45, 0.4], "roughness": 0.8}},
        "objects": objects + [{"plane": {"point": [0, 0, 0], "size": 5}, "material": "floor"}],
        "lights": lights,
        "effects": {"diffuse": "reference", "specular": "reference",
                    "reference": {"max_samples": 16, "target_noise": 0, "batch": 6, "bounces": "unbounded",
                                  "seed": 7, "paths": paths}}})
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ref_pass, "wave_paths", lambda rt: 4 * 24 * 18)
        f = render(sc, cache_root=folder / "cache", runtime=rt)
    ran(f, paths)
    assert ("PATH_LIGHTS" in f.report["effects"]["defines"]["reference"]) == bool(lights)
    return f


@pytest.mark.parametrize("name", list(EQUAL_SCENES))
def test_wavefront_frame_is_the_megakernels(tmp_path, name):
    """The wavefront's stages (kernels/paths/wavefront.cl) are the megakernel's estimator cut where rays
    are traced, through the same functions (kernels/paths/paths.h), dimensions and sums in the same order:
    for one scene and seed the two frames agree to float32 rounding, pixel for pixel. Unbounded
    paths, 16 samples in batches of 6 (the wavefront's waves forced to 4 samples, so a batch spans
    waves); measured max relative difference 0 on PoCL and on Intel's runtime (every sum bit for
    bit). Bound 1e-6: a GPU shares a sample's batch among work items (sample_slices), which reorders
    the megakernel's float32 sums (3.6e-7, test_sample_slices_keep_the_frame), and a compiler may
    fuse a multiply-add in one and not across the other's stages."""
    frames = {paths: equal_scene_frame(tmp_path, name, paths).hdr[..., :3] for paths in PATHS}
    a, b = frames["megakernel"], frames["wavefront"]
    hit = a.sum(-1) > 0
    rel = np.abs(a[hit] - b[hit]) / np.maximum(np.abs(a[hit]), 1e-6)
    print(f"{name}: wavefront against megakernel, max relative difference {rel.max():.2e} over {hit.sum()} px, "
          f"means {a[hit].mean():.6f} / {b[hit].mean():.6f}")
    assert hit.sum() > 200 and np.isfinite(b).all()
    assert rel.max() < 1e-6


def test_wavefront_launches_are_whole_groups(tmp_path):
    """The wavefront's queues change length at every stage; each launch is rounded up to whole
    groups of QUEUE_GROUP with that local size (device/launch.py queue_launch), so PoCL, which builds
    a kernel again for every work-group size it is given or picks, builds each stage once (a first
    frame at 96x72 took 57 s on PoCL with exact lengths, 2.2 s rounded: the same bits)."""
    from iblbake.device import runtime
    from iblbake.device.launch import QUEUE_GROUP
    rt = runtime.Runtime()
    seen, run = [], rt.run

    def recorded(kernel, global_size, local_size, *args):
        if kernel.function_name.startswith("wf_"):
            seen.append((kernel.function_name, global_size, local_size))
        return run(kernel, global_size, local_size, *args)

    rt.run = recorded
    equal_scene_frame(tmp_path, next(iter(EQUAL_SCENES)), "wavefront", rt)
    assert {s[0] for s in seen} == {"wf_generate", "wf_extend", "wf_shade", "wf_shadow", "wf_accumulate"}
    assert {s[2] for s in seen} == {(QUEUE_GROUP,)} and all(s[1][0] % QUEUE_GROUP == 0 for s in seen)
    assert len({s[1] for s in seen if s[0] == "wf_extend"}) > 3       # the queues did change length


def test_a_gpus_build_gives_the_cpus_frame(tmp_path, monkeypatch):
    """A CPU's kernels traverse the 4-wide BVH and prefetch the panorama's texels (device/programs.py
    device_options: IBL_WIDE_BVH, IBL_PREFETCH); a GPU's are built without either, on the binary
    tree: the knot's frame (escaped rays and environment samples at every vertex, 102k triangles)
    is the same bit for bit either way. The GPU's build runs here on the CPU."""
    from iblbake.device import programs, runtime
    rt = runtime.Runtime()
    assert {programs.WIDE_BVH, programs.PREFETCH} <= set(rt.device_options)
    cpu = equal_scene_frame(tmp_path, "knot", "megakernel", rt)
    options = programs.device_options
    monkeypatch.setattr(programs, "device_options",
                        lambda info: [o for o in options(info) if o not in (programs.WIDE_BVH, programs.PREFETCH)])
    rt = runtime.Runtime()
    assert not {programs.WIDE_BVH, programs.PREFETCH} & set(rt.device_options)
    gpu = equal_scene_frame(tmp_path, "knot", "megakernel", rt)
    np.testing.assert_array_equal(cpu.hdr, gpu.hdr)


def test_paths_key_takes_its_three_values_only(tmp_path, white):
    """effects.reference.paths is auto, megakernel or wavefront; anything else is a one-line error
    naming the key and the choices."""
    from iblbake.errors import InputError
    doc = {"environment": {"path": str(white)},
           "effects": {"diffuse": "reference", "reference": {"paths": "gpu"}}}
    with pytest.raises(InputError, match=r"effects\.reference\.paths: 'gpu' is not one of auto \| megakernel \| "
                                         r"wavefront"):
        write(tmp_path, "bad", doc)
    for way in ("auto", *PATHS):
        doc["effects"]["reference"]["paths"] = way
        assert write(tmp_path, way, doc).data["effects"]["reference"]["paths"] == way


def test_a_wavefront_asked_for_and_not_run_is_said(tmp_path, white):
    """effects.reference.paths: wavefront where the frame traces no paths (no reference term, or
    the reference's direct light alone) is a note, not silence; auto and a running wavefront none."""
    from iblbake.render.plan import plan
    floor = {"plane": {"point": [0, 0, 0], "size": 4}, "material": "m"}
    ball = {"sphere": {"center": [0, 0.5, 0], "radius": 0.5}, "material": "m"}

    def notes(name, diffuse, bounces, paths, objects):
        doc = {"camera": {"perspective": {"position": [0, 1, 3], "look_at": [0, 0.5, 0], "fov_y": 40},
                          "resolution": [8, 6]},
               "environment": {"path": str(white)}, "materials": {"m": {"roughness": 0.5}}, "objects": objects,
               "effects": {"diffuse": diffuse, "reference": {"paths": paths, "bounces": bounces}}}
        return [n for n in plan(write(tmp_path, name, doc)).notes if "effects.reference.paths" in n]

    assert notes("a", "sh", "unbounded", "wavefront", [floor, ball]) == [
        "effects.reference.paths: wavefront not used: no term of this frame is the reference"]
    assert "bounces 1" in notes("b", "reference", 1, "wavefront", [floor, ball])[0]
    assert "bounces 1" in notes("c", "reference", "unbounded", "wavefront", [floor])[0]   # a lone plane
    assert notes("d", "reference", "unbounded", "wavefront", [floor, ball]) == []
    assert notes("e", "sh", "unbounded", "auto", [floor, ball]) == []
