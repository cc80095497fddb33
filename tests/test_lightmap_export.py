"""`iblbake lightmap` (render/lightmaps/export.py, gltf_scene.py): a scene's lightmap as the files
engines load, read back by real readers:
- the atlases' EXR read back equal the bake to fp16 (what the file stores), A the texels baked or
  dilated; the manifest's reading of each basis, applied to the files, gives the bake's irradiance;
- ktx-parse (three.js's KTX2Loader parser) returns the KTX2 atlases bit for bit equal to the EXR's,
  and the glTF Sample Viewer's libktx opens them;
- Khronos' glTF-Validator finds no error or warning in lightmap.gltf (+ .bin);
- Babylon.js loads lightmap.gltf through its glTF loader (TEXCOORD_1 as its uv2, the lightmap as
  its lightmapTexture through the loader's extension hook, tests/node/babylon_page.html) and renders
  albedo / pi * E equal to iblbake's own reading of the bake (lightmaps/read.py) to about an 8-bit step;
- the GLSL of every basis (the bake's and every other of the probes' registry) compiles;
- bad input is one line (no `lightmap:` section, an unwritable folder, a file iblbake did not write)."""

import base64
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from iblbake.io import images
from tests.helpers import glsl_compiles, run_cli, write_exr

NODE = Path(__file__).parent / "node"
CUBE = str(Path(__file__).resolve().parents[1] / "examples/corpus/meshes/cube.obj")
W, H = 64, 48
SCENE = f"""camera:
  perspective: {{position: [0, 1.5, 3], look_at: [0, 0.3, 0], fov_y: 50}}
  resolution: [{W}, {H}]
environment: {{path: sky.exr, background: hide}}
materials:
  floor: {{base_color: [0.7, 0.6, 0.5], roughness: 1, specular: 0}}
  box: {{base_color: [0.3, 0.5, 0.7], roughness: 1, specular: 0}}
objects:
  - plane: {{point: [0, 0, 0], size: 3}}
    material: floor
  - mesh: {{path: {CUBE}}}
    material: box
    name: box
"""


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    """The scene under a blue sky, its lightmap (4 texels a unit, 64 rays a texel) baked and written
    as `iblbake lightmap` does (iblbake.bake_lightmap, Lightmap.write)."""
    import iblbake
    tmp = tmp_path_factory.mktemp("lightmap-export")
    write_exr(tmp / "sky.exr", np.ones((32, 64, 3)) * [0.6, 0.8, 1.0])
    (tmp / "scene.yaml").write_text(SCENE + "lightmap: {texels_per_unit: 4, samples: 64}\n")
    lm = iblbake.bake_lightmap(str(tmp / "scene.yaml"), cache=str(tmp / "cache"))
    man = lm.write(tmp / "out")
    return {"tmp": tmp, "out": tmp / "out", "files": lm.files(), "manifest": man, "lm": lm}


def test_atlases_read_back_equal_the_bake_to_fp16(baked):
    """Each basis' coefficient sets, read back from the EXR, equal the bake cast to half (the
    files' precision: |error| <= 2^-11 relative), A the texels baked or dilated; the manifest names
    every file written and its reading of each basis gives the bake's irradiance back."""
    from iblbake.core import sh
    out, lm = baked["out"], baked["lm"]
    man = json.loads((out / "lightmap.json").read_text())
    assert man["atlas"]["width"] == lm.width and man["atlas"]["texels_per_unit"] == 4
    assert sorted(man["bases"]) == sorted(lm.atlases) == ["irradiance", "sh_l1"]
    written = sorted(p.name for p in out.iterdir())
    assert written == sorted(baked["files"]) and man == baked["manifest"]
    for name, b in man["bases"].items():
        sets = np.asarray(lm.atlases[name]).reshape(lm.height, lm.width, -1, 3)
        assert len(b["exr"]) == b["floats"] == sets.shape[2] and all(f in written for f in b["exr"] + b["ktx2"])
        for k, f in enumerate(b["exr"]):
            got = images.read_exr(out / f)
            assert got.shape == (lm.height, lm.width, 4)
            want = sets[..., k, :].astype(np.float16).astype(np.float32)
            assert np.array_equal(got[..., :3], want), (f, np.abs(got[..., :3] - want).max())
            assert np.array_equal(got[..., 3], lm.valid.astype(np.float32))
    # sh_l1 read as the manifest says (E = sum Ahat_l c_k Y_k(n)) at each texel's normal: its irradiance
    from iblbake.render import lightmaps
    tx = lightmaps.texels(lm.baked["layout"])                 # as the bake took them: a chart a lit side
    c = np.stack([images.read_exr(out / f)[..., :3] for f in man["bases"]["sh_l1"]["exr"]], 2).reshape(-1, 4, 3)
    e_sh = np.maximum(0, np.einsum("kj,kjc->kc", sh.sh_basis(tx.normal, 2), c[tx.index] * sh.ahat(2)[:, None]))
    e = images.read_exr(out / man["bases"]["irradiance"]["exr"][0])[..., :3].reshape(-1, 3)[tx.index]
    ok = lm.valid.reshape(-1)[tx.index]
    rel = np.abs(e_sh - e)[ok] / e[ok].max()
    print(f"sh_l1 read at the texels' normals against the irradiance: {rel.max():.2e} of the brightest")
    assert rel.max() < 2e-3                                   # the two halves' rounding (measured 5e-4)


@pytest.fixture(scope="module")
def node():
    if shutil.which("node") is None or not (NODE / "node_modules" / "gltf-validator").is_dir():
        pytest.skip("the Node readers are not set up: run `make readers` (make test does)")

    def run(script, *args):
        p = subprocess.run(["node", str(NODE / script), *map(str, args)], capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr
        return json.loads(p.stdout)
    return run


@pytest.mark.external
def test_ktx2_atlases_read_by_ktx_parse_and_libktx(baked, node):
    """ktx-parse gives every KTX2 atlas back as R16G16B16A16_SFLOAT, one level, one face, bit for
    bit the EXR's halves; libktx opens each without a message."""
    out = baked["out"]
    ktx = sorted(out.glob("*.ktx2"))
    assert len(ktx) == 5
    parsed = node("read_ktx2.mjs", *ktx)
    info = node("libktx_info.cjs", *ktx)
    for f in ktx:
        got = parsed[str(f)]
        assert "error" not in got, got
        assert (got["vkFormat"], got["pixelWidth"], got["pixelHeight"], got["faceCount"], got["pixelDepth"]) == \
            (97, baked["lm"].width, baked["lm"].height, 1, 0)
        assert got["keyValue"]["KTXorientation"] == "rd" and len(got["levels"]) == 1
        data = np.frombuffer(base64.b64decode(got["levels"][0]["data"]), "<f2").reshape(baked["lm"].height, -1, 4)
        assert np.array_equal(data.astype(np.float32), images.read_exr(f.with_suffix(".exr")))
        assert info[str(f)]["messages"] == [] and info[str(f)]["vkFormat"] == 97


@pytest.mark.external
def test_gltf_is_valid(baked, node):
    """glTF-Validator: no error, no warning; what it cannot check is the extension (and so the
    lightmap image it alone uses) and TEXCOORD_0/1 no core texture reads."""
    gl = baked["out"] / "lightmap.gltf"
    r = node("validate_gltf.mjs", gl)[str(gl)]
    assert "error" not in r, r
    assert r["numErrors"] == 0 and r["numWarnings"] == 0, r["messages"]
    assert {m["code"] for m in r["messages"]} <= {"UNSUPPORTED_EXTENSION", "UNUSED_OBJECT", "IMAGE_NPOT_DIMENSIONS"}
    doc = json.loads(gl.read_text())
    assert doc["extensionsUsed"] == ["IBLBAKE_lightmap", "KHR_materials_specular"] and "extensionsRequired" not in doc
    assert all(m["extensions"]["KHR_materials_specular"]["specularFactor"] == 0 for m in doc["materials"])
    assert all("TEXCOORD_1" in p["attributes"] for m in doc["meshes"] for p in m["primitives"])
    assert [m["name"] for m in doc["meshes"]] == ["objects.0", "box"]


@pytest.mark.external
def test_babylon_renders_the_lightmap_as_iblbake_reads_it(baked, node):
    """Babylon.js (its glTF loader, WebGL2 on SwiftShader) renders the lightmapped scene from the
    glTF's camera: albedo / pi * E with E from lightmap.png on TEXCOORD_1, equal to iblbake's reading
    of the bake at the same camera (lightmaps/read.py diffuse_frame), gamma 2.2, inside the objects
    (their silhouettes left out): measured 0.0045 RMS (an 8-bit step is 0.0039). Without the
    lightmap's scale (irradianceScale 1) the floor reads 3x too dark, so the test sees the lightmap."""
    if not Path("/usr/bin/chromium").exists() or not (NODE / "node_modules" / "babylonjs").is_dir():
        pytest.skip("Babylon.js and Chromium are not set up: run `make readers` (make test does)")
    from scipy import ndimage

    from iblbake.render.bakes import Bakes
    from iblbake.render.lightmaps import read

    def render(path):
        out = node("babylon_render.cjs", path, W, H, json.dumps({"iblbakeLightmap": True}))
        px = np.frombuffer(base64.b64decode(out["pixels"]), np.uint8).reshape(H, W, 4)[::-1]
        return px[..., :3] / 255.0, out

    got, info = render(baked["out"] / "lightmap.gltf")
    assert len(info["lightmaps"]) == 2 and all(m["uv"] == 1 and m["uv2"] for m in info["lightmaps"]), info["lightmaps"]
    lm = baked["lm"]
    hdr = read.diffuse_frame(lm.scene, Bakes(baked["tmp"] / "cache").geometry(lm.scene), lm.baked, (H, W), "irradiance")
    want = np.clip(hdr[..., :3], 0, 1) ** (1 / 2.2)
    covered = hdr[..., 3] > 0
    differ = float((covered != (got.sum(-1) > 0)).mean())
    print(f"silhouettes differ on {differ:.2%} of the pixels")
    assert differ < 0.01                # the same camera: edge pixels alone (a rasteriser against a centred ray)
    inner = ndimage.binary_erosion(covered)
    rms = float(np.sqrt(((got - want)[inner] ** 2).mean()))
    print(f"Babylon against iblbake: {rms:.4f} RMS over {inner.sum()} pixels ({info['version']})")
    assert rms < 0.01, rms
    doc = json.loads((baked["out"] / "lightmap.gltf").read_text())
    for m in doc["materials"]:
        m["extensions"]["IBLBAKE_lightmap"]["irradianceScale"] = 1.0
    unscaled = baked["out"].parent / "unscaled" / "lightmap.gltf"
    shutil.copytree(baked["out"], unscaled.parent)
    unscaled.write_text(json.dumps(doc))
    off, _ = render(unscaled)
    assert float(np.sqrt(((off - want)[inner] ** 2).mean())) > 10 * rms


@pytest.mark.external
@pytest.mark.parametrize("name", ["irradiance", "sh_l1", "sh", "zh3", "sg", "ambient_dice"])
def test_glsl_of_every_basis_compiles(name, tmp_path):
    """lightmapIrradiance of the bake's bases and of every basis the probes' registry holds (those a
    bake may add): glslangValidator compiles it in a fragment shader."""
    from types import SimpleNamespace

    from iblbake.render.lightmaps import export
    b = export.basis(name, {})
    src = export.glsl({"layout": SimpleNamespace(width=8, height=4)}, b)
    assert src.count("uniform sampler2D lightmapCoefficient") == b.floats
    glsl_compiles(tmp_path / "lightmap.frag", src + "in vec2 UV;\nin vec3 N;\nout vec4 color;\n"
                  "void main() { color = vec4(lightmapIrradiance(UV, normalize(N)), 1.0); }\n")


@pytest.mark.slow
def test_command_and_its_bad_input(baked, tmp_path):
    """No `lightmap:` section: a usage error (2) naming it; an output folder under a file, or one
    holding a file of the names iblbake did not write: one line (1), nothing written; iblbake's own
    files are replaced without --force, the bake from the cache (--json)."""
    tmp = baked["tmp"]
    (tmp / "bare.yaml").write_text(SCENE)
    p = run_cli("lightmap", tmp / "bare.yaml", "-o", tmp_path / "x")
    assert p.returncode == 2 and "no `lightmap:` section" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    p = run_cli("lightmap", tmp / "scene.yaml", "-o", blocker / "out", "--cache", tmp / "cache")
    assert p.returncode == 1 and str(blocker) in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert "Traceback" not in p.stderr
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "lightmap.gltf").write_text('{"asset": {"version": "2.0", "generator": "Blender"}}')
    p = run_cli("lightmap", tmp / "scene.yaml", "-o", mine, "--cache", tmp / "cache")
    assert p.returncode == 1 and "--force" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert sorted(x.name for x in mine.iterdir()) == ["lightmap.gltf"]
    images.write_exr(baked["out"] / "lightmap_sg_0.exr", np.zeros((2, 2, 3)))     # an earlier bake's other basis
    (baked["out"] / "lightmap_notes.glsl").write_text("// my notes\n")
    p = run_cli("lightmap", tmp / "scene.yaml", "-o", baked["out"], "--cache", tmp / "cache", "--json")
    assert p.returncode == 0, p.stderr                        # its own files (the .bin too): replaced
    summary = json.loads(p.stdout)
    assert summary["removed"] == ["lightmap_sg_0.exr"] and (baked["out"] / "lightmap_notes.glsl").exists()
    (baked["out"] / "lightmap_notes.glsl").unlink()
    assert summary["cached"] and summary["files"] == baked["files"] and summary["bases"] == ["irradiance", "sh_l1"]
    assert (summary["width"], summary["height"]) == (baked["lm"].width, baked["lm"].height)


def test_a_basis_the_bake_adds_is_exported_with_no_code_here(baked, tmp_path):
    """A bake holding another basis of the probes' registry (SG, 9 lobes: lightmap.basis sg) is
    written with its 9 coefficient sets, its registry layout and options in lightmap.json and its
    GLSL, nothing in the exporter naming it; the bases written are the bake's irradiance and its
    basis (held() reads the bake's 'basis', not a list of its own)."""
    from iblbake.core.bases.probes import PROBE_BASES
    lm = baked["lm"]
    rng = np.random.default_rng(1)
    sg = rng.uniform(0, 2, (lm.height, lm.width, 9, 3))
    saved = lm.baked["basis"]
    lm.baked["sg"], lm.baked["basis"] = sg, "sg"
    try:
        man = lm.write(tmp_path)
    finally:
        del lm.baked["sg"]
        lm.baked["basis"] = saved
    assert list(man["bases"]) == ["irradiance", "sg"]
    b = man["bases"]["sg"]
    assert b["floats"] == 9 and b["options"] == PROBE_BASES["sg"].options({}) and b["title"] == "SG", b
    assert b["exr"] == [f"lightmap_sg_{k}.exr" for k in range(9)] and "lobe" in b["layout"]
    for k, f in enumerate(b["exr"]):
        got = images.read_exr(tmp_path / f)[..., :3]
        assert np.array_equal(got, sg[..., k, :].astype(np.float16).astype(np.float32))
    assert "lightmapCoefficient8" in (tmp_path / "lightmap_sg.glsl").read_text()


@pytest.mark.parametrize("name", ["sh_l1", "sh"])
def test_sh_glsl_is_the_float64_reading(name):
    """lightmapIrradiance's SH body, evaluated term by term as GLSL would (numpy for vec3), equals
    the float64 reading of the same coefficients at 200 random normals: sh_l1 as the bake reads it
    (bake.sh_irradiance), the probes' L2 SH irradiance as the registry does."""
    from iblbake.core.bases.probes import PROBE_BASES
    from iblbake.render.lightmaps import export, sh_irradiance
    rng = np.random.default_rng(4)
    b = export.basis(name, {})
    c = rng.normal(size=(200, b.floats, 3))
    c[:, 0] += 2.0                                  # mostly positive light: the clamp at 0 seldom acts
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)

    class Vec:
        x, y, z = n[:, 0:1], n[:, 1:2], n[:, 2:3]
    expr = b.body.strip().removeprefix("return ").removesuffix(";")
    got = eval(expr, {"c": [c[:, k] for k in range(b.floats)], "n": Vec, "max": np.maximum, "vec3": float})
    want = sh_irradiance(c, n) if name == "sh_l1" else \
        np.maximum(0, PROBE_BASES["sh"].irradiance_at(c, np.arange(200), n, {}))
    assert np.abs(got - want).max() < 1e-12 * np.abs(want).max()


def test_write_takes_a_folder_path(baked):
    """Lightmap.write(5) is an InputError naming its argument, not a TypeError from pathlib."""
    import iblbake
    with pytest.raises(iblbake.InputError, match="folder: give the output folder's path"):
        baked["lm"].write(5)


def manifest_irradiance(b: dict, conventions: dict, c, n):
    """E (k, 3) at unit normals n (k, 3) from coefficient sets c (k, floats, 3), with lightmap.json's
    fields of the basis alone (an engine's reading, not iblbake's code)."""
    from numpy.polynomial import legendre

    class N:
        x, y, z = n[:, 0], n[:, 1], n[:, 2]
    terms = conventions["sh_basis"].split(": ", 1)[1].split("; ")
    y = np.stack([eval(t, {"n": N}) * np.ones(len(n)) for t in terms], 1)
    if "irradiance_legendre" in b:                             # SG, ambient dice: lobes about the axes
        p = legendre.legval(np.clip(n @ np.array(b["axes"]).T, -1, 1), np.array(b["irradiance_legendre"]))
        return np.maximum(0, np.einsum("kj,kjc->kc", p, c))
    if "zonal" in b:                                           # ZH3: L1 and a zonal term about the luminance axis
        ahat = np.array(b["ahat"])
        a = np.einsum("kxc,c->kx", c[:, [3, 1, 2]], b["luminance"])
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        zonal = b["zonal"] * (3 * np.einsum("kx,kx->k", a, n) ** 2 - 1)
        e = np.einsum("kj,kjc->kc", y[:, :4] * ahat[:4], c[:, :4]) + (ahat[4] * zonal)[:, None] * c[:, 4]
        return np.maximum(0, e)
    return np.maximum(0, np.einsum("kj,kjc->kc", y[:, :b["floats"]] * b["ahat"], c))


@pytest.mark.parametrize("name", ["sh_l1", "sh", "zh3", "sg", "ambient_dice"])
def test_manifest_alone_evaluates_each_basis(name, baked, tmp_path):
    """Each basis' atlases written (a bake holding it: random coefficients, mostly positive light),
    read back from their EXR and evaluated at 300 random normals with lightmap.json's fields alone
    (SG's axes, sharpness and Legendre profile, the ambient dice's axes and profile, ZH3's factors
    and luminance axis, SH's basis and Ahat) equal the library's reading of the same halves
    (render/lightmaps/bases.py irradiance; measured <= 5.3e-16 of the largest: float64 rounding); the
    units say fp16, the atlases' precision."""
    from iblbake.render.lightmaps import bases
    lm = baked["lm"]
    rng = np.random.default_rng(7)
    floats = bases.floats(name, bases.options(name, {}))
    coeffs = rng.normal(0.2, 0.5, (lm.height, lm.width, floats, 3))
    coeffs[..., 0, :] += 2.0
    saved = {k: lm.baked.get(k) for k in (name, "basis")}
    lm.baked[name], lm.baked["basis"] = coeffs, name       # a bake of lightmap.basis NAME
    try:
        lm.write(tmp_path)
    finally:
        for k, v in saved.items():
            lm.baked[k] = v
        if saved[name] is None:
            del lm.baked[name]
    man = json.loads((tmp_path / "lightmap.json").read_text())
    b = man["bases"][name]
    assert "fp16" in b["units"] and "float32" not in b["units"]
    pick = rng.integers(0, lm.height * lm.width, 300)
    c = np.stack([images.read_exr(tmp_path / f)[..., :3].reshape(-1, 3)[pick] for f in b["exr"]], 1).astype(np.float64)
    n = rng.normal(size=(300, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    got = manifest_irradiance(b, man["conventions"], c, n)
    want = bases.irradiance(name, c, n, bases.options(name, {}))
    print(name, np.abs(got - want).max() / np.abs(want).max())
    assert np.abs(got - want).max() < 1e-14 * np.abs(want).max()


def test_manifest_names_each_object_and_its_gltf_node(baked):
    """lightmap.json's objects: each lightmapped object's scene index, its name (the scene's `name`,
    else objects.N) and the index of its node in lightmap.gltf, which carries that name and mesh."""
    out = baked["out"]
    man = json.loads((out / "lightmap.json").read_text())
    doc = json.loads((out / "lightmap.gltf").read_text())
    assert man["objects"] == [{"index": 0, "name": "objects.0", "gltf_node": 0},
                              {"index": 1, "name": "box", "gltf_node": 1}]
    for o in man["objects"]:
        node = doc["nodes"][o["gltf_node"]]
        assert node["name"] == o["name"] == doc["meshes"][node["mesh"]]["name"]


def test_manifest_lists_the_lights_an_engine_draws(baked, tmp_path):
    """lightmap.json's `lights`: the atlas holds no analytic light's direct light (the frame's lights
    pass draws it), so the manifest lists them as probes.json does, with the convention that says
    so; none in a scene without lights."""
    import iblbake
    assert baked["manifest"]["lights"] == [] and "twice" in baked["manifest"]["conventions"]["lights"]
    write_exr(tmp_path / "sky.exr", np.ones((32, 64, 3)) * [0.6, 0.8, 1.0])
    (tmp_path / "lamp.yaml").write_text(SCENE + "lights:\n  - point: {position: [0, 2, 0], intensity: 5}\n"
                                        "lightmap: {texels_per_unit: 2, samples: 16}\n")
    man = iblbake.bake_lightmap(str(tmp_path / "lamp.yaml"), cache=str(tmp_path / "cache")).write(tmp_path / "out")
    assert [lt["source"] for lt in man["lights"]] == ["lights.0"] and "point" in man["lights"][0]



def test_the_panoramas_sun_is_listed_and_said(tmp_path):
    """`environment.sun: auto` extracts the panorama's sun where a lightmap is baked (stop 75): the
    atlas holds the rest, lightmap.json lists the sun for the engine to draw per pixel, and
    `iblbake lightmap` says so; `sun: none` keeps it in the atlas, nothing listed or said. The
    panorama the atlas saw is written beside it (lightmap_environment.exr: what an engine prefilters
    for the specular; trial75's lightmap.json named no residual) and its diffuse reading states the
    frame's weight, (1 - F) (1 - metallic)."""
    sky = np.ones((32, 64, 3)) * [0.6, 0.8, 1.0]
    sky[8, 20] = 1e6                                      # a sun 1e6 x the median, 40 degrees up
    write_exr(tmp_path / "sky.exr", sky)
    (tmp_path / "scene.yaml").write_text(SCENE + "lightmap: {texels_per_unit: 2, samples: 16}\n")
    said = {}
    for sun in ("auto", "none"):
        p = run_cli("lightmap", tmp_path / "scene.yaml", "-o", tmp_path / sun, "--cache", tmp_path / "cache",
                    "--set", f"environment.sun={sun}")
        assert p.returncode == 0, p.stderr
        man = json.loads((tmp_path / sun / "lightmap.json").read_text())
        said[sun] = ([lt["source"] for lt in man["lights"]], p.stdout.strip().splitlines()[-1])
    assert said["auto"][0] == ["environment.sun: extract (1 of 1, brightest first)"], said
    assert said["auto"][1].endswith("; 1 light extracted from the panorama, to draw per pixel: lightmap.json's "
                                    "lights (environment.sun: none keeps it in the atlases)"), said
    assert said["none"][0] == [] and "extracted" not in said["none"][1], said
    assert "x 16 paths and 16 shadow rays to the panorama = " in p.stderr, p.stderr     # the sun left in: not uniform
    env = {sun: json.loads((tmp_path / sun / "lightmap.json").read_text()).get("environment") for sun in said}
    assert env == {"auto": {"file": "lightmap_environment.exr", "rotation_y": 0.0, "intensity": 1.0}, "none": None}
    residual = images.read_exr(tmp_path / "auto" / "lightmap_environment.exr")
    assert residual.shape == (32, 64, 3) and residual.max() < 2, residual.max()        # the sun's texel filled
    assert np.allclose(residual[16:], sky[16:], rtol=2 ** -10, atol=0)                 # the sky below as it was
    assert not (tmp_path / "none" / "lightmap_environment.exr").exists()
    man = json.loads((tmp_path / "auto" / "lightmap.json").read_text())
    assert "(1 - F_r(n.v)) (1 - metallic) base_color / pi" in man["conventions"]["diffuse"]


def test_gltf_keeps_file_materials_specular_and_no_absolute_path(tmp_path):
    """lightmap.gltf's materials: a glTF mesh without a scene material keeps its file's own
    (examples/meshes/tiles.glb's "glazed tiles", not "file materials"); a scene material's
    `specular: 0` is KHR_materials_specular's specularFactor 0 (declared used), a tinted one its
    factor and colour, the default none; extras.source is the scene's file name, no absolute path."""
    from iblbake.render.lightmaps import gltf_scene
    from iblbake.render.lightmaps.uv import Layout
    from tests.helpers import load_scene
    tiles = Path(__file__).resolve().parents[1] / "examples" / "meshes" / "tiles.glb"
    write_exr(tmp_path / "sky.exr", np.ones((8, 16, 3)))
    sc = load_scene(tmp_path, "scene", {
        "camera": {"perspective": {"position": [0, 1.5, 3], "look_at": [0, 0, 0], "fov_y": 50}, "resolution": [8, 8]},
        "environment": {"path": "sky.exr"},
        "materials": {"matte": {"specular": 0}, "tinted": {"specular": 0.5, "specular_color": [1, 0.5, 0.25]},
                      "plain": {}},
        "objects": [{"plane": {"point": [0, 0, 0], "size": 2}, "material": "matte"},
                    {"mesh": {"path": str(tiles)}, "name": "tiles"},
                    {"sphere": {"center": [0, 1, 0], "radius": 0.5}, "material": "tinted"},
                    {"sphere": {"center": [1, 1, 0], "radius": 0.5}, "material": "plain"}]})
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1]], float)
    lay = Layout(8, 8, np.stack([tri] * 4), np.tile([0, 1, 0.0], (4, 3, 1)), np.arange(4),
                 np.tile([[1, 1], [6, 1], [1, 6.0]], (4, 1, 1)), np.zeros((4, 4)), {})
    doc, _data = gltf_scene.document({"layout": lay}, sc, "lightmap", "IBLBAKE_lightmap", 1.0)
    mats = doc["materials"]
    assert [m["name"] for m in mats] == ["matte", "glazed tiles", "tinted", "plain"]
    spec = [m["extensions"].get("KHR_materials_specular") for m in mats]
    assert spec == [{"specularFactor": 0.0, "specularColorFactor": [1.0, 1.0, 1.0]}, None,
                    {"specularFactor": 0.5, "specularColorFactor": [1.0, 0.5, 0.25]}, None]
    assert doc["extensionsUsed"] == ["IBLBAKE_lightmap", "KHR_materials_specular"]
    assert doc["extras"]["source"] == "scene.yaml" and str(tmp_path) not in json.dumps(doc)


def _two_material_gltf(path):
    """A .gltf of two quads side by side (x in [0, 1] and [1, 2], y = 0, facing up), one primitive
    each, materials "red" and "blue"."""
    quads = []
    for x0 in (0.0, 1.0):
        v = np.array([[x0, 0, 0], [x0, 0, 1], [x0 + 1, 0, 1], [x0 + 1, 0, 0]], np.float32)
        quads.append((v, np.array([0, 1, 2, 0, 2, 3], np.uint16)))
    blob, views, accessors, prims = b"", [], [], []
    for k, (v, f) in enumerate(quads):
        for arr, target, acc in ((v, 34962, {"componentType": 5126, "type": "VEC3", "min": v.min(0).tolist(),
                                             "max": v.max(0).tolist()}),
                                 (f, 34963, {"componentType": 5123, "type": "SCALAR"})):
            views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": arr.nbytes, "target": target})
            accessors.append({"bufferView": len(views) - 1, "count": len(arr), **acc})
            blob += arr.tobytes() + b"\0" * (-arr.nbytes % 4)
        prims.append({"attributes": {"POSITION": len(accessors) - 2}, "indices": len(accessors) - 1, "material": k})
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": prims}], "accessors": accessors, "bufferViews": views,
           "buffers": [{"byteLength": len(blob),
                        "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}],
           "materials": [{"name": "red", "pbrMetallicRoughness": {"baseColorFactor": [1, 0, 0, 1]}},
                         {"name": "blue", "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 1, 1]}}]}
    path.write_text(json.dumps(doc))
    return str(path)


def test_gltf_keeps_each_primitive_material(tmp_path):
    """A glTF mesh of two materials (no scene material) is exported with a primitive per material,
    each holding the triangles of its own (the red quad's at x < 1, the blue's at x > 1), where the
    export had one primitive under a default material named "red, blue"."""
    from iblbake.render import lightmaps
    from iblbake.render.lightmaps import gltf_scene
    from iblbake.render.lightmaps.bake import triangles
    from tests.helpers import load_scene
    write_exr(tmp_path / "sky.exr", np.ones((8, 16, 3)))
    sc = load_scene(tmp_path, "scene", {
        "camera": {"perspective": {"position": [1, 1.5, 3], "look_at": [1, 0, 0], "fov_y": 50}, "resolution": [8, 8]},
        "environment": {"path": "sky.exr"},
        "objects": [{"mesh": {"path": _two_material_gltf(tmp_path / "two.gltf")}, "name": "two"}]})
    lay = lightmaps.layout(sc, triangles(sc), 4.0, 1 << 20)
    doc, data = gltf_scene.document({"layout": lay}, sc, "lightmap", "IBLBAKE_lightmap", 1.0)
    prims = doc["meshes"][0]["primitives"]
    names = [doc["materials"][p["material"]]["name"] for p in prims]
    print(names, [doc["materials"][p["material"]]["pbrMetallicRoughness"]["baseColorFactor"] for p in prims])
    assert sorted(names) == ["blue", "red"]
    for p, name in zip(prims, names):
        acc = doc["accessors"][p["attributes"]["POSITION"]]
        x = (acc["min"][0] + acc["max"][0]) / 2
        assert (x < 1) == (name == "red") and acc["max"][0] - acc["min"][0] <= 1 + 1e-6, (name, acc)
        assert doc["materials"][p["material"]]["pbrMetallicRoughness"]["baseColorFactor"][:3] == \
            ([1.0, 0.0, 0.0] if name == "red" else [0.0, 0.0, 1.0])
