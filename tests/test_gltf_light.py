"""glTF image-based lights (`iblbake export-gltf`) read by real readers:
- Khronos' glTF-Validator finds no error and no warning in a .gltf (PNGs beside it) or a .glb,
  and reads every face image at the size the light declares;
- Babylon.js, the extension's reference loader, renders the light in headless Chromium (WebGL2
  on SwiftShader: tests/node/babylon_render.cjs): a mirror, a rough metal and a white diffuse
  sphere under it equal iblbake's own render of the same scene (its panorama, its camera) to a
  few 8-bit steps, which they do only with the faces in the orientation export-gltf writes (the
  x mirror of Babylon's left-handed world, each face turned 180 degrees: the other orientations,
  measured, are 18-60x further off), the mips at the roughness Babylon reads them for, and
  the SH signs of tests/test_sh_formats.py.
Also RGBD's round trip (Babylon's toRGBD / fromRGBD) and the command's one-line errors."""

import json
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from iblbake.bake import gltf_light
from iblbake.core import conventions
from iblbake.io import gltf, images

from tests.helpers import run_cli, write_exr

NODE = Path(__file__).parent / "node"
CHROMIUM = "/usr/bin/chromium"


def test_rgbd_round_trip():
    """Babylon's RGBD keeps each texel's largest channel to a fraction of a percent from 1 to 255,
    dimmer texels to an 8-bit gamma step, and clips above 255."""
    rng = np.random.default_rng(3)
    n = 20000
    m = np.exp(rng.uniform(0, math.log(255), n))                          # largest channel 1 .. 255
    c = m[:, None] * np.concatenate([np.ones((n, 1)), rng.uniform(0, 1, (n, 2))], axis=1)
    back = gltf.rgbd_decode(gltf.rgbd_encode(c))
    err = np.abs(back[:, 0] - c[:, 0]) / c[:, 0]
    assert err.max() < 6.5e-3, err.max()                                  # measured 5.8e-3
    dim = rng.uniform(0.01, 1.0, (5000, 3))                               # D = 1: plain 8-bit gamma
    top = dim.max(axis=1)
    half_step = gltf.GAMMA * 0.5 / 255 / top ** (1 / gltf.GAMMA)          # d(x^2.2)/x at half a step
    back = gltf.rgbd_decode(gltf.rgbd_encode(dim)).max(axis=1)
    assert np.all(np.abs(back - top) / top <= 1.05 * half_step)
    sun = gltf.rgbd_decode(gltf.rgbd_encode([[1e4, 10.0, 0.0]]))[0]       # clips at 255, keeps the rest
    assert sun[0] == 255.0 and abs(sun[1] - 10.0) < 0.25 and sun[2] == 0.0
    assert np.array_equal(gltf.rgbd_encode([[0.0, -1.0, np.nan]]), [[0, 0, 0, 255]])


# --- a scene both renderers draw ----------------------------------------------------------------

W, H = 720, 240
CAMERA_Z, YFOV = 8.0, 0.6                       # radians, as glTF's camera
SIZE, MIPS = 128, 4                             # export-gltf --size 128 --min-size 16
# Babylon's PBR shader reads mip log2(SIZE alphaG) (MIPS - 1) / log2(SIZE) for alphaG = r^2 +
# MINIMUMVARIANCE (0.0005): the rough sphere's r is where that is exactly mip 2, so the render
# shows that one mip, not a blend of two
R_MIP2 = math.sqrt(SIZE ** (2 / (MIPS - 1) - 1) - 0.0005)
SPHERES = [((-2.2, 0.0, 0.0), (1.0, 1.0, 1.0), 1.0, 0.0),     # centre, base colour, metallic, roughness
           ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 1.0, R_MIP2),
           ((2.2, 0.0, 0.0), (1.0, 1.0, 1.0), 0.0, 1.0)]
SPOTS = [((0.45, 0.55, 0.70), (9.0, 7.0, 4.0)), ((-0.75, 0.15, 0.64), (3.0, 6.0, 9.0)),
         ((0.25, -0.45, 0.86), (8.0, 3.0, 3.0))]


def sky(d):
    """A smooth sky that differs in every axis and sign (mirrors, flips and turns all show) with
    three bright 8-degree disks (what a roughness mismatch blurs differently)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    c = 0.3 * np.stack([1.3 + 0.8 * x + 0.3 * x * y, 1.3 + 0.8 * y + 0.3 * y * z,
                        1.3 + 0.8 * z + 0.3 * x * z + 0.2 * (x * x - y * y)], axis=-1)
    for centre, colour in SPOTS:
        a = np.asarray(centre) / np.linalg.norm(centre)
        c = c + np.asarray(colour) * ((d @ a) > math.cos(math.radians(4.0)))[..., None]
    return c


@pytest.fixture(scope="module")
def lit(tmp_path_factory):
    """The sky as a panorama, iblbake's render of the spheres under it, and a function writing the
    same scene as glTF around an exported light."""
    tmp = tmp_path_factory.mktemp("gltf-light")
    env = write_exr(tmp / "sky.exr", sky(conventions.equirect_texel_dirs(1024, 512)))
    mats = "\n".join(f"  m{i}: {{base_color: {list(c)}, metallic: {m}, roughness: {r}}}"
                     for i, (_, c, m, r) in enumerate(SPHERES))
    objs = "\n".join(f"  - sphere: {{center: {list(p)}, radius: 1}}\n    material: m{i}" for i, (p, *_) in enumerate(SPHERES))
    (tmp / "scene.yaml").write_text(f"""camera:
  perspective: {{position: [0, 0, {CAMERA_Z}], look_at: [0, 0, 0], fov_y: {math.degrees(YFOV)}}}
  resolution: [{W}, {H}]
environment: {{path: sky.exr, background: hide}}
materials:
{mats}
objects:
{objs}
effects:
  diffuse: sh
  specular: prefiltered
  prefilter: {{dominant_direction: false}}
  tonemap: linear
  output_transfer: gamma
  gamma: 2.2
""")
    p = run_cli("render", tmp / "scene.yaml", "-o", tmp / "iblbake.png", "-q", "--cache", tmp / "cache")
    assert p.returncode == 0, p.stderr
    import OpenImageIO as oiio
    ref = oiio.ImageInput.open(str(tmp / "iblbake.png")).read_image("float")[..., :3]
    return {"tmp": tmp, "env": env, "ref": ref}


def sphere_scene(light: Path, out: Path):
    """A copy of the exported light's document with the three spheres (an icosphere of radius 1)
    and the camera added."""
    import base64

    import trimesh
    doc = json.loads(light.read_text())
    ico = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    pos, nrm = ico.vertices.astype(np.float32), ico.vertex_normals.astype(np.float32)
    idx = ico.faces.astype(np.uint32).ravel()
    blob = pos.tobytes() + nrm.tobytes() + idx.tobytes()
    doc["buffers"] = [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                       + base64.b64encode(blob).decode()}]
    doc["bufferViews"] = [{"buffer": 0, "byteOffset": 0, "byteLength": pos.nbytes, "target": 34962},
                          {"buffer": 0, "byteOffset": pos.nbytes, "byteLength": nrm.nbytes, "target": 34962},
                          {"buffer": 0, "byteOffset": pos.nbytes + nrm.nbytes, "byteLength": idx.nbytes,
                           "target": 34963}]
    doc["accessors"] = [{"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3",
                         "min": pos.min(0).tolist(), "max": pos.max(0).tolist()},
                        {"bufferView": 1, "componentType": 5126, "count": len(nrm), "type": "VEC3"},
                        {"bufferView": 2, "componentType": 5125, "count": len(idx), "type": "SCALAR"}]
    doc["materials"] = [{"pbrMetallicRoughness": {"baseColorFactor": list(c) + [1.0], "metallicFactor": m,
                                                  "roughnessFactor": r}} for _, c, m, r in SPHERES]
    doc["meshes"] = [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2, "material": i}]}
                     for i in range(len(SPHERES))]
    doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": YFOV, "aspectRatio": W / H, "znear": 0.1,
                                                              "zfar": 100.0}}]
    doc["nodes"] = [{"mesh": i, "translation": list(p)} for i, (p, *_) in enumerate(SPHERES)]
    doc["nodes"].append({"camera": 0, "translation": [0.0, 0.0, CAMERA_Z]})
    doc["scenes"][0]["nodes"] = list(range(len(doc["nodes"])))
    out.write_text(json.dumps(doc))
    return out


@pytest.fixture(scope="module")
def babylon():
    if (shutil.which("node") is None or not (NODE / "node_modules" / "babylonjs").is_dir()
            or not Path(CHROMIUM).exists()):
        pytest.skip("Babylon.js and Chromium are not set up: run `make readers` (make test does)")

    def render(path, **options):
        p = subprocess.run(["node", str(NODE / "babylon_render.cjs"), str(path), str(W), str(H), json.dumps(options)],
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr
        out = json.loads(p.stdout)
        import base64
        px = np.frombuffer(base64.b64decode(out["pixels"]), np.uint8).reshape(H, W, 4)[::-1]
        return px[..., :3].astype(np.float64) / 255.0, out
    return render


def sphere_errors(got, ref):
    """RMS difference (8-bit gamma-encoded values in [0, 1]) inside each sphere's disk, its
    silhouette left out (an icosphere against an analytic sphere)."""
    from scipy import ndimage
    covered = (ref.sum(-1) > 0) & (got.sum(-1) > 0)
    labels, n = ndimage.label(ndimage.binary_erosion(covered, iterations=2))
    assert n == len(SPHERES)
    order = np.argsort([np.nonzero(labels == k)[1].mean() for k in range(1, n + 1)])
    return [float(np.sqrt(((got - ref)[labels == k + 1] ** 2).mean())) for k in order]


def export(lit, name, *extra):
    out = lit["tmp"] / name
    p = run_cli("export-gltf", lit["env"], "-o", out, "--size", SIZE, "--min-size", "16", "-q", "--json",
                "--cache", lit["tmp"] / "cache", *extra)
    assert p.returncode == 0, p.stderr
    return out, json.loads(p.stdout)


@pytest.mark.external
def test_babylon_renders_the_light_as_iblbake_does(lit, babylon):
    """Babylon's render of the exported light equals iblbake's render of the panorama to about one
    8-bit step: measured 0.005 (mirror: an icosphere's interpolated normals against a sphere),
    0.0022 (rough metal, exactly on mip 2) and 0.0004 (diffuse, the SH) RMS. Babylon as loaded,
    but for what iblbake's split sum leaves out (plainSplitSum) and its loader's gamma slip
    (linearEnvironment; docs/manual.md). Mips baked at roughness k/(N-1), as the extension's text puts
    it, make the rough sphere 10x further off (measured 0.0226)."""
    light, summary = export(lit, "light.gltf")
    assert [round(m["alpha"], 6) for m in summary["mips"]] == [0.0] + [round(SIZE ** (k / (MIPS - 1) - 1), 6)
                                                                      for k in range(1, MIPS)]
    got, info = babylon(sphere_scene(light, lit["tmp"] / "scene.gltf"), linearEnvironment=True, plainSplitSum=True)
    mirror, rough, diffuse = sphere_errors(got, lit["ref"])
    assert mirror < 0.01 and rough < 0.005 and diffuse < 0.0012, (mirror, rough, diffuse, info["version"])
    linear, _ = export(lit, "linear.gltf", "--roughness-mapping", "linear")
    got, _ = babylon(sphere_scene(linear, lit["tmp"] / "scene-linear.gltf"), linearEnvironment=True, plainSplitSum=True)
    assert sphere_errors(got, lit["ref"])[1] > 5 * rough


@pytest.fixture(scope="module")
def validator():
    if shutil.which("node") is None or not (NODE / "node_modules" / "gltf-validator").is_dir():
        pytest.skip("the Node readers are not set up: run `make readers` (make test does)")

    def run(*paths):
        p = subprocess.run(["node", str(NODE / "validate_gltf.mjs"), *map(str, paths)], capture_output=True,
                           text=True, timeout=120)
        assert p.returncode == 0, p.stderr
        return json.loads(p.stdout)
    return run


@pytest.mark.external
def test_validator_accepts_gltf_and_glb(lit, validator):
    gl, _ = export(lit, "v.gltf")
    glb, summary = export(lit, "v.glb")
    assert summary["files"] == [str(glb)]
    sides = sorted(x.name for x in lit["tmp"].glob("v_specular_*.png"))
    assert len(sides) == 6 * MIPS and "v_specular_0_px.png" in sides
    reports = validator(gl, glb)
    for path, r in reports.items():
        assert "error" not in r, r
        assert r["numErrors"] == 0 and r["numWarnings"] == 0, r["messages"]
        # what the validator cannot check: the extension itself, and so whether its images are used
        assert {m["code"] for m in r["messages"]} <= {"UNSUPPORTED_EXTENSION", "UNUSED_OBJECT"}, r["messages"]
        pngs = [x for x in r["info"]["resources"] if x.get("mimeType") == "image/png"]
        assert [(x["image"]["width"], x["image"]["height"]) for x in pngs] == \
            [(SIZE >> k, SIZE >> k) for k in range(MIPS) for _ in range(6)]
        assert all(x["image"]["format"] == "rgba" for x in pngs)
    doc = json.loads(gl.read_text())
    light = doc["extensions"]["EXT_lights_image_based"]["lights"][0]
    assert light["specularImageSize"] == SIZE and np.array(light["irradianceCoefficients"]).shape == (9, 3)
    assert doc["extras"]["source_sha256"] == images.file_sha256(lit["env"])


def test_faces_as_babylon_reads_them(lit):
    """The file's face f, row r, column c holds the sky at the direction Babylon samples it for: it
    reads the rows bottom to top, so at Vulkan's direction of face f, row s-1-r, column c in its
    left-handed world, which is that direction with x negated in glTF's; checked on mip 0 (the
    mirror: the sky resampled to the cube)."""
    light, _ = export(lit, "f.gltf")
    from PIL import Image
    got = np.stack([gltf.rgbd_decode(np.asarray(Image.open(lit["tmp"] / f"f_specular_0_{n}.png")))
                    for n in gltf.FACES])
    d = conventions.cube_texel_dirs(SIZE)[:, ::-1, :] * np.array([-1.0, 1.0, 1.0])
    want = sky(d / np.linalg.norm(d, axis=-1, keepdims=True))
    inside = np.ones(want.shape[:-1], bool)
    for centre, _ in SPOTS:                          # a disk's edge falls between texels: leave it out
        a = np.asarray(centre) / np.linalg.norm(centre)
        cosang = (d / np.linalg.norm(d, axis=-1, keepdims=True)) @ a
        inside &= np.abs(np.degrees(np.arccos(np.clip(cosang, -1, 1))) - 4.0) > 1.5
    err = np.abs(got - want)[inside] / want[inside]
    assert err.max() < 0.02, err.max()     # measured 0.011: RGBD's 8-bit step and the resampled panorama


@pytest.mark.slow
def test_bad_input_is_one_line(lit, tmp_path):
    cases = [(["-o", tmp_path / "x.png"], ".gltf or .glb"), (["-o", tmp_path / "x.gltf", "--size", "100"],
             "not a power of two"), (["-o", tmp_path / "x.gltf", "--size", "32", "--min-size", "64"], "larger than"),
             (["-o", tmp_path / "x.gltf", "--rgbd-scale", "-2"], "finite number > 0")]
    for args, words in cases:
        p = run_cli("export-gltf", lit["env"], *args)
        assert p.returncode == 2 and words in p.stderr and "Traceback" not in p.stderr, p.stderr
    p = run_cli("export-gltf", tmp_path / "nope.exr", "-o", tmp_path / "x.gltf")
    assert p.returncode == 1 and "nope.exr" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert not list(tmp_path.iterdir())                          # nothing written by a refused call
    p = run_cli("export-gltf", lit["env"], "-o", tmp_path / "ok.glb", "--size", "16", "-q", "--depfile",
                tmp_path / "ok.d", "--cache", lit["tmp"] / "cache")
    assert p.returncode == 0 and (tmp_path / "ok.d").read_text().startswith(f"{tmp_path / 'ok.glb'}:")
    assert "sky.exr" in (tmp_path / "ok.d").read_text()
    assert sorted(x.name for x in tmp_path.iterdir()) == ["ok.d", "ok.glb"]
    p = run_cli("export-gltf", lit["env"], "-o", tmp_path / "ok.glb", "--size", "16", "-q")   # its own: replaced
    assert p.returncode == 0, p.stderr
    model = tmp_path / "model.gltf"
    model.write_text('{"asset": {"version": "2.0", "generator": "Blender"}}')
    png = tmp_path / "mine_specular_0_px.png"
    png.write_bytes(b"mine")
    for out, victim in ((model, model), (tmp_path / "mine.gltf", png)):
        before = victim.read_bytes()
        p = run_cli("export-gltf", lit["env"], "-o", out, "--size", "16")
        assert p.returncode == 1 and "--force" in p.stderr and victim.read_bytes() == before, p.stderr
    p = run_cli("export-gltf", lit["env"], "-o", model, "--size", "16", "--force", "-q")
    assert p.returncode == 0 and gltf.written_by_iblbake(model)


def test_image_uris_are_percent_encoded_and_read_back(tmp_path):
    """The .gltf named its PNGs by the raw file name: '#' started a fragment, '%41' decoded to 'A',
    a non-UTF-8 byte became a lone surrogate. Now the name's bytes are percent-encoded, and each
    URI resolves (io/confine.py) to the PNG written."""
    import os

    from iblbake.io import confine
    from iblbake.scene import gltf as scene_gltf
    pngs = [[b"png%d" % f for f in range(6)]]
    for name, first in (("my light é#1.gltf", "my%20light%20%C3%A9%231_specular_0_px.png"),
                        ("a%41.gltf", "a%2541_specular_0_px.png"),
                        (os.fsdecode(b"\xfe.gltf"), "%FE_specular_0_px.png"),
                        ("plain-name.gltf", "plain-name_specular_0_px.png")):
        path = tmp_path / name
        gltf.write(path, np.zeros((9, 3)), pngs, 4)
        text = path.read_text(errors="surrogateescape")
        uris = [im["uri"] for im in json.loads(text)["images"]]
        assert uris[0] == first and len(uris) == 6
        for uri, want in zip(uris, gltf.sidecars(path, 1)):
            assert confine.asset_file(path, uri) == want and want.exists()
        assert scene_gltf.relative_uris(text) == [p.name for p in gltf.sidecars(path, 1)]
