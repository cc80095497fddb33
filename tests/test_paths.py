"""The reference's paths (effects.reference.bounces) against closed forms: a white furnace of
Lambert surfaces (every pixel converges to the environment's 1, however the objects shadow each
other), an enclosure lit by its own emission (E / (1 - a), and E (1 + a + ... + a^k) with k
bounces), what compiles a path and what does not, and bounces: 1 as the direct light of before.
Each closed form runs over every ray source of the one driver (render/paths/trace.py): the camera's
samples (the reference pass), the irradiance probes' rays and a reflection capture's texels."""

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
SOURCES = ("camera", "probe_rays", "capture_texels")
PROBE_RAYS, CAPTURE = 4096, {"size": 16, "samples": 16}      # 8192 rays from each point; 8192 a capture


def ran(f):
    """The reference pass's report."""
    return next(p for p in f.report["passes"] if p["name"] == "reference")


write = load_scene


def traced(source, sc, folder, points, bounces, rt=None):
    """The radiance the paths bring back along every ray of `source` in scene sc, each source through
    the one driver: camera, the frame's pixels that met a surface (the reference pass's
    CameraSamples); probe_rays, PROBE_RAYS rays from each of `points` (PointRays, the irradiance
    probes' rays, but seeing a solid's inside as the camera does: the enclosures are spheres);
    capture_texels, a reflection capture at points[0], its scene and sky parts added (TexelRays)."""
    from iblbake.device.runtime import Runtime
    from iblbake.render import reflection_probes
    from iblbake.render.bakes import Bakes
    from iblbake.render.paths.tracer import Tracer
    from iblbake.render.probes import spherical_fibonacci
    from iblbake.render.units import Job

    if source == "camera":
        f = render(sc, cache_root=folder / "cache")
        return f.hdr[..., :3][f.hdr[..., 3] > 0.999]
    job = Job(sc, rt or Runtime(), Bakes(folder / "cache"))
    if source == "probe_rays":
        tracer = Tracer(job, {"bounces": bounces, "seed": 1}, back_faces_black=False)
        return tracer.trace(np.asarray(points, np.float64), spherical_fibonacci(PROBE_RAYS), True)[0].reshape(-1, 3)
    settings = {"position": list(points[0]), "bounces": bounces, "seed": 1, **CAPTURE}
    img, _ = reflection_probes.capture(reflection_probes.tracer(job, settings), 0, settings)
    return (img[..., :3] + img[..., 4:7]).reshape(-1, 3).astype(np.float64)


def furnace(folder, env, bounces, samples):
    """A white Lambert sphere resting on a white Lambert floor (6 x 6) under L = 1."""
    return write(folder, f"furnace_{bounces}", {
        "camera": {"perspective": {"position": [0, 1.5, 3], "look_at": [0, 0.4, 0], "fov_y": 50}, "resolution": [24, 24]},
        "environment": {"path": str(env), "background": "hide"},
        "materials": {"white": {"base_color": [1, 1, 1], **LAMBERT}},
        "objects": [{"sphere": {"center": [0, 0.6, 0], "radius": 0.6}, "material": "white"},
                    {"plane": {"point": [0, 0, 0], "size": 6}, "material": "white"}],
        "effects": {"diffuse": "reference", "specular": "reference",
                    "reference": {"max_samples": samples, "target_noise": 0, "batch": 64, "bounces": bounces}}})


FURNACE_POINTS = [[1.5, 0.3, 0.5], [-1.2, 1.5, -0.8]]      # above the floor, beside the sphere


@pytest.mark.slow
def test_white_furnace_converges_to_one(tmp_path, white):
    """Unbounded paths: every pixel of the sphere and the floor is 1 (at 1024 samples the mean
    within 0.1%, measured 0.013%; the RMS over the pixels within 1.5%, measured 0.46% (0.44-0.75%
    over seeds 1-6 with the earlier Halton dimensions); 99% of them within 4%, measured 1.5%):
    noise, not bias. The worst pixel is not bounded: in an albedo-1 furnace a path survives
    roulette with 0.95 a bounce and its throughput grows by 1 / 0.95 each time, so a rare long
    path is a firefly (worst pixel 2.9%; 2.7-11.5% over seeds 1-6 with the Halton dimensions). The direct
    light alone (bounces 1) misses what the sphere and the floor send each other: 10% or more at
    the contact."""
    sc = furnace(tmp_path, white, "unbounded", 1024)
    f = render(sc, cache_root=tmp_path / "cache")
    hit = f.hdr[..., 3] > 0.999
    got = f.hdr[..., :3][hit]
    err = np.abs(got - 1)
    rms, p99 = np.sqrt(np.mean(err ** 2)), np.quantile(err, 0.99)
    print(f"furnace: mean {got.mean():.5f}, rms {rms:.4f}, 99% {p99:.4f}, worst {err.max():.4f} over {hit.sum()} px")
    assert abs(got.mean() - 1) < 1e-3 and rms < 0.015 and p99 < 0.04
    ref = ran(f)
    assert ref["bounces"] == "unbounded" and "BOUNCES" in f.report["effects"]["defines"]["reference"]
    direct = render(furnace(tmp_path, white, 1, 256), cache_root=tmp_path / "cache").hdr[..., :3][hit]
    print(f"direct only: mean {direct.mean():.4f}, min {direct.min():.4f}")
    assert direct.min() < 0.9 and direct.mean() < got.mean() - 0.02


@pytest.mark.parametrize("source", SOURCES[1:])
def test_white_furnace_rays_bring_back_one(tmp_path, white, source):
    """The white furnace along the rays of the other sources: every ray from a point beside the
    sphere brings back 1, whatever it meets (one path a ray: the mean over the 8192 rays within 1%;
    measured 0.26% for the probes' rays, 0.04% for the capture's texels)."""
    sc = furnace(tmp_path, white, "unbounded", 4)
    got = traced(source, sc, tmp_path, FURNACE_POINTS, "unbounded")
    print(f"furnace ({source}): mean {got.mean(0)} over {len(got)} rays or texels, max {got.max():.4f}")
    assert np.abs(got.mean(0) - 1).max() < 1e-2


def enclosure(folder, env, a, e, bounces, samples=128):
    """The camera inside a sphere of albedo a (Lambert) that emits e: L = e / (1 - a) everywhere."""
    return write(folder, f"enclosure_{bounces}", {
        "camera": {"perspective": {"position": [0.3, -0.2, 0.5], "look_at": [0, 0, -1], "fov_y": 90},
                   "resolution": [16, 16]},
        "environment": {"path": str(env), "background": "hide"},
        "materials": {"wall": {"base_color": [a] * 3, "emissive": e, **LAMBERT}},
        "objects": [{"sphere": {"center": [0, 0, 0], "radius": 2}, "material": "wall"}],
        "effects": {"diffuse": "reference", "specular": "reference",
                    "reference": {"max_samples": samples, "target_noise": 0, "batch": 64, "bounces": bounces}}})


INSIDE = [[0.3, -0.2, 0.5], [-0.5, 0.4, -0.3]]       # points inside the enclosures (the camera's first)
# the mean's bound past Russian roulette, per source: a camera's pixel holds 128 paths (stratified), a
# ray one path
ROULETTE = {"camera": 5e-3, "probe_rays": 1e-2, "capture_texels": 1e-2}


@pytest.mark.parametrize("source", SOURCES)
@pytest.mark.parametrize("bounces", [1, 2, 4, "unbounded"])
def test_enclosure_is_emission_over_one_minus_albedo(tmp_path, black, bounces, source):
    """Inside a sphere of albedo 0.5 emitting E: E (1 + a + ... + a^k) after k > 1 bounces, exact (1e-5)
    before Russian roulette starts (layout.py RR_DEPTH, bounce 4): every path's estimate is the sum
    itself; from there on, and unbounded (E / (1 - a)), roulette's noise: the camera's mean within
    0.5%, measured 0.09% unbounded and under 1e-5 at 4 bounces (the roulette's dimension is
    stratified); a ray's one path within 1% over 8192 rays, measured 0.013% (4 bounces) and 0.024%
    (unbounded) for the probes' rays, 0.25% and 0.53% for the capture's texels. Bounces 1: the camera's is the environment's direct
    light (the walls' light reaches nothing: E), a ray's the surfaces it sees lit directly (E (1 + a))."""
    a, e = 0.5, np.array([1.0, 0.5, 0.25])
    sc = enclosure(tmp_path, black, a, e.tolist(), bounces)
    got = traced(source, sc, tmp_path, INSIDE, bounces)
    k = (0 if source == "camera" else 1) if bounces == 1 else bounces
    want = e / (1 - a) if bounces == "unbounded" else e * sum(a ** j for j in range(k + 1))
    if bounces in (1, 2):
        assert np.abs(got / want - 1).max() < 1e-5, (got[:2], want)
    else:
        rel = np.abs(got.mean(0) / want - 1)
        print(f"{source}, bounces {bounces}: mean {got.mean(0)} against {want}: {rel.max():.5f}")
        assert rel.max() < ROULETTE[source]


def test_no_path_where_light_cannot_pass(tmp_path, white):
    """A lone sphere seen from outside never sees itself, nor anything with visibility off: the
    reference compiles no path code there, as bounces: 1 (the default)."""
    base = {"camera": {"perspective": {"position": [0, 0, 3]}, "resolution": [8, 8]},
            "environment": {"path": str(white)}, "materials": {"m": {}},
            "effects": {"diffuse": "reference", "specular": "reference",
                        "reference": {"max_samples": 2, "bounces": "unbounded"}}}
    lone = write(tmp_path, "lone", {**base, "objects": [{"sphere": {"radius": 1}, "material": "m"}]})
    two = [{"sphere": {"radius": 1}, "material": "m"}, {"plane": {"point": [0, -1, 0]}, "material": "m"}]
    unseen = write(tmp_path, "unseen", {**base, "objects": two,
                                        "effects": {**base["effects"], "reference": {"visibility": False,
                                                                                     "bounces": "unbounded"}}})
    inside = write(tmp_path, "inside", {**base, "objects": [{"sphere": {"radius": 5}, "material": "m"}]})
    for sc, traced in ((lone, False), (unseen, False), (inside, True)):
        f = render(sc, cache_root=tmp_path / "cache")
        defines = f.report["effects"]["defines"]["reference"]
        assert ("BOUNCES" in defines) == traced, sc.source


@pytest.mark.parametrize("source", SOURCES)
@pytest.mark.parametrize("bounces", [2, "unbounded"])
def test_point_light_in_an_enclosure(tmp_path, black, bounces, source):
    """A point light of I candela at the centre of a sphere of radius R and albedo a: the walls
    receive E = I / R^2 straight on and send L = (a E / pi)(1 + a + ... + a^(k-1)) after k bounces,
    (a E / pi) / (1 - a) unbounded. Paths sample the light at every later vertex (the lights pass
    lights the first; a ray's first vertex is a later one): bounces 2 is exact (1e-5), unbounded
    roulette's noise (the camera's 0.1%, measured 0.013% at 512 samples; over 8192 rays of one path
    1%, measured 0.23% for the probes' rays and 0.18% for the capture's texels)."""
    a, radius, intensity = 0.5, 2.0, 4.0
    sc = enclosure(tmp_path, black, a, [0, 0, 0], bounces, samples=512)
    sc.data["lights"] = [{"point": {"position": [0, 0, 0], "color": [1, 1, 1], "intensity": intensity,
                                    "radius": 0.0, "range": None}, "shadows": "hard", "shadow_samples": 16}]
    got = traced(source, sc, tmp_path, INSIDE, bounces)
    direct = a * intensity / radius ** 2 / np.pi
    if bounces == 2:
        assert np.abs(got / (direct * (1 + a)) - 1).max() < 1e-5, got[:2]
    else:
        rel = abs(got.mean() / (direct / (1 - a)) - 1)
        print(f"{source}, unbounded: {got.mean():.5f} against {direct / (1 - a):.5f}: {rel:.5f}")
        assert rel < {"camera": 1e-3}.get(source, ROULETTE[source])


def test_shadow_rays_lose_no_light_on_a_lone_sphere(tmp_path):
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
        sc = write(tmp_path, f"lone_{visibility}", {
            "camera": {"orthographic": {"position": [0, 5, 7], "look_at": [0, 0, 0], "width": 1.4},
                       "resolution": [48, 48]},
            "environment": {"path": str(env), "background": "hide"},
            "materials": {"m": {"base_color": [0.6, 0.6, 0.6], "roughness": 0.4}},
            "objects": [{"sphere": {"center": [0, 0, 0], "radius": 0.6}, "material": "m"}],
            "effects": {"diffuse": "reference", "specular": "reference",
                        "reference": {"max_samples": 64, "target_noise": 0, "visibility": visibility}}})
        f = render(sc, cache_root=tmp_path / "cache")
        assert "BOUNCES" not in f.report["effects"]["defines"]["reference"]      # a lone sphere: the direct light, no path
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


def test_textured_glb_through_paths(tmp_path, white):
    """A textured glTF (examples/meshes/tiles.glb: base colour, metallic-roughness and normal maps)
    on a floor: its maps are read at every path vertex (level 0), the frame is finite, and the
    light the tiles and the floor exchange makes it brighter than the direct light alone (measured
    1.11x; bound 1.05x)."""
    mesh = Path(__file__).resolve().parents[1] / "examples" / "meshes" / "tiles.glb"
    frames = {}
    for bounces in (1, "unbounded"):
        sc = write(tmp_path, f"tiles_{bounces}", {
            "camera": {"perspective": {"position": [0, 1.2, 2.5], "look_at": [0, 0, 0], "fov_y": 50},
                       "resolution": [24, 16]},
            "environment": {"path": str(white), "background": "hide"},
            "materials": {"floor": {"base_color": [0.7, 0.7, 0.7], **LAMBERT}},
            "objects": [{"mesh": {"path": str(mesh), "rotate": [-90, 0, 0], "translate": [0, 0.05, 0]}},
                        {"plane": {"point": [0, 0, 0], "size": 4}, "material": "floor"}],
            "effects": {"diffuse": "reference", "specular": "reference",
                        "reference": {"max_samples": 16, "target_noise": 0, "bounces": bounces}}})
        f = render(sc, cache_root=tmp_path / "cache")
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


def equal_scene_frame(folder, name, rt=None):
    """EQUAL_SCENES[name] under the lamp, unbounded paths, 16 samples in batches of 6: the frame and
    its report."""
    env = lamp_panorama(folder)
    objects, lights = EQUAL_SCENES[name]
    sc = write(folder, f"{name}", {
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
                                  "seed": 7}}})
    f = render(sc, cache_root=folder / "cache", runtime=rt)
    assert ("PATH_LIGHTS" in f.report["effects"]["defines"]["reference"]) == bool(lights)
    return f


def test_a_gpus_build_gives_the_cpus_frame(tmp_path, monkeypatch):
    """A CPU's kernels traverse the 4-wide BVH and prefetch the panorama's texels (device/programs.py
    device_options: IBL_WIDE_BVH, IBL_PREFETCH); a GPU's are built without either, on the binary
    tree: the knot's frame (escaped rays and environment samples at every vertex, 102k triangles)
    is the same bit for bit either way. The GPU's build runs here on the CPU."""
    from iblbake.device import programs, runtime
    rt = runtime.Runtime()
    assert {programs.WIDE_BVH, programs.PREFETCH} <= set(rt.device_options)
    cpu = equal_scene_frame(tmp_path, "knot", rt)
    options = programs.device_options
    monkeypatch.setattr(programs, "device_options",
                        lambda info: [o for o in options(info) if o not in (programs.WIDE_BVH, programs.PREFETCH)])
    rt = runtime.Runtime()
    assert not {programs.WIDE_BVH, programs.PREFETCH} & set(rt.device_options)
    gpu = equal_scene_frame(tmp_path, "knot", rt)
    np.testing.assert_array_equal(cpu.hdr, gpu.hdr)


def test_the_removed_paths_key_is_a_note(tmp_path, white):
    """effects.reference.paths (auto | megakernel | wavefront) is removed: a scene that still names it
    loads and renders as before (the megakernel was every frame's engine) with a note saying so;
    another value is still a one-line error naming the key."""
    from iblbake.errors import InputError
    from iblbake.render.plan import REMOVED_PATHS, plan
    doc = {"camera": {"perspective": {"position": [0, 1, 3]}, "resolution": [8, 6]},
           "environment": {"path": str(white)}, "materials": {"m": {}},
           "objects": [{"sphere": {"radius": 0.5}, "material": "m"}, {"plane": {"point": [0, -0.5, 0]}, "material": "m"}],
           "effects": {"diffuse": "reference", "reference": {"max_samples": 2, "bounces": "unbounded"}}}
    assert "effects.reference.paths" not in " ".join(plan(write(tmp_path, "none", doc)).notes)
    for way in ("auto", "megakernel", "wavefront"):
        doc["effects"]["reference"]["paths"] = way
        sc = write(tmp_path, way, doc)
        pl = plan(sc)
        assert REMOVED_PATHS in pl.notes and "delete the key" in REMOVED_PATHS
        assert "BOUNCES" in pl.defines["reference"] and "WAVEFRONT" not in pl.defines["reference"]
    doc["effects"]["reference"]["paths"] = "gpu"
    with pytest.raises(InputError, match=r"effects\.reference\.paths: 'gpu' is not one of"):
        write(tmp_path, "bad", doc)


def test_trace_runs_the_megakernel_only(rt):
    """render/paths/trace.py's engines: the megakernel; the retired wavefront (or any other name) is a
    one-line InputError naming it."""
    from iblbake.errors import InputError
    from iblbake.render.paths.trace import ENGINES, trace
    assert list(ENGINES) == ["megakernel"]
    with pytest.raises(InputError, match=r"path engine 'wavefront' is not one of megakernel \(the wavefront is retired\)"):
        trace(object(), "wavefront")


def test_the_paths_constants_have_one_definition():
    """RR_DEPTH and MAX_PATH are scene/layout.py's, emitted to kernels/layout.h (which every path
    program includes) and read by the twin: no kernel defines them again."""
    from iblbake.render.twin import paths as twin
    from iblbake.scene import layout

    kernels = Path(__file__).resolve().parents[1] / "kernels"
    header = (kernels / "layout.h").read_text()
    assert f"#define RR_DEPTH {layout.RR_DEPTH}\n" in header and f"#define MAX_PATH {layout.MAX_PATH}\n" in header
    assert (twin.RR_DEPTH, twin.MAX_PATH) == (layout.RR_DEPTH, layout.MAX_PATH) == (4, 256)
    again = [f.name for f in kernels.rglob("*.[ch]*") if f.name != "layout.h"
             and any(f"#define {k} " in f.read_text() for k in ("RR_DEPTH", "MAX_PATH"))]
    assert again == []
