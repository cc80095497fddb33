"""probes.json's `lights` (render/probes/files.py light_entries): the lights an engine draws per
pixel beside the probes, above all those extracted from the panorama (`environment.sun: extract`),
which the probes' paths count at every vertex but an engine loading the files could not know of;
probes.glsl's constants of the directional ones; each reflection probe's settings, `taps` too."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

import iblbake
from iblbake.io import images
from iblbake.render import render
from iblbake.scene import pack
from tests.helpers import glsl_compiles, load_scene, run_cli, scene_file

QUADS = Path(__file__).resolve().parents[1] / "examples" / "corpus" / "meshes"


def lit_scene(folder, studio):
    """A sphere on a floor under studio, its four lamps extracted (the panorama turned 30 degrees,
    twice as bright), a point light of the scene's own, a reflection probe read in 16 taps."""
    return load_scene(folder, "lit", {
        "camera": {"perspective": {"position": [0, 1, 3], "look_at": [0, 0.5, 0]}, "resolution": [16, 12]},
        "environment": {"path": str(studio), "sun": "extract", "sun_lights": 4, "sun_shadows": "soft",
                        "intensity": 2, "rotation_y": 30},
        "materials": {"m": {"base_color": [0.8, 0.8, 0.8], "specular": 0}},
        "objects": [{"plane": {"point": [0, 0, 0], "size": 4}, "material": "m"},
                    {"sphere": {"center": [0, 0.5, 0], "radius": 0.5}, "material": "m"}],
        "lights": [{"point": {"position": [1, 2, 1], "intensity": 3}}],
        "probes": {"counts": [2, 2, 2], "rays": 64},
        "reflection_probes": [{"position": [0, 0.5, 1.5], "min": [-2, 0, -2], "max": [2, 2, 2], "size": 8,
                               "samples": 1, "taps": 16}],
        "effects": {"diffuse": "probes", "specular": "off"}})


@pytest.mark.slow
def test_probes_json_lists_the_lights_the_frame_draws(tmp_path, panoramas, rt):
    """A new user's trial: probes.json did not list the lights extracted from the panorama, so an
    engine loading the volume lit by `sun: extract` lacked their direct light (the probes hold their
    bounce only). Read back from the manifest's JSON, the lights are the frame's: the scene's point
    light, then the four lamps the frame's lights pass reports (its direction in the world frame,
    the illuminance times environment.intensity, colour, disk), and their records (what the
    kernels read) rebuild from the entries alone; each lamp's irradiance per channel and solid
    angle; probes.glsl's constants compile; the reflection probe's taps are listed."""
    sc = lit_scene(tmp_path, panoramas["studio"])
    vol = iblbake.bake_probes(sc, cache=tmp_path / "cache")
    man = json.loads(json.dumps(vol.manifest))
    lights = man["lights"]
    frame = render(sc, runtime=rt, cache_root=tmp_path / "cache")
    passed = next(p for p in frame.report["passes"] if p["name"] == "lights")
    extracted = passed["extracted"]
    assert len(extracted) == 4 and len(lights) == 5 and passed["lights"] == 5
    assert lights[0]["source"] == "lights.0" and lights[0]["point"]["intensity"] == 3
    for k, (got, said) in enumerate(zip(lights[1:], extracted)):
        d = got["directional"]
        assert got["source"] == said["source"] == f"environment.sun: extract ({k + 1} of 4, brightest first)"
        assert got["shadows"] == "soft"
        assert np.allclose(d["direction"], said["light_direction_world"], atol=1e-6)
        assert d["illuminance"] == pytest.approx(said["illuminance"], rel=1e-9)       # the frame's, as said
        assert d["illuminance"] == pytest.approx(2 * said["illuminance_before_intensity"], rel=1e-9)
        assert np.allclose(d["color"], said["color"], atol=1e-6)
        assert d["angular_diameter"] == pytest.approx(said["angular_diameter_deg"], abs=1e-4)
        assert np.allclose(got["irradiance"], np.multiply(d["color"], d["illuminance"]), rtol=1e-12)
        half = math.radians(d["angular_diameter"]) / 2
        assert got["solid_angle_sr"] == pytest.approx(2 * math.pi * (1 - math.cos(half)), rel=1e-12)
    # the records the frame's kernels read, from the frame's own list and from the entries alone
    from iblbake.render.device_scene import scene_lights
    from iblbake.render.bakes import Bakes
    bakes = Bakes(tmp_path / "cache")
    frame_lights = scene_lights(sc, bakes.sun(sc.data["environment"]))
    rebuilt = [{k: v for k, v in lt.items() if k not in ("source", "irradiance", "solid_angle_sr")} for lt in lights]
    assert np.allclose(pack.light_records(rebuilt), pack.light_records(frame_lights), rtol=1e-6, atol=1e-7)
    assert man["reflection_probes"][0]["taps"] == 16
    # the command writes the same list, and says how many lights it found in the panorama
    r = run_cli("probes", sc.source, "-o", tmp_path / "out", "--cache", tmp_path / "cache")
    assert r.returncode == 0 and "; 4 lights extracted from the panorama, to draw per pixel" in r.stdout, r.stdout + r.stderr
    assert json.loads((tmp_path / "out" / "probes.json").read_text())["lights"] == lights
    written = images.read_exr(tmp_path / "out" / "environment.exr")      # the residual, half floats
    assert np.allclose(written, vol.environment, rtol=2 ** -10, atol=0)
    assert "lights" in man["conventions"]
    src = vol.glsl()
    assert "#define PROBE_LIGHT_COUNT 4" in src
    to = src.split("const vec3 PROBE_LIGHT_TO[4] = vec3[4](vec3(")[1].split(")")[0]
    assert np.allclose([float(x) for x in to.split(",")], -np.asarray(lights[1]["directional"]["direction"]), atol=1e-8)
    glsl_compiles(tmp_path / "probes.frag", src + "\nin vec3 P;\nin vec3 N;\nin vec3 V;\nout vec4 color;\n"
                  "void main() { vec3 e = probeIrradiance(P, normalize(N), normalize(V));\n"
                  "  for (int i = 0; i < PROBE_LIGHT_COUNT; ++i)\n"
                  "    e += PROBE_LIGHT_IRRADIANCE[i] * max(dot(normalize(N), PROBE_LIGHT_TO[i]), 0.0)"
                  " * PROBE_LIGHT_SIN_RADIUS[i];\n  color = vec4(e, 1.0); }\n")


def test_probes_json_sky_is_the_residual_panoramas_sh(tmp_path, panoramas, rt):
    """A new user's trial: an exported volume's fallback (where no probe is near, outside the
    volume) was the whole panorama's SH (`iblbake sh`), so an engine that drew probes.json's
    extracted lamps per pixel counted them twice. probes.json's `sky` is the SH irradiance of the
    residual panorama (studio less its four lamps, taken out here in numpy and projected by the
    quadrature oracle), in the world frame (rotation_y 30) times intensity 2; evaluated at world
    normals it is the renderer's own fallback SH read in the panorama's frame; it differs from the
    whole panorama's; probes.glsl's probeSkyIrradiance holds the same coefficients and compiles.
    The residual itself, what an engine prefilters for the specular (trial75: nothing said which
    panorama the listed lights left), is the volume's `environment` with its manifest entry."""
    from iblbake.bake import sun as sunbake
    from iblbake.core import conventions, sh
    from iblbake.render.bakes import Bakes
    from iblbake.render.units import Job
    sc = lit_scene(tmp_path, panoramas["studio"])
    vol = iblbake.bake_probes(sc, cache=tmp_path / "cache")
    man = json.loads(json.dumps(vol.manifest))
    sky = man["sky"]
    env = sc.data["environment"]
    bakes = Bakes(tmp_path / "cache")
    whole = np.asarray(bakes.environment({**env, "sun": "none"})[0], np.float64)[..., :3]
    residual, lamps = sunbake.extract_lights(whole, 4, sunbake.LAMP_DIAMETER, sunbake.LAMP_SHARE)
    assert len(lamps) == 4 and sky["lights_extracted"] and (sky["bands"], sky["window"]) == (3, "none")
    to_e = (sh.window(3, "none") * sh.ahat(3))[:, None] * 2.0

    def world_sh(image):
        return sh.project_direct(np.asarray(image, np.float64), 3, 30.0) * to_e
    assert man["environment"] == {"file": "environment.exr", "rotation_y": 30.0, "intensity": 2.0}
    assert "twice" in man["conventions"]["environment"]
    assert np.array_equal(vol.environment, residual.astype(np.float32))
    got, want, full = np.asarray(sky["irradiance"]), world_sh(residual), world_sh(whole)
    assert np.abs(got - want).max() < 1e-12 * np.abs(want).max()      # measured 8e-16
    assert (full[0] > 4 * want[0]).all()          # the lamps are 7.3-8.2x the rest of studio's mean light
    # the renderer's fallback (the sh unit, the panorama's frame) read at to_env of world normals
    bakes.runtime = rt
    own = bakes.load("sh", Job(sc, rt, bakes))[0]
    n = conventions.equirect_texel_dirs(16, 8).reshape(-1, 3)
    assert np.allclose(sh.irradiance(got, n, 3), 2.0 * sh.irradiance(own, conventions.rotate_y(n, -30.0), 3),
                       rtol=0, atol=1e-7 * np.abs(got).max())          # measured 3e-9 (turned the other way: 0.21)
    src = iblbake.bake_probes(sc, cache=tmp_path / "cache").glsl()
    table = src.split("const vec3 PROBE_SKY_SH[9] = vec3[9](")[1].split(");")[0]
    assert np.allclose([float(x) for x in table.replace("vec3(", "").replace(")", "").split(",")], got.ravel(),
                       rtol=1e-8)
    glsl_compiles(tmp_path / "sky.frag", src + "\nin vec3 P;\nin vec3 N;\nin vec3 V;\nout vec4 color;\n"
                  "void main() { color = vec4(mix(probeSkyIrradiance(normalize(N)), probeIrradiance(P, normalize(N), "
                  "normalize(V)), probeVolumeWeight(P)), 1.0); }\n")


def test_sun_shadow_samples_sets_the_extracted_lights_soft_shadows(tmp_path, panoramas, rt):
    """A new user's trial: the extracted lights' soft shadows took 16 rays, no setting (a softbox's
    penumbra grainy at 1 spp). `environment.sun_shadow_samples` gives them: the records the lights
    pass reads and probes.json's lights carry it, the pass traces it per light, and the penumbra of
    a sphere on a floor under studio's four lamps converges with it: against 1024 rays, 16 rays'
    RMS error over the frame is 5.1x 128's (measured; Sobol points, faster than 1/sqrt(8), 2.8x).
    Not a positive integer: one line naming the key."""
    from iblbake.render.device_scene import scene_lights
    from iblbake.render.bakes import Bakes

    def frame(n):
        sc = load_scene(tmp_path, f"s{n}", {
            "camera": {"perspective": {"position": [0, 2.5, 2.5], "look_at": [0, 0, 0]}, "resolution": [24, 18]},
            "environment": {"path": str(panoramas["studio"]), "sun": "extract", "sun_lights": 4,
                            "sun_shadows": "soft", "sun_shadow_samples": n, "background": "hide"},
            "materials": {"m": {"base_color": [0.8, 0.8, 0.8], "specular": 0}},
            "objects": [{"plane": {"point": [0, 0, 0], "size": 4}, "material": "m"},
                        {"sphere": {"center": [0, 0.5, 0], "radius": 0.5}, "material": "m"}],
            "effects": {"diffuse": "sh", "specular": "off"}})
        lights = scene_lights(sc, Bakes(tmp_path / "cache").sun(sc.data["environment"]))
        assert [lt["shadow_samples"] for lt in lights] == [n] * 4
        f = render(sc, runtime=rt, cache_root=tmp_path / "cache")
        said = next(p for p in f.report["passes"] if p["name"] == "lights")
        assert said["shadow_rays_per_sample"] == 4 * n
        return f.hdr[..., :3].astype(np.float64)
    ref, few, many = frame(1024), frame(16), frame(128)
    err = [float(np.sqrt(((f - ref) ** 2).mean())) for f in (few, many)]
    assert err[0] > 3.0 * err[1] > 0, err          # measured 5.1x
    for bad in ("0", "2.5", "lots"):
        r = run_cli("render", scene_file(tmp_path, panoramas["studio"]), "-o", tmp_path / "x.exr",
                    "--set", f"environment.sun_shadow_samples={bad}")
        assert r.returncode == 1 and "environment.sun_shadow_samples" in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.mark.parametrize("effects, given, want", [
    ({"diffuse": "probes"}, {}, ("extract", 4, "soft")),
    ({"specular": "probes", "diffuse": "sh"}, {"sg": True}, ("extract", 4, "soft")),
    ({"diffuse": "probes"}, {"sun_lights": 2, "sun_shadows": "hard"}, ("extract", 2, "hard")),
    ({"diffuse": "probes"}, {"sun": "none"}, ("none", 1, "hard")),
    ({"diffuse": "sh"}, {}, ("none", 1, "hard")),
    ({"diffuse": "reference", "specular": "reference"}, {}, ("none", 1, "hard")),
    ({"diffuse": "sh", "specular": "prefiltered"}, {"probe": True}, ("extract", 4, "soft")),
    ({"diffuse": "sh", "specular": "prefiltered", "reflection_probes": False}, {"probe": True},
     ("extract", 4, "soft")),
    ({"diffuse": "sh", "specular": "importance"}, {"probe": True}, ("extract", 4, "soft")),
    ({"diffuse": "sh"}, {"sg": True}, ("extract", 4, "soft")),
    ({"diffuse": "sh"}, {"sun": "extract"}, ("extract", 1, "hard")),
    ({"diffuse": "lightmap"}, {"sg": True, "lightmap": True}, ("extract", 4, "soft")),
    ({"diffuse": "probes"}, {"lightmap": True}, ("extract", 4, "soft")),
    ({"diffuse": "sh"}, {"lightmap": True}, ("extract", 4, "soft")),
    ({"diffuse": "lightmap"}, {"lightmap": True, "sun": "none"}, ("none", 1, "hard")),
])
def test_sun_auto_extracts_where_the_frame_reads_probes(tmp_path, panoramas, effects, given, want):
    """`environment.sun: auto` (the default) extracts the panorama's sun and lamps where the scene
    has irradiance probes (a section, or a frame that reads them), reflection probes or a lightmap
    (a section, or a frame that reads one), whichever mode a frame reads (a volume or lightmap baked
    by name keys what the frame reads), with 4 lights and soft shadows unless the scene gives them,
    and leaves the panorama whole elsewhere (before: none unless asked: a new user's room turned
    30 degrees under studio, a sphere's lit side 1.7-2.1x bright at defaults; a lightmap kept the
    panorama whole until stop 75: a new user's two storeys' frame 35% off where 17% lit per pixel)."""
    given = dict(given)
    probe, sg, lightmap = given.pop("probe", False), given.pop("sg", False), given.pop("lightmap", False)
    doc = {"camera": {"perspective": {"position": [0, 1, 3], "look_at": [0, 0.5, 0]}, "resolution": [8, 6]},
           "environment": {"path": str(panoramas["studio"]), **given},
           "materials": {"m": {"base_color": [0.8, 0.8, 0.8]}},
           "objects": [{"sphere": {"center": [0, 0.5, 0], "radius": 0.5}, "material": "m"}],
           "effects": effects}
    if sg:
        doc["probes"] = {"irradiance": "sg"}
    if lightmap:
        doc["lightmap"] = {}
    if probe:
        doc["reflection_probes"] = [{"position": [0, 0.5, 1.5], "min": [-2, 0, -2], "max": [2, 2, 2]}]
    env = load_scene(tmp_path, "auto", doc).data["environment"]
    assert (env["sun"], env["sun_lights"], env["sun_shadows"]) == want


@pytest.mark.slow
def test_sun_auto_lights_a_sphere_beside_a_lamps_beam_per_pixel(tmp_path, panoramas, rt):
    """The frame the default `sun: auto` makes of a sphere beside the beam studio's lamps throw
    through a window: the lamps lit per pixel with their shadows, what the probes hold is the rest.
    A room of quads (window in the +x wall), 24 x 18 px, its sphere's mean against the path-traced
    reference's (512 samples): x1.07 with auto, x1.32 with the lamps left in the panorama (as
    before; the trial's 64 px ball: x1.71 -> x1.04). The corpus' quad_room's walls
    (examples/corpus/meshes), turned 30 degrees about y."""
    room = {"camera": {"perspective": {"position": [0.9, 1.0, 1.3], "look_at": [-1.2, 1.9, -1.0], "fov_y": 70},
                       "resolution": [24, 18]},
            "environment": {"path": str(panoramas["studio"]), "intensity": 2, "background": "hide"},
            "materials": {"m": {"base_color": [0.8, 0.8, 0.8], "specular": 0}},
            "objects": [{"mesh": {"path": str(QUADS / f"quad_{w}.obj"), "rotate": [0, 30, 0]}, "material": "m"}
                        for w in ("floor", "ceiling", "left", "back", "front", "window")]
                       + [{"sphere": {"center": [-0.3, 0.5, -0.6], "radius": 0.5}, "material": "m"}],
            "probes": {}, "effects": {"diffuse": "probes", "specular": "off"},
            "output": {"object": str(tmp_path / "obj.exr")}}
    ball = None
    means = {}
    for mode in ("probes", "reference"):
        sc = load_scene(tmp_path, mode, {**room, "effects": {"diffuse": mode, "specular": "off",
                                                           "reference": {"max_samples": 512, "target_noise": 0}}})
        frame = render(sc, runtime=rt, cache_root=tmp_path / "cache")
        if ball is None:
            ball = np.rint(frame.aovs["object"]) == len(room["objects"]) - 1
        means[mode] = float((frame.hdr[..., :3] @ np.array([0.2126, 0.7152, 0.0722]))[ball].mean())
    assert abs(means["probes"] / means["reference"] - 1) < 0.15, means


def test_render_says_what_sun_auto_extracted(tmp_path, panoramas):
    """A new user's trial: the frames of `sun: none` and the default differed and nothing but
    --report said why. The render's line says how many lights `sun: auto` took out of the
    panorama, and why (probes, or a lightmap); not where the scene asked for none, nor where it has
    neither."""
    def line(**sections):
        path = scene_file(tmp_path, panoramas["studio"], camera={
            "perspective": {"position": [0, 0, 3], "fov_y": 45}, "resolution": [8, 8]}, **sections)
        r = run_cli("render", path, "-o", tmp_path / "out.exr")
        assert r.returncode == 0, r.stderr
        return r.stdout.strip().splitlines()[-1]
    probes = {"min": [-2, -2, -2], "max": [2, 2, 2], "counts": [2, 2, 2], "rays": 64}
    assert line(probes=probes).endswith("; 4 lights extracted from the panorama and lit per pixel (environment.sun: "
                                        "auto, the scene has probes; environment.sun: none keeps them in it)")
    assert "extracted" not in line(probes=probes, environment={"sun": "none"})
    assert "extracted" not in line()
    lit = line(lightmap={"texels_per_unit": 4, "samples": 16}, effects={"diffuse": "lightmap"})
    assert lit.endswith("(environment.sun: auto, the scene has a lightmap; environment.sun: none keeps them in it)"), lit
