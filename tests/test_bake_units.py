"""The bakes as declared units (render/units.py) on the scene put on the device once
(render/device_scene.py): the load order follows the declared reads, a probe bake runs from a scene
whose effects do not read probes (through the unit, the scene left as it was) and is the volume a
frame of that scene would read, the scene's tables go up once per runtime and content, and the
probe package keeps its names and imports no pass."""

import ast
import copy
import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from iblbake.io import images
from iblbake.render import Bakes, plan, render, units
from iblbake.render.units import Job, Unit, order
from tests.helpers import load_scene

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def sky(tmp_path_factory):
    p = tmp_path_factory.mktemp("sky") / "sky.exr"
    images.write_exr(p, np.full((32, 64, 3), 0.75, np.float32))
    return p


def test_the_bake_order_follows_the_declared_reads():
    """Every subset of the bakes comes out with each unit after every unit of the subset it reads
    (a topological order), ties in UNITS' order (the radiance chain before the prefiltered one,
    which reuses it); a unit declared before one it reads is moved after it, and a cycle is
    refused naming it."""
    names = list(units.UNITS)
    assert order(names) == names
    assert {"env_cdf", "radiance"} <= set(units.UNITS["probes"].reads)
    for k in range(1, len(names) + 1):
        for subset in itertools.combinations(names, k):
            got = order(reversed(subset))
            assert sorted(got) == sorted(subset)
            for u in got:
                assert all(got.index(r) < got.index(u) for r in units.UNITS[u].reads if r in got), (subset, got)
            assert got == [n for n in names if n in subset]      # nothing reads against the ties here

    def unit(name, reads=()):
        return type(name, (Unit,), {"name": name, "reads": reads})()
    declared = {u.name: u for u in (unit("volume", ("chain", "table")), unit("table"), unit("chain", ("table",)))}
    assert order(["volume", "chain", "table"], declared) == ["table", "chain", "volume"]
    assert order(["volume", "chain"], declared) == ["chain", "volume"]      # a read not asked for: on demand
    cyclic = {**declared, "table": unit("table", ("volume",))}
    with pytest.raises(ValueError, match="cycle"):
        order(["volume", "table"], cyclic)
    with pytest.raises(KeyError):
        order(["nothing"])


def far_sphere(tmp_path, sky, name, **effects):
    """Probes around the origin, the only object a small sphere no probe ray meets (as
    test_probes.far_sphere_scene); the effects as given (none of them probes by default)."""
    return load_scene(tmp_path, name, {
        "camera": {"perspective": {"position": [0, 0, 3], "look_at": [0, 0, 0]}, "resolution": [8, 8]},
        "environment": {"path": str(sky)},
        "materials": {"m": {"base_color": [0.8, 0.8, 0.8], "roughness": 1, "specular": 0}},
        "objects": [{"sphere": {"center": [500, 0, 0], "radius": 0.01}, "material": "m"}],
        "probes": {"min": [-1, -1, -1], "max": [1, 1, 1], "counts": [2, 2, 2], "irradiance": "sh", "rays": 64,
                   "classification": False},
        "effects": {"diffuse": "sh", "specular": "off", **effects}})


def test_a_probe_bake_runs_from_a_scene_whose_effects_do_not_read_probes(tmp_path, rt, sky):
    """The probes unit, asked by name with a Job (a scene, a runtime, a store: no frame), bakes the
    volume of a scene whose effects are `diffuse: sh` and leaves the scene as it was; every probe
    holds the uniform sky's SH (0.75 pi sqrt(4 pi) in Y00, to float32). A frame of the same scene
    with `diffuse: probes` plans the bake and finds it in the cache (the same key: what a frame
    reads), as does iblbake.bake_probes, which edits no scene either."""
    import iblbake

    sc = far_sphere(tmp_path, sky, "sh")
    before = copy.deepcopy(sc.data)
    assert "probes" not in plan(sc).bakes
    bakes = Bakes(tmp_path / "cache")
    vol, cached, extra = bakes.load("probes", Job(sc, rt, bakes))
    assert not cached and extra["probes"] == 8 and extra["rays_traced"] > 0
    assert sc.data == before
    want = np.zeros((9, 3))
    want[0] = 0.75 * math.pi * math.sqrt(4 * math.pi)
    assert np.abs(vol["irradiance"] - want).max() < 1e-5
    frame = render(far_sphere(tmp_path, sky, "probes", diffuse="probes"), runtime=rt, cache_root=tmp_path / "cache")
    baked = next(b for b in frame.report["bakes"] if b["name"] == "probes")
    assert baked["cached"] and baked["entry"] == extra["entry"]
    api = iblbake.bake_probes(sc, cache=tmp_path / "cache")
    assert api.cached and api.entry == extra["entry"] and sc.data == before
    assert np.array_equal(api.irradiance, vol["irradiance"])


def test_the_probes_key_follows_the_camera_and_the_extracted_lights(tmp_path, rt, sky):
    """Which probes are off follows what the camera sees (its room, the bounds it stands in, the
    points behind surfaces), and the extracted lights light every vertex of the probes' paths: a
    moved camera or another `sun_lights` reused the volume baked for the first (stale states, stale
    light). Each now keys its own volume; the same scene keys the same."""
    import iblbake

    bakes = Bakes(tmp_path / "cache")
    unit = units.UNITS["probes"]

    def key(*overrides):
        sc = far_sphere(tmp_path, sky, "k")
        return unit.key(Job(iblbake.load_scene(sc, list(overrides)) if overrides else sc, rt, bakes))

    first = key()
    assert key() == first
    assert key("camera.perspective.position=[0, 0.5, 3]") != first
    assert key("environment.sun=extract") != key("environment.sun=extract", "environment.sun_lights=4")


def quad_scene(tmp_path, sky, name, colour):
    quad = tmp_path / "quad.obj"
    quad.write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3\nf 1 3 4\n")
    return load_scene(tmp_path, name, {
        "camera": {"perspective": {"position": [0, 0, 3], "look_at": [0, 0, 0]}, "resolution": [16, 12]},
        "environment": {"path": str(sky)},
        "materials": {"m": {"base_color": colour, "roughness": 0.5}},
        "objects": [{"mesh": {"path": str(quad)}, "material": "m"},
                    {"sphere": {"center": [0, 0, 0.5], "radius": 0.3}, "material": "m"}],
        "effects": {"diffuse": "sh", "specular": "off"}})


def test_the_scene_goes_to_the_device_once_per_content(tmp_path, rt, sky):
    """Frames of one scene on one runtime share its DeviceScene (the tables go up once); a scene
    with another material gets its own, sharing the triangles and BVH (one copy on the host and
    one on the device); a frame after the other scene's is the first frame's, pixel for pixel (no
    stale table), and each frame is the one a fresh store renders."""
    bakes = Bakes(tmp_path / "cache")
    grey, red = quad_scene(tmp_path, sky, "grey", [0.5, 0.5, 0.5]), quad_scene(tmp_path, sky, "red", [0.8, 0.1, 0.1])
    a = render(grey, runtime=rt, cache=bakes)
    b = render(red, runtime=rt, cache=bakes)
    a2 = render(grey, runtime=rt, cache=bakes)

    def held(kind):
        return list(bakes.held(kind))
    assert len(held("device-scene")) == 2 and len(held("device-geometry")) == 1
    assert bakes.device_scene(rt, grey) is bakes.device_scene(rt, grey)
    assert bakes.device_scene(rt, red).arrays.tris is bakes.device_scene(rt, grey).arrays.tris     # one copy
    assert np.array_equal(a.hdr, a2.hdr) and np.abs(a.hdr - b.hdr).max() > 0.05
    assert np.array_equal(b.hdr, render(red, runtime=rt, cache_root=tmp_path / "cache").hdr)


def test_the_probe_package_keeps_its_names_and_imports_no_pass():
    """render/probes is a package of one module per idea, each saying what it holds; every name
    the module render/probes.py had is importable from it; neither it nor render/reflection_probes.py
    imports anything from render/passes (issue 46)."""
    from iblbake.render import probes
    names = ("ACTIVE", "BACKFACE_BLEND_LIMIT", "DEFAULT_LONGEST", "FILES", "FIXED_RAYS", "FORMAT", "Grid", "INACTIVE",
             "INSIDE_WARN", "MAX_ATLAS_SIDE", "MAX_DISTANCE", "MAX_OFFSET", "RELOCATION_PASSES", "SAMPLING_KEYS",
             "SH_GLSL", "Tracer", "VERSION", "atlas", "bake", "bake_settings", "basis_glsl",
             "basis_options", "classify", "data_texture", "glsl", "grid_of", "inside_geometry", "load", "manifest",
             "outside_camera_rooms", "project", "random_rotation", "ray_directions", "read_manifest", "relocate",
             "sampled", "save", "scene_bounds", "spherical_fibonacci", "trace_defines", "volume_dict", "warnings",
             "with_borders")
    assert [n for n in names if not hasattr(probes, n)] == []
    files = sorted((ROOT / "iblbake/render/probes").glob("*.py")) + [ROOT / "iblbake/render/reflection_probes.py"]
    assert len(files) >= 8
    for f in files:
        tree = ast.parse(f.read_text())
        assert ast.get_docstring(tree), f.name
        mods = [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module] + \
               [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
        assert not [m for m in mods if m.startswith(("iblbake.render.passes", "iblbake.render.frame"))], f.name


def test_the_store_says_what_it_holds_in_memory(tmp_path, sky):
    """Bakes.held(kind) and Bakes.result(kind): what tests and tools read of a store (they reached
    into its private memo): the bakes of a kind by key in the order made, and the first one's
    result; a kind not held is a KeyError naming it."""
    sc = load_scene(tmp_path, "held", {"camera": {"perspective": {"position": [0, 0, 3]}, "resolution": [8, 8]},
                                       "environment": {"path": str(sky)}})
    bakes = Bakes(tmp_path / "cache")
    with pytest.raises(KeyError, match="'env'"):
        bakes.result("env")
    image, info = bakes.environment(sc.data["environment"])
    assert bakes.result("env") is image and len(bakes.held("env")) == 1
    assert info.width == 64 and float(image.mean()) == pytest.approx(0.75, abs=1e-6)
    digest = bakes.file_sha256(sky)
    (key, value), = bakes.held("sha256").items()
    assert key[:2] == ("sha256", str(sky)) and value == digest and not bakes.held("dfg")
