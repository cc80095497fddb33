"""Helpers shared by the test modules: scene and file writers, the CLI in a subprocess, reading
back what a render or a page wrote, small kernels. Test modules import from here (or take
conftest.py's fixtures), never from one another: tests/test_suite.py checks it."""

import base64
import contextlib
import json
import os
import shutil
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import numpy.polynomial.legendre as npleg
import pytest
import yaml

from iblbake.core import conventions
from iblbake.io import images
from iblbake.scene.layout import TONEMAP_IDS

ROOT = Path(__file__).resolve().parents[1]
# the example panoramas `make assets` fetches (examples/panoramas/NAME.exr; conftest's `panoramas` fixture)
PANORAMA_NAMES = ("city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset")


def write_exr(path, image, half=False):
    from iblbake.io import images
    images.write_exr(path, np.asarray(image, dtype=np.float32), half=half)
    return str(path)


def run_cli(*args, cwd=None, env=None):
    """Run the installed CLI in a subprocess (end-to-end: exit codes, stderr, no tracebacks)."""
    full_env = dict(os.environ)
    full_env.pop("IBLBAKE_DEBUG", None)
    if env:
        full_env.update(env)
    # a file name that is not UTF-8 is printed as its bytes: read back as Python names it
    return subprocess.run([sys.executable, "-m", "iblbake.cli", *map(str, args)], capture_output=True,
                          text=True, errors="surrogateescape", cwd=cwd, env=full_env, timeout=600)


def scene_file(folder, env, *, name="scene.yaml", **sections):
    """Write a scene file into `folder` and return its path: a unit sphere of material `m` seen
    from +z at 64x64 under `env` (background hidden), with each top-level section given by
    keyword replacing the default one (camera=, materials=, objects=, effects=, output=, lights=)
    and `environment=` merged into the default environment. `materials` holding a base_color is
    the one material `m`. The shared builder of every test's scenes."""
    import yaml
    doc = {"camera": {"perspective": {"position": [0, 0, 3], "fov_y": 45}, "resolution": [64, 64]},
           "environment": {"path": str(env), "background": "hide"},
           "materials": {"m": {}},
           "objects": [{"sphere": {"radius": 1}, "material": "m"}]}
    env_extra = sections.pop("environment", None) or {}
    doc["environment"].update(env_extra)
    for k, v in sections.items():
        if v is not None:
            doc[k] = v
    if "base_color" in doc["materials"]:
        doc["materials"] = {"m": doc["materials"]}
    path = Path(folder) / name
    path.write_text(yaml.safe_dump(doc))
    return path


def load_scene(folder, name, doc):
    """Write the scene `doc` (a dict) as folder/NAME.yaml and load it (iblbake.scene.load)."""
    import yaml
    from iblbake.scene import load as scene_load
    path = Path(folder) / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return scene_load.load(path)


def mend_cache_entry(entry, edit_manifest=None, **arrays):
    """Rewrite a cache entry as another version or a hand might: each name=array saved as NAME.npy
    over the entry's file, edit_manifest(manifest) applied, and the manifest's sizes, times and
    hashes made to match every file (one the caller rewrote itself, an EXR say, too), so that the
    files pass its check and only what they hold is wrong."""
    import hashlib
    import json
    from iblbake.bake import cache
    man = json.loads((entry / cache.MANIFEST).read_text())
    for name, a in arrays.items():
        np.save(entry / f"{name}.npy", a)
    if edit_manifest:
        edit_manifest(man)
    for f in man["files"]:
        p = entry / f["name"]
        f.update(sha256=hashlib.sha256(p.read_bytes()).hexdigest(), bytes=p.stat().st_size,
                 mtime_ns=p.stat().st_mtime_ns)
    (entry / cache.MANIFEST).write_text(json.dumps(man))


def rel_err(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


STRESS = os.environ.get("IBLBAKE_STRESS") == "1"     # `make stress`: more fuzz inputs and kill runs


def stress_scale(fast: int, full: int) -> int:
    """How many inputs or runs a stress loop takes: `fast` in `make test`, `full` in `make stress`."""
    return full if STRESS else fast


@contextlib.contextmanager
def mounted_tmpfs(path, options: str):
    """A tmpfs mounted at `path` with mount `options` (e.g. "size=256k", "ro,size=64k") for the
    full-disk and read-only tests; skips where mounting is not allowed (not root, a container)."""
    path.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)], capture_output=True)
    if r.returncode:
        pytest.skip(f"cannot mount a tmpfs here ({r.stderr.decode().strip()})")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)])


class BakeContext:
    """What Bakes.load reads of a frame's context (render/units.py Job.of): the scene, the runtime,
    the bakes' store (the geometry comes from it), no warnings, no progress."""

    def __init__(self, sc, rt, bakes):
        self.scene, self.rt, self.bakes = sc, rt, bakes
        self.warn, self.progress = (lambda _m: None), None
        self.arrays = None


# --- what a render, a sheet or a page wrote -----------------------------------------------------


def box_downsample(img, factor):
    """Solid-angle-weighted mean over factor x factor blocks (rows weighted by their solid angle)."""
    h, w = img.shape[:2]
    om = conventions.equirect_row_solid_angles(w, h)[:, None, None]
    wimg = (img * om).reshape(h // factor, factor, w // factor, factor, 3).sum((1, 3))
    wsum = om.reshape(h // factor, factor).sum(1)[:, None, None] * factor
    return wimg / wsum


def prefiltered_bakes(frame):
    """The prefiltered chain and DFG table a render baked (float64), as rr.shade takes them."""
    rep = {b["name"]: b for b in frame.report["bakes"]}
    entry = Path(rep["prefiltered"]["entry"])
    man = json.loads((entry / "manifest.json").read_text())
    return {"prefiltered": [images.read_exr(entry / f["name"])[..., :3].astype(np.float64) for f in man["files"]],
            "dfg": images.read_exr(Path(rep["dfg"]["entry"]) / "dfg.exr")[..., :2].astype(np.float64)}


def sheet_scene(folder, env, sweep_spec=None, res=(48, 32)):
    doc = {"camera": {"perspective": {"position": [0, 0.4, 4], "fov_y": 40}, "resolution": list(res)},
           "environment": {"path": str(env), "background": "show"},
           "materials": {"gold": {"base_color": [1.0, 0.78, 0.34], "metallic": 1, "roughness": 0.3},
                         "paint": {"base_color": [0.8, 0.1, 0.1], "roughness": 0.5}},
           "objects": [{"sphere": {"center": [-0.6, 0, 0], "radius": 0.5}, "material": "gold"},
                       {"sphere": {"center": [0.6, 0, 0], "radius": 0.5}, "material": "paint"}],
           "effects": {"specular": "prefiltered", "samples": 8}}
    if sweep_spec:
        doc["sweep"] = sweep_spec
    p = Path(folder) / "sheet.yaml"
    p.write_text(yaml.safe_dump(doc))
    return p


def read_png(path):
    import OpenImageIO as oiio
    return oiio.ImageBuf(str(path)).get_pixels(oiio.UINT8)


def decode(path, shape):
    """A data script's image: (float16 RGB, mask), as the page decodes it."""
    text = Path(path).read_text()
    b64 = text.split('", "', 1)[1].rsplit('"', 1)[0]
    raw = zlib.decompress(base64.b64decode(b64))
    h, w = shape
    rgb = np.frombuffer(raw[:6 * w * h], np.uint8).reshape(2, -1).T.copy().view("<f2").reshape(h, w, 3)
    mask = np.unpackbits(np.frombuffer(raw[6 * w * h:], np.uint8))[:w * h].reshape(h, w).astype(bool)
    return rgb, mask


def manifest_of(index) -> dict:
    """The page's inline data (what html.manifest wrote)."""
    text = Path(index).read_text()
    return json.loads(text.split("window.IBL_DATA = ", 1)[1].split(";</script>", 1)[0].replace("<\\/", "</"))


@contextlib.contextmanager
def read_only_folder(path: Path):
    path.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0:
        path.chmod(0o555)
        try:
            yield path
        finally:
            path.chmod(0o755)
        return
    with mounted_tmpfs(path, "ro,size=64k") as p:   # root ignores mode bits: use a read-only mount
        yield p


# --- numbers and kernels ---------------------------------------------------------------------------


def gauss_sphere(n_theta=48, n_phi=96):
    """Exact quadrature for polynomials of degree < 2*n_theta on the sphere."""
    z, wz = npleg.leggauss(n_theta)
    phi = 2 * np.pi * np.arange(n_phi) / n_phi
    s = np.sqrt(1 - z * z)
    d = np.stack(np.broadcast_arrays(s[:, None] * np.cos(phi), s[:, None] * np.sin(phi), z[:, None]), -1)
    w = np.broadcast_to(wz[:, None] * (2 * np.pi / n_phi), d.shape[:2])
    return d.reshape(-1, 3), w.reshape(-1)


HOSTILE = np.array([0.0, 1e-30, 1e-8, 0.5, 1.0, 11.2, 1e4, 6.5e4, 1e30, np.inf, -np.inf, np.nan, -1.0, -1e30],
                   dtype=np.float32)


def run_cl(rt, hdr, op, ev=0.0, srgb=True, gamma=2.2):
    """kernels/tonemap.cl on `hdr` with operator `op`: (display floats, 8-bit values), RGB."""
    hdr = np.asarray(hdr, np.float32).reshape(-1, 3)
    n = len(hdr)
    rgba = np.zeros((n, 4), np.float32)
    rgba[:, :3] = hdr
    out, disp = rt.empty(n * 4), rt.empty(n * 16)
    rt.launch("tonemap.cl", "tonemap_u8", {"TONEMAP": TONEMAP_IDS[op], "OUTPUT_SRGB": int(srgb)}, (n,), {},
              hdr=rt.to_device(rgba), exposure_scale=2.0 ** ev, gamma=gamma, n=n, pixel0=0, png_u8=out, display=disp)
    return rt.read(disp, (n, 4))[:, :3], rt.read(out, (n, 4), np.uint8)[:, :3]


def selftest_kernel(rt, name, n, inputs, out_floats):
    """Kernel `name` of kernels/selftest.cl over n items: (n, out_floats) float32."""
    prg = rt.program("selftest.cl", {"SH_BANDS": 3})
    out = rt.empty(n * out_floats * 4)
    bufs = [rt.to_device(np.ascontiguousarray(x, np.float32)) if isinstance(x, np.ndarray) else x for x in inputs]
    import pyopencl as cl
    rt.run(cl.Kernel(prg, name), (n,), None, *bufs, out)
    return rt.read(out, (n, out_floats))


# The corpus' absolute judgement (issue 59): default irradiance probes within REGION_BOUND of the
# converged reference on every region of at least MIN_PIXELS pixels.
REGION_BOUND = 0.30
MIN_PIXELS = 10


def outside(errors: dict, bound: float) -> dict:
    """The regions of a study row's region_absolute / part_absolute over bound, as their ratio and worst channel."""
    return {n: f"x{e['ratio']:.2f}, worst channel {100 * e['channel']:.0f}%" for n, e in errors.items()
            if e["pixels"] >= MIN_PIXELS and e["absolute"] > bound}


# a textured quad as a GLB (tests of textures and of lightmaps' TEXCOORD_1)
QUAD_V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
QUAD_F = np.array([[0, 1, 2], [0, 2, 3]])
QUAD_UV = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], float)       # glTF's: v down the image


def quad_glb(path, *, base=None, mr=None, normal=None, occlusion=None, emissive=None, uv=QUAD_UV, uv1=None,
             vertices=QUAD_V, faces=QUAD_F, edit=None, **factors):
    """A quad (or other mesh) as a GLB written by trimesh's exporter with a PBRMaterial; `uv` in
    glTF's convention; `uv1` (TEXCOORD_1) and `edit(doc)` applied to the exporter's JSON after."""
    import trimesh
    from PIL import Image
    from trimesh.visual.material import PBRMaterial

    def im(a):
        return None if a is None else Image.fromarray(np.asarray(a, np.uint8))

    mat = PBRMaterial(baseColorTexture=im(base), metallicRoughnessTexture=im(mr), normalTexture=im(normal),
                      occlusionTexture=im(occlusion), emissiveTexture=im(emissive), **factors)
    gl_uv = np.asarray(uv, float) * [1, -1] + [0, 1]                  # trimesh keeps OpenGL's v up
    m = trimesh.Trimesh(vertices, faces, visual=trimesh.visual.TextureVisuals(uv=gl_uv, material=mat), process=False)
    m.export(str(path))
    if uv1 is not None or edit is not None:
        rewrite_glb(path, uv1, edit)
    return str(path)


def rewrite_glb(path, uv1=None, edit=None):
    from iblbake.io.gltf import glb_bytes
    data = Path(path).read_bytes()
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + n])
    pos = 20 + n
    bn = struct.unpack_from("<I", data, pos)[0]
    binary = bytearray(data[pos + 8:pos + 8 + bn])
    if uv1 is not None:
        extra = np.asarray(uv1, np.float32).tobytes()
        binary += b"\0" * (-len(binary) % 4)
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(binary), "byteLength": len(extra)})
        binary += extra
        doc["accessors"].append({"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5126,
                                 "count": len(uv1), "type": "VEC2"})
        doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_1"] = len(doc["accessors"]) - 1
    if edit is not None:
        edit(doc)
    doc["buffers"][0]["byteLength"] = len(binary)
    Path(path).write_bytes(glb_bytes(doc, bytes(binary)))


def corpus_cases(names, panoramas=("studio", "city"), keep=()):
    """(name, panorama) cases of a corpus test, those not in `keep` marked `corpus`: minutes each,
    `make test-corpus` runs them all, `make test` the kept ones (one of each kind of miss)."""
    import pytest
    return [pytest.param(n, p, id=f"{n}-{p}", marks=() if (n, p) in keep else pytest.mark.corpus)
            for n in names for p in panoramas]


def flip_bytes(path, rng, n: int = 8) -> None:
    """A fuzz case's damage: n bytes of the file at random places set to random values."""
    b = bytearray(Path(path).read_bytes())
    for _ in range(n):
        b[rng.integers(len(b))] = rng.integers(256)
    Path(path).write_bytes(bytes(b))


def quad_room_lightmap_study(cache, panoramas):
    """The corpus' quad_room under studio at 40 px (specular off; its lightmap at 4 texels a unit,
    1024 rays a texel, holding the panorama whole: `environment.sun: none`, what the atlas alone
    is judged by): (the study, its runtime, its bakes, the diffuse term's converged reference;
    two seeds to 3% or 256 samples, as tests/test_corpus.py's)."""
    from iblbake.device.runtime import Runtime
    from iblbake.render.bakes import Bakes
    from iblbake.study import accuracy as acc

    settings = acc.Settings(max_side=40, repeats=1, target_noise=0.03, max_samples=256, flip=False)
    rt, bakes = Runtime(), Bakes(cache)
    st = acc.Study(ROOT / "examples" / "corpus" / "quad_room.yaml",
                   [f"environment.path={panoramas['studio']}", "effects.specular=off", "lightmap.texels_per_unit=4",
                    "lightmap.samples=1024", "environment.sun=none"], settings, runtime=rt, bakes=bakes)
    return st, rt, bakes, st.render_reference("diffuse")


def glsl_compiles(path, source: str) -> None:
    """glslangValidator compiles `source` as a GLSL 330 fragment shader written to path (a .frag);
    the test is skipped where it is not installed (Debian's glslang-tools; make readers installs it)."""
    if shutil.which("glslangValidator") is None:
        pytest.skip("glslangValidator not installed (Debian's glslang-tools; make readers installs it)")
    Path(path).write_text("#version 330 core\n" + source)
    p = subprocess.run(["glslangValidator", str(path)], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stdout + p.stderr
