"""Fuzzing the loaders (issue 7): scene YAML, meshes and panoramas, real malformed files and
random mutations of valid ones. Every input is either accepted (a scene then renders with a finite
frame) or refused with the one-line error; never a traceback, a native crash, a hang or an object
constructed from YAML tags. Loaders run in a child process (tests/fuzz_worker.py) so a crash in a
native decoder is caught and counted instead of taking pytest down.

`make test` runs a fast subset; `make stress` (IBLBAKE_STRESS=1) fuzzes ten times more inputs.
"""

import json
import random
import re
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from iblbake.io import images

from tests.helpers import ROOT, run_cli, stress_scale

WORKER = Path(__file__).with_name("fuzz_worker.py")
ASSIMP = ROOT / "tests" / "data" / "assimp"
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")


def run_worker(kind, files, cache, limit_memory=True):
    """Outcomes of the worker on `files`, restarting it after a native crash."""
    results, todo = [], [str(f) for f in files]

    def limits():
        if limit_memory:   # an allocation bomb becomes MemoryError, not the OOM killer
            resource.setrlimit(resource.RLIMIT_AS, (6 << 30, 6 << 30))

    while todo:
        p = subprocess.run([sys.executable, str(WORKER), kind, str(cache), *todo], capture_output=True,
                           text=True, timeout=1800, preexec_fn=limits)
        started, done = None, set()
        for line in p.stdout.splitlines():
            rec = json.loads(line)
            if "start" in rec:
                started = rec["start"]
            else:
                results.append(rec)
                done.add(rec["file"])
        if p.returncode == 0:
            break
        # the child died on a signal (or exited) while on `started`: a native crash of that input
        results.append({"file": started, "outcome": "crash", "seconds": 0,
                        "message": f"child exited {p.returncode}: {p.stderr[-500:]}"})
        todo = todo[todo.index(started) + 1:] if started in todo else []
    return results


def judge(stress, results, case, names_file=True):
    """Count, then assert: no crash/hang/non-finite, each error one line naming its input."""
    stress.count("inputs fuzzed", len(results))
    bad = [r for r in results if r["outcome"] in ("crash", "hang", "nonfinite")]
    stress.count("crashes", len(bad))
    assert not bad, f"{case}: {len(bad)} inputs crashed or hung, first: {bad[0]['file']}: {bad[0]['message']}"
    for r in results:
        if r["outcome"] == "error":
            msg = r["message"]
            assert "\n" not in msg.strip(), (r["file"], msg)
            if names_file:
                assert Path(r["file"]).name in msg or "fuzz.yaml" in msg, (r["file"], msg)
    slowest = max((r["seconds"] for r in results), default=0.0)
    stress.check(f"{case}: slowest input", slowest, 30.0, "seconds")
    return results


# --- mutations --------------------------------------------------------------------------------

def mutate_bytes(data: bytes, rng: random.Random) -> bytes:
    buf = bytearray(data)
    kind = rng.randrange(4)
    if kind == 0:                                  # truncated
        return bytes(buf[:rng.randrange(0, len(buf))])
    if kind == 1:                                  # bit flips
        for _ in range(rng.randrange(1, 24)):
            buf[rng.randrange(len(buf))] ^= 1 << rng.randrange(8)
    elif kind == 2:                                # a run of bytes overwritten with 0x00 or 0xff
        i = rng.randrange(len(buf))
        n = rng.randrange(1, 64)
        buf[i:i + n] = bytes([rng.choice((0, 255))]) * len(buf[i:i + n])
    else:                                          # a chunk duplicated (lengths no longer match)
        i, j = sorted(rng.randrange(len(buf)) for _ in range(2))
        buf[j:j] = buf[i:i + 256]
    return bytes(buf)


HOSTILE_NUMBERS = ["nan", "inf", "-inf", ".nan", ".inf", "-.inf", "1e308", "-1e308", "1e-320", "0", "-0", "-1", "4294967296",
                   "99999999999999999999", "1e6", "1e-6"]


def mutate_text(text: str, rng: random.Random) -> str:
    lines = text.splitlines()
    kind = rng.randrange(4)
    if kind == 0 and lines:                        # a line deleted
        del lines[rng.randrange(len(lines))]
    elif kind == 1 and lines:                      # a line duplicated
        i = rng.randrange(len(lines))
        lines.insert(i, lines[i])
    elif kind == 2:                                # a number replaced by a hostile one
        nums = list(re.finditer(r"-?\d+(\.\d+)?(e-?\d+)?", text))
        if nums:
            m = rng.choice(nums)
            return text[:m.start()] + rng.choice(HOSTILE_NUMBERS) + text[m.end():]
    else:
        return mutate_bytes(text.encode(), rng).decode("utf-8", "replace")
    return "\n".join(lines) + "\n"


# --- meshes -----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def assimp_models():
    if not (ASSIMP / ".complete").exists():
        pytest.fail(f"{ASSIMP} missing: run `make testmodels` (Debian's assimp-testmodels)")
    return sorted(p for p in ASSIMP.rglob("*") if p.suffix.lower() in MESH_SUFFIXES)


@pytest.mark.external
def test_real_malformed_meshes_fail_with_one_line(tmp_path, stress, assimp_models):
    """Every OBJ/PLY/STL/OFF/glTF of assimp-testmodels (its invalid/ folder, out-of-range indices,
    infinities, schema failures, wrong types, Draco): loaded or refused in one line."""
    results = judge(stress, run_worker("mesh", assimp_models, tmp_path), "assimp-testmodels meshes")
    by_name = {Path(r["file"]).relative_to(ASSIMP).as_posix(): r for r in results}
    # the named hard cases are refused for the right reason
    expect = {
        "glTF2/IndexOutOfRange/IndexOutOfRange.gltf": "indexes vertex",
        "glTF2/BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb": "not finite",
        "glTF2/SchemaFailures/sceneWrongType.gltf": "cannot be read",
        "glTF2/draco/2CylinderEngine.gltf": "Draco",
        "invalid/empty.obj": "no triangles",
        "invalid/malformed.obj": "cannot be read",
        "invalid/OutOfMemory.off": "cannot be read",
    }
    for name, text in expect.items():
        r = by_name[name]
        assert r["outcome"] == "error" and text in r["message"], (name, r)
    # and real well-formed meshes load
    for name in ("PLY/cube_binary.ply", "STL/Spider_binary.stl", "OBJ/box.obj",
                 "glTF2/BoxTextured-glTF-Binary/BoxTextured.glb"):
        assert by_name[name]["outcome"] == "ok", by_name[name]


@pytest.mark.external
def test_mutated_meshes_fail_cleanly(tmp_path, stress, assimp_models):
    rng = random.Random(7)
    seeds = [ASSIMP / n for n in ("PLY/cube_binary.ply", "PLY/cube.ply", "STL/Spider_binary.stl",
                                  "STL/triangle.stl", "OBJ/box.obj", "OFF/Cube.off",
                                  "glTF2/BoxTextured-glTF-Binary/BoxTextured.glb")]
    files = []
    for k in range(stress_scale(80, 800)):
        src = seeds[k % len(seeds)]
        data = src.read_bytes()
        text_format = src.suffix.lower() in (".obj", ".off") or (src.suffix == ".ply" and b"ascii" in data[:64])
        out = mutate_text(data.decode(), rng).encode() if text_format and k % 2 else mutate_bytes(data, rng)
        f = tmp_path / f"m{k:04d}{src.suffix}"
        f.write_bytes(out)
        files.append(f)
    judge(stress, run_worker("mesh", files, tmp_path), "mutated meshes")


# --- panoramas --------------------------------------------------------------------------------

def _seed_images(folder):
    import OpenImageIO as oiio
    rng = np.random.default_rng(3)
    img = (rng.random((32, 64, 3)) * 4).astype(np.float32)
    out = []
    for name, fmt, extra in (("f.exr", oiio.FLOAT, {}), ("h.exr", oiio.HALF, {}),
                             ("t.exr", oiio.HALF, {"tile": 16}), ("r.hdr", oiio.FLOAT, {}),
                             ("p.pfm", oiio.FLOAT, {}), ("t.tif", oiio.FLOAT, {})):
        spec = oiio.ImageSpec(64, 32, 3, fmt)
        if "tile" in extra:
            spec.tile_width = spec.tile_height = extra["tile"]
        path = folder / name
        o = oiio.ImageOutput.create(str(path))
        assert o.open(str(path), spec) and o.write_image(img), o.geterror()
        o.close()
        out.append(path)
    return out


def test_mutated_panoramas_fail_cleanly(tmp_path, stress):
    """Truncated, bit-flipped, zeroed and spliced EXR (scanline, tiled, half), HDR, PFM, TIFF."""
    rng = random.Random(11)
    seeds = _seed_images(tmp_path)
    files = []
    for k in range(stress_scale(90, 900)):
        src = seeds[k % len(seeds)]
        f = tmp_path / f"i{k:04d}{src.suffix}"
        f.write_bytes(mutate_bytes(src.read_bytes(), rng))
        files.append(f)
    results = judge(stress, run_worker("image", files, tmp_path), "mutated panoramas")
    # most mutations are caught (a flipped bit in pixel data is a valid image: that is fine)
    assert sum(r["outcome"] == "error" for r in results) >= len(results) // 4


def test_fuzzed_files_through_the_cli(tmp_path, stress):
    """End to end: what the user sees for a broken panorama is one line on stderr and exit 1."""
    rng = random.Random(5)
    src = _seed_images(tmp_path)[0].read_bytes()
    n = stress_scale(6, 30)
    for k in range(n):
        f = tmp_path / f"c{k}.exr"
        f.write_bytes(mutate_bytes(src, rng)[: len(src) // 2])   # truncated: always broken
        out = tmp_path / f"c{k}.json"
        p = run_cli("sh", f, "-o", out)
        assert p.returncode == 1 and "Traceback" not in p.stderr, p.stderr[-400:]
        assert len(p.stderr.strip().splitlines()) == 1 and f"c{k}.exr" in p.stderr, p.stderr
        assert not out.exists()
    stress.count("inputs fuzzed", n)


# --- scenes -----------------------------------------------------------------------------------

HOSTILE_SCENES = {
    "alias bomb": "a: &a [x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
                  "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
                  "e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d]\nf: [*e, *e, *e, *e, *e, *e, *e, *e, *e]\n",
    "recursive alias": "camera: &a {perspective: *a}\n",
    "python object": "camera: !!python/object/apply:os.system ['touch PWNED']\n",
    "python name": "effects: !!python/name:os.system\n",
    "custom tag": "materials: !mine {m: 1}\n",
    "binary": "environment: {path: !!binary aGVsbG8=}\n",
    "timestamp": "environment: {path: 2024-01-01}\n",
    "deep nesting": "a: " + "[" * 3000 + "]" * 3000 + "\n",
    "collection key": "? [a, b]\n: 1\n",
    "null key": "~: 1\n",
    "tabs": "camera:\n\tresolution: [4, 4]\n",
    "not a mapping": "- camera\n- objects\n",
    "empty": "",
    "huge": "a: " + "x" * (2 << 20) + "\n",
    "nan resolution": "camera: {resolution: [.nan, 16]}\n",
    "inf roughness": "materials: {m: {roughness: .inf}}\n",
    "negative radius": "objects: [{sphere: {radius: -1}, material: m}]\n",
    "zero scale": "objects: [{mesh: {path: cube.ply, scale: 0}, material: m}]\n",
    "output escapes": "output: {frame: ../../escaped.png}\n",
    "bad utf-8": b"camera: {resolution: [4, 4]}\n\xff\xfe\n",
    "unknown section": "camra: {}\n",
}


def _base_scene(folder: Path) -> str:
    """A valid scene that touches every section, with a small panorama and mesh beside it."""
    images.write_exr(folder / "env.exr", (np.random.default_rng(0).random((16, 32, 3)) * 2).astype(np.float32))
    import trimesh
    trimesh.creation.box().export(folder / "cube.ply")
    doc = {
        "camera": {"perspective": {"position": [0, 1, 5], "look_at": [0, 0, 0], "fov_y": 40},
                   "resolution": [32, 24], "spp": 1},
        "environment": {"path": "env.exr", "intensity": 1.0, "rotation_y": 30, "background": "show", "blur": 0.2},
        "materials": {"m": {"base_color": [0.8, 0.2, 0.2], "metallic": 0.0, "roughness": 0.4},
                      "gold": {"base_color": [1.0, 0.8, 0.3], "metallic": 1.0, "roughness": 0.2,
                               "emissive": [0.1, 0.0, 0.0]}},
        "objects": [{"sphere": {"center": [0, 0, 0], "radius": 1}, "material": "gold"},
                    {"plane": {"point": [0, -1, 0], "normal": [0, 1, 0], "size": 6}, "material": "m"},
                    {"mesh": {"path": "cube.ply", "translate": [2, 0, 0], "rotate": [0, 30, 0], "scale": 0.5},
                     "material": "m"}],
        "effects": {"diffuse": "sh", "sh_bands": 3, "specular": "importance", "samples": 16, "mip_bias": 1.0,
                    "tonemap": "aces", "exposure": 0.0},
        "output": {"frame": ["out/frame.png"]},
    }
    return yaml.safe_dump(doc, sort_keys=False)


def hostile_document(base: str, text) -> bytes:
    """The hostile text in place of the base scene's section of the same name (so the hostile
    value is what the loader meets, not a duplicate key), or alone if it is a whole document."""
    if isinstance(text, bytes):
        return text
    section = text.split(":", 1)[0]
    doc = yaml.safe_load(base)
    if section not in doc:
        return text.encode()
    del doc[section]
    return (text + yaml.safe_dump(doc, sort_keys=False)).encode()


@pytest.mark.slow
def test_scene_loader_fuzz(tmp_path, stress):
    """Hand-written hostile documents and random mutations of a scene touching every section:
    loaded and rendered (finite frame) or refused in one line naming the scene file; YAML tags
    never construct anything (no PWNED file appears)."""
    base = _base_scene(tmp_path)
    (tmp_path / "base.yaml").write_text(base)
    assert run_worker("scene", [tmp_path / "base.yaml"], tmp_path / "cache", False)[0]["outcome"] == "ok"
    rng = random.Random(13)
    files = []
    for name, text in HOSTILE_SCENES.items():
        f = tmp_path / f"hostile-{name.replace(' ', '-')}.yaml"
        f.write_bytes(hostile_document(base, text))
        files.append(f)
    for k in range(stress_scale(70, 600)):
        f = tmp_path / f"mut{k:04d}.yaml"
        text = base
        for _ in range(1 if k % 2 else rng.randrange(1, 4)):
            text = mutate_text(text, rng)
        f.write_text(text)
        files.append(f)
    results = judge(stress, run_worker("scene", files, tmp_path / "cache", limit_memory=False), "scene YAML")
    assert not (tmp_path / "PWNED").exists() and not Path("PWNED").exists()
    by_name = {Path(r["file"]).name: r for r in results}
    for name in ("alias bomb", "recursive alias", "python object", "python name", "custom tag", "binary",
                 "deep nesting", "huge", "output escapes", "bad utf-8"):
        r = by_name[f"hostile-{name.replace(' ', '-')}.yaml"]
        assert r["outcome"] == "error", (name, r)
    accepted = sum(r["outcome"] == "ok" for r in results)
    assert accepted >= len(results) // 20, "the mutations should leave some scenes valid (and rendered)"


def test_hostile_scenes_through_the_cli(tmp_path, stress):
    base = _base_scene(tmp_path)
    for name in ("python object", "alias bomb", "recursive alias", "tabs"):
        f = tmp_path / "s.yaml"
        text = HOSTILE_SCENES[name]
        f.write_bytes(hostile_document(base, text))
        p = run_cli("render", f, "-o", tmp_path / "x.png")
        assert p.returncode == 1 and "Traceback" not in p.stderr, p.stderr[-400:]
        assert len(p.stderr.strip().splitlines()) == 1 and "s.yaml" in p.stderr, (name, p.stderr)
        assert not (tmp_path / "x.png").exists()
    stress.count("inputs fuzzed", 4)


@pytest.mark.slow
@pytest.mark.parametrize("reader", ["ktx2", "layout"])
def test_cube_map_readers_under_coverage_guided_fuzzing(tmp_path, stress, reader):
    """tests/fuzz_readers.py under atheris (libFuzzer's engine) per reader: the KTX2 parser
    seeded with a valid file of every format, the cross/strip face splitter on images of every
    shape; 20,000 executions each here, 1,000,000 in `make stress`. Every input must be read or
    refused with a one-line InputError naming the file; a finding fails the run and leaves its
    input as crash-* (the message names it)."""
    runs = stress_scale(20000, 1000000)
    env = dict(__import__("os").environ, IBLBAKE_FUZZ_READER=reader)
    p = subprocess.run([sys.executable, str(WORKER.with_name("fuzz_readers.py")), str(tmp_path / "corpus"),
                        f"-atheris_runs={runs}", "-max_len=4096", "-seed=1"], cwd=tmp_path, capture_output=True,
                       text=True, timeout=3000, env=env)
    found = sorted(tmp_path.glob("crash-*"))
    stress.count("inputs fuzzed", runs)
    stress.count("crashes", len(found))
    stress.check(f"atheris {reader}: {runs} executions", len(found), 0, "crashes")
    assert p.returncode == 0 and not found, (found, p.stderr[-3000:])
    assert f"Done {runs} " in p.stderr, p.stderr[-500:]
