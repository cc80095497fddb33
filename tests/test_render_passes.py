"""The pass contract and the frame around it: the reference pass with visibility against the
closed form of a sphere over a plane, tiled frames against untiled ones, the layout table the
kernels share, frames too large for the machine, and the package's import layers."""

import ast
import dataclasses
import os
import re
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from iblbake.render import frame, plan, render
from iblbake.io import images
from iblbake.render import twin as rr
from iblbake.scene import layout, pack
from iblbake.scene import load as scene


ROOT = Path(__file__).resolve().parents[1]
R = 1.0
BASE = 0.8


@pytest.fixture(scope="module")
def white(tmp_path_factory):
    p = tmp_path_factory.mktemp("white") / "white.exr"
    images.write_exr(p, np.ones((32, 64, 3), np.float32))
    return p


def sphere_over_plane(folder, env, h, visibility=True, samples=4096, res=40):
    doc = {"camera": {"perspective": {"position": [0, 3 * h, 2.5 * h], "look_at": [0, 0, 0], "fov_y": 60},
                      "resolution": [res, res]},
           "environment": {"path": str(env), "background": "hide"},
           "materials": {"ball": {"base_color": [0.5, 0.5, 0.5]}, "floor": {"base_color": [BASE] * 3, "roughness": 1}},
           "objects": [{"sphere": {"center": [0, h, 0], "radius": R}, "material": "ball"},
                       {"plane": {"point": [0, 0, 0], "normal": [0, 1, 0]}, "material": "floor"}],
           "effects": {"diffuse": "reference", "specular": "off",
                       "reference": {"max_samples": samples, "target_noise": 0, "batch": 256,
                                     "visibility": visibility, "bounces": 1}}}     # the direct light's closed form
    p = Path(folder) / f"sphere_over_plane_{h}.yaml"
    p.write_text(yaml.safe_dump(doc))
    return scene.load(p)


def plane_closed_form(sc, visibility=True):
    """Per sample on the plane: kD c (1 - R^2 h / d^3) under L = 1 (the sphere's form factor from
    a point of the plane at distance d from its centre; R^2/h^2 right under it)."""
    arrays = pack.scene_arrays(sc)
    gb = rr.primary(sc["camera"], arrays)
    hit = gb["hit"]
    v, n, nov, (base, metallic, _, rough, f0, f90) = rr.surface(gb, arrays)
    on_plane = gb["material"][hit] == sc.data["materials"].__len__() - 1    # floor: the last material
    h = sc.data["objects"][0]["sphere"]["center"][1]
    p = gb["pos"][hit]
    d = np.linalg.norm(p - np.array([0.0, h, 0.0]), axis=1)
    blocked = R * R * h / d ** 3 if visibility else 0.0
    want = rr.diffuse_weight(base, metallic, rough, f0, f90, nov)[:, 0] * np.pi * (1 - blocked)
    return gb, arrays, hit, on_plane, want


@pytest.mark.slow
@pytest.mark.parametrize("h", [2 * R, 4 * R])
def test_reference_visibility_sphere_over_plane_closed_form(tmp_path, white, h):
    sc = sphere_over_plane(tmp_path, white, h)
    gb, arrays, hit, on_plane, want = plane_closed_form(sc)
    frame = render(sc, cache_root=tmp_path / "cache")
    got = frame.hdr[..., 0].reshape(-1)[hit][on_plane]
    err = np.abs(got / want[on_plane] - 1)
    print(f"h = {h}: OpenCL vs closed form, worst {err.max():.4f}, mean {err.mean():.5f} over {on_plane.sum()} px")
    assert err.max() < 0.01
    # the darkening is real: right under the sphere the plane loses (R/h)^2 of its light
    assert want[on_plane].min() < want[on_plane].max() * (1 - 0.8 * (R / h) ** 2)
    twin = rr.exact(gb, arrays, sc["effects"], sc["environment"], np.ones((32, 64, 3)), sub=2)[hit][on_plane, 0]
    terr = np.abs(twin / want[on_plane] - 1)
    print(f"h = {h}: numpy twin vs closed form, worst {terr.max():.4f}")
    assert terr.max() < 0.01


@pytest.mark.slow           # over 3 s on the 2-core CPU: make test, not make check
def test_reference_without_visibility_is_the_unoccluded_integral(tmp_path, white):
    sc = sphere_over_plane(tmp_path, white, 2 * R, visibility=False)
    _, _, hit, on_plane, want = plane_closed_form(sc, visibility=False)
    frame = render(sc, cache_root=tmp_path / "cache")
    got = frame.hdr[..., 0].reshape(-1)[hit][on_plane]
    assert np.abs(got / want[on_plane] - 1).max() < 2e-3
    assert "VISIBILITY" not in frame.report["effects"]["defines"]["reference"]


def busy_scene(folder, env, fx):
    doc = {"camera": {"perspective": {"position": [0.3, 1.2, 4], "fov_y": 40}, "resolution": [37, 23], "spp": 3},
           "environment": {"path": str(env), "background": "show", "rotation_y": 30},
           "materials": {"a": {"base_color": [0.9, 0.5, 0.2], "metallic": 1, "roughness": 0.3},
                         "b": {"base_color": [0.2, 0.6, 0.9], "roughness": 0.6, "emissive": [0.1, 0, 0]}},
           "objects": [{"sphere": {"center": [-0.6, 0, 0], "radius": 0.6}, "material": "a"},
                       {"sphere": {"center": [0.7, 0, 0], "radius": 0.5}, "material": "b"},
                       {"plane": {"point": [0, -0.6, 0], "size": 5}, "material": "b"}],
           "effects": fx, "output": {"frame": ["f.png"], "normal": "n.exr", "albedo": "a.exr", "depth": "d.exr",
                                     "dither": True}}
    p = Path(folder) / "busy.yaml"
    p.write_text(yaml.safe_dump(doc))
    return scene.load(p)


@pytest.mark.external
@pytest.mark.parametrize("fx", [{"diffuse": "sh", "specular": "prefiltered"},
                                {"diffuse": "off", "specular": "importance", "samples": 8},
                                {"diffuse": "reference", "specular": "reference",
                                 "reference": {"max_samples": 16, "target_noise": 0}},
                                {"diffuse": "sh", "specular": "prefiltered", "ssr": "on",
                                 "ssr_settings": {"max_roughness": 0.7}}],
                         ids=["prefiltered", "importance", "reference", "ssr"])
def test_tiled_frame_equals_the_untiled_one(tmp_path, small_panoramas, fx):
    """A device budget of a few rows renders in tiles; every pixel, AOV and 8-bit value is the same.
    SSR's rays read any pixel of the frame: a tiled frame gathers every tile first (two sweeps), so
    its rays see what an untiled frame's do (before, a ray leaving its tile kept the environment)."""
    sc = busy_scene(tmp_path, small_panoramas["city"], fx)
    whole = render(sc, cache_root=tmp_path / "cache")
    budget = frame.frame_bytes(sc, plan(sc), 5, tiled=True)
    tiled = render(sc, cache_root=tmp_path / "cache", device_budget=budget)
    assert whole.report["tiles"] == 1 and tiled.report["tiles"] >= 4      # 23 rows, 5 or 6 per tile
    if fx.get("ssr") == "on":
        ssr = next(p for p in tiled.report["passes"] if p["name"] == "ssr")
        assert ssr["sweeps"] == 2
        spec_only = render(busy_scene(tmp_path, small_panoramas["city"], {**fx, "ssr": "off"}),
                                  cache_root=tmp_path / "cache")
        changed = np.abs(whole.hdr - spec_only.hdr)[..., :3].max(-1) > 1e-3
        assert changed.mean() > 0.05, changed.mean()          # SSR did something to compare
    assert np.array_equal(whole.hdr, tiled.hdr)
    assert np.array_equal(whole.png, tiled.png)
    for a in ("normal", "albedo", "depth", "object"):
        assert np.array_equal(whole.aovs[a], tiled.aovs[a]), a


@pytest.mark.slow
def test_frame_that_cannot_fit_fails_in_one_line(tmp_path):
    """16384 x 16384 under a 6 GiB address-space limit: a one-line error naming camera.resolution,
    exit 1, no abort inside the OpenCL driver, nothing written. On the CPU device, whose buffers
    are this process's memory (a GPU driver does not even start under such a limit)."""
    out = tmp_path / "big.png"
    limit = 6 << 30

    def cap():
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    p = subprocess.run([sys.executable, "-m", "iblbake.cli", "render", str(ROOT / "examples/scenes/quick.yaml"),
                        "-o", str(out), "--cache", str(tmp_path / "c"), "--set", "camera.resolution=[16384,16384]",
                        "--device", "cpu"],
                       capture_output=True, text=True, preexec_fn=cap, timeout=300)
    assert p.returncode == 1, p.stderr[-2000:]
    lines = p.stderr.strip().splitlines()
    assert "camera.resolution" in lines[-1] and "Traceback" not in p.stderr
    assert not out.exists()


def test_layout_header_is_the_table():
    """kernels/layout.h is exactly what iblbake/scene/layout.py emits (regenerate with
    `python -m iblbake.scene.layout > kernels/layout.h`)."""
    assert (ROOT / "kernels" / "layout.h").read_text() == layout.header_text()


def test_scene_reference_is_the_schema():
    """docs/scene.md is exactly what iblbake/scene/schema.py emits (regenerate with `make docs`),
    and names every key the validator knows."""
    from iblbake.scene import schema
    text = (ROOT / "docs" / "scene.md").read_text()
    assert text == schema.schema_markdown(), "docs/scene.md is stale: run `make docs`"
    for key in ("effects.reference.target_noise", "materials.NAME.base_color_map.uv_scale", "objects.N.mesh.path",
                "lights.N.spot.outer_cone_angle", "camera.orthographic.width"):
        assert f"| `{key}` |" in text, key


def test_every_kernel_parameter_is_bound_by_name():
    """Each pass's kernel parameters are names the frame's table (render/frame.py: the scene's
    values, every declared buffer, the tile's counts) or the pass's own arguments provide (a
    missing one would be a KeyError at launch, not a shifted argument), and what a pass reads and
    writes (from its kernels' const and non-const pointers) is in the table."""
    from iblbake.device import programs
    from iblbake.render import frame
    from iblbake.render.passes import PASSES
    table = set(frame.TABLE_SCENE) | set(frame.buffer_names()) | set(frame.TABLE_TILE)
    own = {p.name: set(p.bound_params()) for p in PASSES}        # the passes' (and shade's sources') declarations
    for p in PASSES:
        for fn in p.kernel_functions():
            names = {n for n, _ in programs.kernel_params(p.kernel, fn)}
            assert names <= table | own.get(p.name, set()), (fn, names - table - own.get(p.name, set()))
        assert set(p.reads) | set(p.writes) <= table | own.get(p.name, set()), p.name
        assert p.writes, p.name                    # every pass leaves something in a buffer


def test_the_frame_names_no_pass():
    """render/frame.py derives everything from the passes' declarations: it names none of them."""
    from iblbake.render.passes import PASSES
    src = (ROOT / "iblbake" / "render" / "frame.py").read_text()
    assert not [p.name for p in PASSES if f'"{p.name}"' in src or f"'{p.name}'" in src]


def test_the_frame_is_a_sequence_of_short_steps():
    """render/frame.py's render() reads as its named steps (plan, place the scene, load the bakes,
    allocate, sweep, report): no function in the module over 60 lines (render() was 145)."""
    tree = ast.parse((ROOT / "iblbake" / "render" / "frame.py").read_text())
    long = {n.name: n.end_lineno - n.lineno + 1 for n in ast.walk(tree)
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.end_lineno - n.lineno + 1 > 60}
    assert not long, long


def test_passes_set_nothing_on_the_frame_context():
    """The frame's context is a declared record: a pass keeps its state in its own declared
    record and counters (Pass.keeps, Pass.counters), never on the context (`grep -rn "ctx[.][a-z_]* = "
    iblbake/render/passes` finds nothing), and every attribute a pass, a source or the paths'
    profile reads of it is a declared field, property or method; one it lacks cannot be set."""
    passes = ROOT / "iblbake" / "render" / "passes"
    sets = [f"{f.name}:{i}" for f in sorted(passes.glob("*.py"))
            for i, line in enumerate(f.read_text().splitlines(), 1) if re.search(r"ctx\.[a-z_]* = ", line)]
    assert not sets, sets
    readers = [*passes.glob("*.py"), *(ROOT / "iblbake" / "render" / "sources").glob("*.py"),
               ROOT / "iblbake" / "render" / "paths" / "profile.py"]
    used = {m for f in readers for m in re.findall(r"\bctx\.([a-z_0-9]+)", f.read_text())}
    declared = {f.name for f in dataclasses.fields(frame.Context)} | set(dir(frame.Context))
    assert used and used <= declared, used - declared
    assert "__dict__" not in dir(frame.Context) and frame.Context.__slots__      # nothing undeclared can be set


def test_buffers_follow_the_declarations(tmp_path, lobed_sky):
    """The frame allocates exactly the declared buffers of the running passes at full size
    (per sample, per pixel, per frame) and a placeholder for every other, and a tile budget of
    frame_bytes(rows) gives tiles of those rows."""
    from iblbake.render import frame
    from iblbake.render.passes.base import Buffer
    sc = busy_scene(tmp_path, lobed_sky, {"diffuse": "sh", "specular": "importance", "samples": 4, "ao": "gtao"})
    pl = plan(sc)
    planned = frame.planned_buffers(pl, tiled=False)
    assert set(planned) == {"gb_pos", "gb_nrm", "gb_dir", "radiance", "ao_buf", "gtao_raw", "gtao_levels",
                            "spec_sums", "hdr", "aov_normal", "aov_albedo", "aov_depth", "aov_object", "png_u8", "display"}
    assert {"ao_pos", "ao_nrm", "ao_dir"} <= set(frame.planned_buffers(pl, tiled=True))
    w, h = sc.data["camera"]["resolution"]
    spp = sc.data["camera"]["spp"]
    one_row = frame.frame_bytes(sc, pl, 1) - frame.frame_bytes(sc, pl, 0)
    # gb_pos, gb_nrm, gb_dir, radiance (16 each), ao_buf (4), spec_sums (32); hdr, aovs (40), png (4), display
    assert one_row == w * (spp * (4 * 16 + 4 + 32) + 16 + 40 + 4 + 16)
    assert planned["spec_sums"] == Buffer("spec_sums", count=2)
    budget = frame.frame_bytes(sc, pl, 5, tiled=True)
    f = render(sc, cache_root=tmp_path / "cache", device_budget=budget)
    assert f.report["tiles"] == -(-h // 5)


def test_a_frame_that_lights_nothing_reads_zeros(tmp_path, lobed_sky):
    """Both terms off and the background hidden: no pass writes radiance, and resolve, which
    reads it for every sample, still gets it at full size, zero-filled (it was a placeholder of a
    few bytes: the H200 faulted reading past it, a CPU read whatever lay there). The frame is
    black with its coverage, and its albedo AOV the materials' base colour."""
    from iblbake.render import frame
    sc = busy_scene(tmp_path, lobed_sky, {"diffuse": "off", "specular": "off"})
    sc.data["environment"]["background"] = "hide"
    sc.data["materials"]["b"]["emissive"] = [0.0, 0.0, 0.0]
    sc.data["camera"]["spp"] = 1
    pl = plan(sc)
    assert not [p.name for p in pl.passes if "radiance" in p.writes]
    assert "radiance" in frame.planned_buffers(pl, tiled=False)
    f = render(sc, cache_root=tmp_path / "cache")
    cover = f.hdr[..., 3]
    assert cover.max() == 1 and np.all(f.hdr[..., :3] == 0)
    bases = {tuple(np.float32(m["base_color"])) for m in sc.data["materials"].values()}
    full = f.aovs["albedo"][cover == 1][:, :3]
    assert {tuple(a) for a in full} <= bases


LAYERS = {"core": 0, "io": 0, "device": 1, "bake": 2, "scene": 2, "render": 3, "study": 4, "api": 5, "cli": 6}


def test_imports_run_downward():
    """cli -> api -> study -> render -> {scene, bake} -> device -> {core, io}; nothing imports
    cli; core never imports device (every import, function-level ones too)."""
    bad = []
    for f in (ROOT / "iblbake").rglob("*.py"):
        rel = f.relative_to(ROOT / "iblbake").parts
        own = rel[0] if len(rel) > 1 else (f.stem if f.stem in LAYERS else None)
        for node in ast.walk(ast.parse(f.read_text())):
            mods = []
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("iblbake"):
                mods = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                mods = [a.name for a in node.names if a.name.startswith("iblbake")]
            for m in mods:
                parts = m.split(".")
                target = parts[1] if len(parts) > 1 else None
                if target not in LAYERS or target == own:
                    continue
                if target == "cli" and own != "cli" and f.name not in ("entry.py",):
                    bad.append(f"{'/'.join(rel)} imports {m}")
                elif own in LAYERS and LAYERS[target] >= LAYERS[own]:
                    bad.append(f"{'/'.join(rel)} imports {m}")
    assert not bad, bad


@pytest.mark.slow
def test_mesh_triangles_and_bvh_are_cached_by_content(tmp_path, white):
    """A second render reads the mesh's triangles and BVH from the cache (the same pixels); a
    changed mesh file, or another transform, builds them again."""
    import trimesh
    mesh = tmp_path / "m.ply"
    trimesh.creation.icosphere(subdivisions=3, radius=0.8).export(mesh)
    doc = {"camera": {"perspective": {"position": [0, 0, 3]}, "resolution": [32, 24]},
           "environment": {"path": str(white), "background": "hide"},
           "materials": {"m": {"base_color": [0.7, 0.7, 0.7], "roughness": 0.5}},
           "objects": [{"mesh": {"path": str(mesh)}, "material": "m"}]}
    p = tmp_path / "mesh.yaml"
    p.write_text(yaml.safe_dump(doc))

    def geometry(sets=()):
        f = render(scene.load(p, sets), cache_root=tmp_path / "c")
        return f, next(b for b in f.report["bakes"] if b["name"] == "geometry")

    a, ga = geometry()
    b, gb = geometry()
    assert not ga["cached"] and gb["cached"] and gb["triangles"] == 1280
    assert np.array_equal(a.hdr, b.hdr)
    _, gc = geometry(["objects.0.mesh.translate=[0.1,0,0]"])
    assert not gc["cached"]
    trimesh.creation.icosphere(subdivisions=2, radius=0.8).export(mesh)
    _, gd = geometry()
    assert not gd["cached"] and gd["triangles"] == 320


def test_chain_table_uploads_levels_already_back_to_back_without_a_copy(rt):
    """Levels that are consecutive views of one float32 array (a chain read from the cache) go
    up as that array; separate or strided levels are packed; the device holds the same RGB
    texels either way (kernels/envmap.h reads 3 floats a texel)."""
    from iblbake.render.bakes import back_to_back, chain_table
    shapes = [(4, 8), (2, 4), (1, 2)]
    offs = np.cumsum([0] + [h * w for h, w in shapes])
    flat = np.random.default_rng(0).random(3 * offs[-1]).astype(np.float32)
    views = [flat[3 * o:3 * o1].reshape(h, w, 3) for o, o1, (h, w) in zip(offs[:-1], offs[1:], shapes)]
    packed = back_to_back(views, offs)
    assert packed is not None and np.shares_memory(packed, flat) and packed.size == flat.size
    copies = [v.copy() for v in views]
    assert back_to_back(copies, offs) is None                        # separate arrays: packed
    assert back_to_back(views[::-1], offs) is None                   # out of order
    rgba = np.zeros((4, 8, 4), np.float32)
    assert back_to_back([rgba[..., :3]], offs[:2]) is None           # strided
    assert back_to_back([views[0]], offs[:2]) is not None            # one contiguous level
    for levels in (views, copies):
        c = chain_table(rt, levels)
        assert np.array_equal(rt.read(c["chain"], (int(offs[-1]), 3)).reshape(-1), flat)
