"""Trust boundaries of a scene (docs/manual.md, "Paths a scene may name"; iblbake/io/confine.py):
a glTF's buffers and images stay in the glTF's folder, a scene's outputs in the scene's folder,
a mesh read through trimesh reads no file beside it; each way out (absolute, `..`, percent-
encoded, links, URI schemes) is refused with one line, and --allow-outside lifts the rule.

Every open is watched with an audit hook (sys.addaudithook: each Python-level open of a path):
canary files outside the folders must never be opened. The fuzz target puts random absolute,
relative, encoded and linked paths in every path key of a scene and in a glTF's URIs: nothing
read or written outside the rule, 0 raw exceptions (`make test` a few seconds, `make stress` more).
"""

import base64
import contextlib
import json
import os
import random
import re
import sys
import traceback
import types
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest

from iblbake.errors import IblbakeError, InputError
from iblbake.io import images
from iblbake.scene import geometry, gltf, materials
from iblbake.scene import load as scene_load

from tests.helpers import run_cli, scene_file, stress_scale, write_exr

ALLOW = "IBLBAKE_ALLOW_OUTSIDE"
# a triangle's positions and texture coordinates: the bytes of every buffer here (a canary read
# by mistake would load as well as the real one)
BUFFER = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32).tobytes() + \
    np.array([[0, 0], [1, 0], [0, 1]], np.float32).tobytes()

_opened = None          # a list while `watching_opens` records


def _audit(event, args):
    if event == "open" and _opened is not None and isinstance(args[0], (str, bytes, os.PathLike)):
        _opened.append(os.fsdecode(args[0]))


sys.addaudithook(_audit)          # once per process: audit hooks cannot be removed


@contextlib.contextmanager
def watching_opens():
    """The paths every Python-level open (builtins, os.open) is given meanwhile."""
    global _opened
    _opened = seen = []
    try:
        yield seen
    finally:
        _opened = None


def _png(path):
    images.write_png(path, np.full((2, 2, 4), 200, np.uint8))


def make_world(tmp_path):
    """tmp/outside (the canaries) beside tmp/scene (a sky, a buffer, a texture, a subfolder, a
    link out to a canary, a link to a folder outside and a link inside)."""
    out, scene = tmp_path / "outside", tmp_path / "scene"
    (scene / "sub").mkdir(parents=True)
    out.mkdir()
    for folder in (out, scene, scene / "sub"):
        (folder / ("canary.bin" if folder == out else "buf.bin")).write_bytes(BUFFER)
        _png(folder / ("canary.png" if folder == out else "tex.png"))
    (out / "canary.mtl").write_text("newmtl a\nKd 1 0 0\n")
    write_exr(scene / "sky.exr", np.ones((8, 16, 3), np.float32))
    os.symlink(out / "canary.bin", scene / "link_out.bin")
    os.symlink(out / "canary.png", scene / "link_out.png")
    os.symlink(out, scene / "link_dir")
    os.symlink("buf.bin", scene / "link_in.bin")
    return types.SimpleNamespace(root=tmp_path, out=out, scene=scene, sky=scene / "sky.exr")


@pytest.fixture
def world(tmp_path):
    return make_world(tmp_path)


def write_gltf(path, buffer_uri, image_uri="tex.png"):
    """A one-triangle glTF whose buffer (positions, TEXCOORD_0) and base colour image are named
    by these URIs (None: the image left out)."""
    doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": buffer_uri, "byteLength": len(BUFFER)}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                           {"buffer": 0, "byteOffset": 36, "byteLength": 24}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
                         {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "material": 0}]}],
           "materials": [{"pbrMetallicRoughness": {}}],
           "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0}
    if image_uri is not None:
        doc["images"] = [{"uri": image_uri}]
        doc["textures"] = [{"source": 0}]
        doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    Path(path).write_text(json.dumps(doc))
    return Path(path)


def mesh_scene(w, mesh="m.gltf", **sections):
    return scene_file(w.scene, w.sky, objects=[{"mesh": {"path": str(mesh)}}], **sections)


def canaries_opened(w, seen) -> list:
    return [p for p in seen if Path(os.path.realpath(p)).is_relative_to(os.path.realpath(w.out))]


# --- a glTF's URIs ------------------------------------------------------------------------------

def _ways_out(w) -> dict:
    """URI -> what it is, each naming a canary outside the glTF's folder (w.scene)."""
    absolute = str(w.out / "canary.bin")
    return {absolute: "absolute", "../outside/canary.bin": "..", "%2E%2E/outside/canary.bin": "percent-encoded ..",
            "..%2Foutside%2Fcanary.bin": "percent-encoded /", "sub/../../outside/canary.bin": "in, then out",
            "link_out.bin": "a link out", "link_dir/canary.bin": "a linked folder", "file://" + absolute: "a file: URI",
            quote(absolute): "percent-encoded absolute"}


@pytest.mark.parametrize("role", ["buffer", "image"])
def test_gltf_uris_outside_their_folder_are_refused(world, role):
    """Were read (a buffer up to 2 GiB), turned into triangles and rendered, exit 0: a canary
    outside the glTF's folder is now never opened, by the scene loader or by the glTF reader."""
    for uri, kind in _ways_out(world).items():
        if role == "image":
            uri = uri.replace("canary.bin", "canary.png")
        path = write_gltf(world.scene / "m.gltf", *(("buf.bin", uri) if role == "image" else (uri, "tex.png")))
        with watching_opens() as seen:
            with pytest.raises(InputError) as e:
                scene_load.load(mesh_scene(world))
            msg = str(e.value)
            assert f"the URI {uri!r}" in msg and "objects.0.mesh.path" in msg and "\n" not in msg, (kind, msg)
            assert ("scheme" in msg) if kind == "a file: URI" else ("--allow-outside" in msg), (kind, msg)
            doc = gltf.read(path, "here")       # the reader's own guard: a mesh changed after loading
            with pytest.raises(InputError, match=r"here: mesh .*m\.gltf: (buffer|image) 0 "):
                doc.buffer(0) if role == "buffer" else doc.image(0)
            assert all(os.path.realpath(f).startswith(os.path.realpath(world.scene))
                       for f in gltf.external_files(path)), kind          # what depfiles and cache keys hash
        assert canaries_opened(world, seen) == [], kind


def test_a_glb_naming_a_buffer_outside_is_refused(world):
    """A GLB may name buffers by URI too: the same rule when its mesh is read."""
    from iblbake.io.gltf import glb_bytes
    doc = json.loads(write_gltf(world.scene / "m.gltf", "../outside/canary.bin", None).read_text())
    glb = world.scene / "m.glb"
    glb.write_bytes(glb_bytes(doc, b""))
    with watching_opens() as seen:
        with pytest.raises(InputError, match=r"buffer 0 '\.\./outside/canary\.bin' is a path that leaves the glTF's"):
            geometry.load_mesh({"path": str(glb)}, "here")
    assert canaries_opened(world, seen) == []


def test_a_glb_s_uris_are_checked_at_load_and_listed_as_inputs(world):
    """A .glb's external URIs were neither checked by the scene loader (deps exited 0; render
    refused later under objects.0.mesh, no line) nor listed by deps: now as a .gltf's."""
    from iblbake.io.gltf import glb_bytes
    for uri in ("../outside/canary.bin", "buf.bin"):
        doc = json.loads(write_gltf(world.scene / "m.gltf", uri, "tex.png").read_text())
        (world.scene / "m.glb").write_bytes(glb_bytes(doc, b""))
        scene = mesh_scene(world, "m.glb")
        if uri != "buf.bin":
            with watching_opens() as seen, pytest.raises(InputError) as e:
                scene_load.load(scene)
            assert re.match(r".*scene\.yaml:\d+: objects\.0\.mesh\.path: .*m\.glb: the URI '\.\./outside/canary\.bin' "
                            r"is a path that leaves the glTF's folder", str(e.value)), str(e.value)
            assert canaries_opened(world, seen) == []
            continue
        names = [os.path.basename(f) for f in scene_load.input_files(scene_load.load(scene))]
        assert names == ["scene.yaml", "sky.exr", "m.glb", "buf.bin", "tex.png"], names


def test_gltf_uris_inside_their_folder_and_data_uris_are_read(world):
    """What stays in the folder is read as before: a subfolder, `..` that stays in, a percent-
    encoded name, a link to a file beside it, and a data: URI (no file)."""
    data = "data:application/octet-stream;base64," + base64.b64encode(BUFFER).decode()
    for uri in ("buf.bin", "sub/buf.bin", "sub/../buf.bin", "%62uf.bin", "su%62/buf.bin", "link_in.bin", data):
        path = write_gltf(world.scene / "m.gltf", uri, "sub/%74ex.png")
        sc = scene_load.load(mesh_scene(world))
        assert gltf.read(path, "here").buffer(0) == BUFFER, uri
        mesh = geometry.load_mesh(sc.data["objects"][0]["mesh"], "here")
        np.testing.assert_array_equal(mesh.vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
        records, _ = materials.table(sc)
        textures, _ = materials.load_textures(records, "here")
        assert len(textures.textures) == 1, uri


def test_allow_outside_lets_a_gltf_read_outside(world, monkeypatch):
    """IBLBAKE_ALLOW_OUTSIDE=1 (what --allow-outside sets) reads what the user means; any other
    value than 0 or 1 is refused naming the variable."""
    path = write_gltf(world.scene / "m.gltf", str(world.out / "canary.bin"), "../outside/canary.png")
    monkeypatch.setenv(ALLOW, "1")
    sc = scene_load.load(mesh_scene(world))
    with watching_opens() as seen:
        assert gltf.read(path, "here").buffer(0) == BUFFER
        records, _ = materials.table(sc)
        materials.load_textures(records, "here")
    assert sorted({os.path.realpath(p) for p in canaries_opened(world, seen)}) == [str(world.out / "canary.bin"), str(world.out / "canary.png")]
    monkeypatch.setenv(ALLOW, "yes")
    with pytest.raises(InputError, match=r"IBLBAKE_ALLOW_OUTSIDE='yes': give 1 .* or 0"):
        scene_load.load(mesh_scene(world))


def test_a_bad_allow_outside_is_refused_on_every_load(world, monkeypatch):
    """IBLBAKE_ALLOW_OUTSIDE=2 was checked only when a path met the rule (a plain scene loaded,
    render exited 0) and then pinned on that key (`objects.0.mesh.path: IBLBAKE_ALLOW_OUTSIDE=...`):
    it is checked on every load, the message naming the variable alone."""
    write_gltf(world.scene / "m.gltf", "../outside/canary.bin")
    monkeypatch.setenv(ALLOW, "2")
    for scene in (scene_file(world.scene, world.sky, name="plain.yaml"), mesh_scene(world)):
        with pytest.raises(InputError) as e:
            scene_load.load(scene)
        assert str(e.value) == "IBLBAKE_ALLOW_OUTSIDE='2': give 1 (scenes and assets may name files outside " \
                               "their folder) or 0", str(e.value)
    p = run_cli("deps", world.scene / "plain.yaml", env={ALLOW: "2"})
    assert p.returncode == 1 and p.stderr.count("\n") == 1 and "IBLBAKE_ALLOW_OUTSIDE='2'" in p.stderr, p.stderr


def test_meshes_read_no_file_beside_them(world):
    """trimesh read an OBJ's material library and a PLY's texture (anything they named, a FIFO
    beside them blocked the render); the scene's materials shade these meshes: no other file is
    opened, and the triangles are those of before."""
    (world.scene / "side.mtl").write_text("newmtl a\nKd 1 0 0\nmap_Kd tex.png\n")
    obj = world.scene / "t.obj"
    obj.write_text("mtllib side.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl a\nf 1/1 2/2 3/3\n")
    ply = world.scene / "t.ply"
    ply.write_text("ply\nformat ascii 1.0\ncomment TextureFile tex.png\nelement vertex 3\nproperty float x\n"
                   "property float y\nproperty float z\nproperty float s\nproperty float t\nelement face 1\n"
                   "property list uchar int vertex_indices\nend_header\n0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 2\n")
    for mesh in (obj, ply):
        with watching_opens() as seen:
            m = geometry.load_mesh({"path": str(mesh)}, "here")
        mine = {os.path.realpath(p) for p in seen if os.path.realpath(p).startswith(str(world.root))}
        assert mine == {str(mesh)}, mesh.name
        np.testing.assert_array_equal(m.vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
        np.testing.assert_allclose(m.uv[0], [[0, 1], [1, 1], [0, 0]])        # v flipped to glTF's


# --- a scene's outputs --------------------------------------------------------------------------

@pytest.mark.parametrize("key", ["frame", "normal"])
def test_scene_outputs_outside_the_folder_are_refused(world, key):
    """An absolute output.frame or AOV was written wherever it named, exit 0, where `../x.png`
    was refused: the rule holds for absolute paths and links too."""
    suffix = ".png" if key == "frame" else ".exr"
    for given in (str(world.out / f"x{suffix}"), str(world.scene / "link_dir" / f"x{suffix}"), f"link_dir/x{suffix}",
                  f"../outside/x{suffix}", f"/x{suffix}"):
        scene = scene_file(world.scene, world.sky, output={key: given})
        with pytest.raises(InputError) as e:
            scene_load.load(scene)
        msg = str(e.value)
        assert f"output.{key}: {given!r} leaves the scene's folder {world.scene}" in msg and \
            "-o on the command line, or pass --allow-outside" in msg, msg


def test_scene_outputs_inside_the_folder_are_taken(world, monkeypatch):
    """An absolute path inside the folder is taken, a percent sign is a file name's (a scene's
    paths are paths, not URIs); IBLBAKE_ALLOW_OUTSIDE=1 takes any."""
    scene = scene_file(world.scene, world.sky, output={"frame": [str(world.scene / "a.png"), "%2E%2E/b.png"],
                                                     "depth": "sub/../d.exr"})
    out = scene_load.load(scene).data["output"]
    assert out["frame"] == [str(world.scene / "a.png"), str(world.scene / "%2E%2E" / "b.png")]
    assert out["depth"] == str(world.scene / "d.exr")
    monkeypatch.setenv(ALLOW, "1")
    scene = scene_file(world.scene, world.sky, output={"frame": str(world.out / "x.png"), "albedo": "../a.exr"})
    out = scene_load.load(scene).data["output"]
    assert out["frame"] == [str(world.out / "x.png")] and out["albedo"] == str(world.root / "a.exr")


def test_a_nul_in_a_scene_path_is_refused(world):
    """Found by the fuzz target: a NUL in any path key was a raw ValueError (embedded null byte)."""
    for key, section in (("environment.path", {"environment": {"path": "a\0b.exr"}}),
                         ("objects.0.mesh.path", {"objects": [{"mesh": {"path": "a\0b.ply"}, "material": "m"}]}),
                         ("materials.m.base_color_map.path", {"materials": {"base_color_map": {"path": "a\0.png"},
                                                                            "base_color": [1, 1, 1]}}),
                         ("output.frame", {"output": {"frame": ["f.png", "a\0.png"]}}),
                         ("output.depth", {"output": {"depth": "a\0.exr"}})):
        with pytest.raises(InputError, match=rf"{key}: '.*' holds a NUL character, which no path can"):
            scene_load.load(scene_file(world.scene, world.sky, **section))


@pytest.mark.slow          # two renders: over 3 s on the 2-core CPU
def test_render_writes_outside_only_when_allowed(world, tmp_path):
    """End to end: render refuses a scene's absolute output (exit 1, one line, nothing written),
    writes it with --allow-outside; -o is the user's own and goes anywhere."""
    target = world.out / "x.png"
    scene = scene_file(world.scene, world.sky, output={"frame": str(target)},
                       camera={"perspective": {"position": [0, 0, 3]}, "resolution": [16, 12]})
    cache = ["--cache", tmp_path / "cache"]
    p = run_cli("render", scene, *cache, "-q")
    assert p.returncode == 1 and p.stderr.count("\n") == 1, p.stderr
    assert "leaves the scene's folder" in p.stderr and not target.exists()
    p = run_cli("render", scene, *cache, "-q", "--allow-outside")
    assert p.returncode == 0 and target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", p.stderr
    p = run_cli("render", scene, *cache, "-q", "-o", world.out / "y.png")
    assert p.returncode == 0 and (world.out / "y.png").is_file(), p.stderr


@pytest.mark.slow          # two command lines: 3.1 s on the 2-core CPU
def test_cli_refuses_a_gltf_reading_outside(world):
    """The command line's one line (exit 1) for a buffer outside, and --allow-outside on deps."""
    write_gltf(world.scene / "m.gltf", str(world.out / "canary.bin"))
    scene = mesh_scene(world, output={"frame": "f.png"})
    p = run_cli("render", scene, "-q")
    assert p.returncode == 1 and p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr
    assert f"the URI {str(world.out / 'canary.bin')!r} is an absolute path" in p.stderr, p.stderr
    p = run_cli("deps", scene, "--allow-outside")
    assert p.returncode == 0 and str(world.out / "canary.bin") in p.stdout, p.stderr


# --- the fuzz target ------------------------------------------------------------------------------

def _encode(s: str, rng) -> str:
    """`s` with random characters percent-encoded (a URI decodes them back)."""
    return "".join(f"%{b:02X}" if rng.random() < 0.3 else chr(b) if b < 128 else quote(chr(b))
                   for b in s.encode("utf-8")) if s.isascii() else quote(s)


def _random_path(w, rng, name: str, uri: bool) -> str:
    """A path (or a URI) to the file `name` beside the scene, or to a canary outside, in one of
    the ways there are to write it."""
    out_name = {"bin": "canary.bin", "png": "canary.png", "exr": "canary.bin", "gltf": "canary.bin"}[name.rsplit(".", 1)[-1]]
    forms = [name, "./" + name, "sub/" + name, "sub/../" + name, str(w.scene / name),
             str(w.out / out_name), "../outside/" + out_name, "sub/../../outside/" + out_name,
             "../" * rng.randint(2, 12) + str(w.out / out_name).lstrip("/"), "link_out." + out_name.split(".")[1],
             "link_dir/" + out_name, str(w.scene / "link_dir" / out_name), "link_in.bin",
             "file://" + str(w.out / out_name), "http://example.invalid/" + name, "", "/", "//", ".", "..",
             "~/" + name, "a\x00b", "%00", "%ZZ", "é/" + name, "x" * rng.choice((255, 300, 5000)), "sub", "\\..\\x"]
    p = rng.choice(forms)
    if uri and rng.random() < 0.4:
        p = _encode(p, rng)
    return p


def _scene_doc(w, rng, mesh: str, env: str, tex: str) -> dict:
    """A scene of the mesh under the panorama, textured; its outputs usually inside, else random."""
    def outs(sfx):
        return _random_path(w, rng, "o" + sfx, False) + rng.choice(("", sfx)) if rng.random() < 0.4 else "o" + sfx
    doc = {"camera": {"perspective": {"position": [0, 0, 3]}, "resolution": [8, 8]},
           "environment": {"path": env}, "materials": {"m": {"base_color_map": {"path": tex}}},
           "objects": [{"mesh": {"path": mesh}, "material": "m"}],
           "output": {"frame": [outs(".png") for _ in range(rng.randint(1, 2))]}}
    for aov in rng.sample(scene_load.AOVS, rng.randint(0, 2)):
        doc["output"][aov] = outs(".exr")
    return doc


def _inputs_named(w, doc) -> set:
    """The files the scene itself names as inputs, links resolved: the user's, read wherever."""
    named = [doc["environment"]["path"], doc["objects"][0]["mesh"]["path"],
             doc["materials"]["m"]["base_color_map"]["path"]]
    out = set()
    for p in named:
        try:
            out.add(os.path.realpath(w.scene / p))
        except ValueError:         # a NUL in it: names nothing
            pass
    return out


def _exercise(sc) -> None:
    """What rendering a loaded scene reads: its meshes, their materials and textures, the files
    its cache keys hash, its depfile's list."""
    for o in sc.data["objects"]:
        geometry.load_mesh(o["mesh"], "fuzz")
        for f in gltf.external_files(o["mesh"]["path"]):
            images.file_sha256(f)
    records, _ = materials.table(sc)
    materials.load_textures(records, "fuzz")
    scene_load.input_files(sc)


def fuzz_case(w, rng, allowed: bool) -> tuple:
    """One random scene and glTF; (raw exception or None, escapes found, whether it rendered's
    reads all ran)."""
    import yaml
    folder = w.scene / rng.choice(("", "sub"))
    def some(name, uri, p=0.5):           # random, or the file itself (so that most cases load)
        return _random_path(w, rng, name, uri) if rng.random() < p else name
    write_gltf(folder / "m.gltf", some("buf.bin", True), rng.choice((None, some("tex.png", True))))
    mesh = rng.choice([str(folder.relative_to(w.scene) / "m.gltf"), str(folder / "m.gltf"), some("m.gltf", False)])
    env, tex = some("sky.exr", False, 0.2), some("tex.png", False, 0.2)
    doc = _scene_doc(w, rng, mesh, env, tex)
    scene = w.scene / "fuzz.yaml"
    scene.write_text(yaml.safe_dump(doc))
    escapes, sc = [], None
    with watching_opens() as seen:
        try:
            sc = scene_load.load(scene)
            _exercise(sc)
            whole = True
        except IblbakeError:
            whole = False
        except Exception as e:        # a raw exception: the fuzz's failure
            at = [f for f in traceback.extract_tb(e.__traceback__) if "iblbake" in f.filename][-1]
            return f"{type(e).__name__}: {e} at {at.filename}:{at.lineno} (scene {doc}, glTF " \
                   f"{(folder / 'm.gltf').read_text()})", [], False
    if allowed:
        return None, [], whole
    named = _inputs_named(w, doc)
    escapes += [f"read {p}" for p in canaries_opened(w, seen) if os.path.realpath(p) not in named]
    if sc is not None:
        outs = sc.data["output"]["frame"] + [sc.data["output"][a] for a in scene_load.AOVS if sc.data["output"][a]]
        escapes += [f"writes {p}" for p in outs if not Path(os.path.realpath(p)).is_relative_to(os.path.realpath(w.scene))]
    return None, [f"{e} (scene {doc})" for e in escapes], whole


def test_fuzz_paths_in_scenes_and_gltf_uris(world, stress, monkeypatch):
    """Random absolute, relative, percent-encoded and linked paths in every path key of a scene
    and in its glTF's buffer and image URIs: no canary opened unless the scene names it as an
    input itself, no output outside the scene's folder, and 0 raw exceptions; one case in five
    with IBLBAKE_ALLOW_OUTSIDE=1 (any path taken: still no raw exception)."""
    rng = random.Random(60)
    raw, escapes, whole = [], [], 0
    n = stress_scale(60, 1500)
    for k in range(n):
        allowed = k % 5 == 4
        monkeypatch.setenv(ALLOW, "1" if allowed else "0")
        exc, esc, ran = fuzz_case(world, rng, allowed)
        raw += [exc] if exc else []
        escapes += esc
        whole += ran
    stress.count("inputs fuzzed", n)
    assert not raw and not escapes, (len(raw), raw[:3], len(escapes), escapes[:3])
    assert whole >= n // 10, f"only {whole} of {n} cases loaded and read everything: the fuzz tests too little"
    stress.check("scene paths fuzz: raw exceptions", len(raw), 0, "count")
    stress.check("scene paths fuzz: reads or writes outside the rule", len(escapes), 0, "count")
