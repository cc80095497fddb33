"""`iblbake sh --format filament|threejs|gltf|glsl`: each export evaluated with that engine's own
formula gives iblbake's irradiance (float64 twin, sh.irradiance) to 1e-5 at 500 directions.
The engines' formulas, transcribed:
- Filament, shaders/src/light_indirect.fs, Irradiance_SphericalHarmonics(n) = max(0, sh[0] +
  sh[1] n.y + sh[2] n.z + sh[3] n.x + sh[4] n.y n.x + sh[5] n.y n.z + sh[6] (3 n.z^2 - 1) +
  sh[7] n.z n.x + sh[8] (n.x^2 - n.y^2)), multiplied by the diffuse colour (the coefficients
  carry the Lambertian 1/pi: filament/include/filament/IndirectLight.h, Builder::irradiance);
- three.js, src/math/SphericalHarmonics3.js, getIrradianceAt(normal) with its rounded
  constants 0.886227, 2 * 0.511664, 2 * 0.429043, 0.743125, 0.247708, 0.429043, times
  BRDF_Lambert = albedo / pi;
- Babylon.js (EXT_lights_image_based's reference loader), packages/dev/core/src/Maths/sphericalPolynomial.ts
  and its glTF loader: SphericalHarmonics.FromArray(irradianceCoefficients), scaled by intensity
  and 1/pi (convertIrradianceToLambertianRadiance), pre-scaled by SH3ylmBasisConstants (with
  their Condon-Shortley minus signs) and evaluated by the PBR shader's computeEnvironmentIrradiance
  on its trigonometric terms 1, y, z, x, yx, yz, 3z^2 - 1, zx, x^2 - y^2 at the normal in
  Babylon's left-handed world, where the loader's root node (rotation [0, 1, 0, 0], scaling
  [1, 1, -1]) puts glTF's (x, y, z) at (-x, y, z); times the albedo;
- the GLSL snippet compiled by glslangValidator (Debian's glslang-tools) when it is there, and
  its function run here through a line-by-line Python transcription of its loop."""

import json
import math

import numpy as np
import pytest

from iblbake.core import sh

from tests.helpers import glsl_compiles, run_cli


def directions(n=500, seed=11):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.fixture(scope="module")
def baked(small_panoramas, tmp_path_factory):
    """iblbake's own document (3 bands) of city: the irradiance every export must reproduce."""
    out = tmp_path_factory.mktemp("shfmt") / "city.json"
    p = run_cli("sh", small_panoramas["city"], "-o", out, "-q")
    assert p.returncode == 0, p.stderr
    doc = json.loads(out.read_text())
    d = directions()
    e = np.stack([sh.irradiance(np.asarray(doc["irradiance"])[:, c], d, 3) for c in range(3)], axis=-1)
    return {"env": small_panoramas["city"], "doc": doc, "dirs": d, "E": e}


def export(baked, fmt, *extra):
    p = run_cli("sh", baked["env"], "--format", fmt, "-q", *extra)
    assert p.returncode == 0, p.stderr
    return p.stdout


def rel(got, want):
    return float(np.abs(got - want).max() / np.abs(want).max())


@pytest.mark.external
def test_filament(baked):
    lines = [ln for ln in export(baked, "filament").splitlines() if ln.strip()]
    c = np.array([[float(v) for v in ln.split(";")[0].strip("() ").split(",")] for ln in lines])
    assert c.shape == (9, 3)
    x, y, z = baked["dirs"].T
    poly = np.stack([np.ones_like(x), y, z, x, y * x, y * z, 3 * z * z - 1, z * x, x * x - y * y], axis=1)
    diffuse = np.maximum(poly @ c, 0.0)              # Irradiance_SphericalHarmonics, albedo 1
    assert rel(diffuse, np.maximum(baked["E"], 0) / math.pi) < 1e-5


@pytest.mark.external
def test_threejs(baked):
    doc = json.loads(export(baked, "threejs"))
    c = np.array(doc["sh"]).reshape(9, 3)
    x, y, z = baked["dirs"].T
    t = (c[0] * 0.886227 + np.outer(2.0 * 0.511664 * y, c[1]) + np.outer(2.0 * 0.511664 * z, c[2])
         + np.outer(2.0 * 0.511664 * x, c[3]) + np.outer(2.0 * 0.429043 * x * y, c[4])
         + np.outer(2.0 * 0.429043 * y * z, c[5]) + np.outer(0.743125 * z * z - 0.247708, c[6])
         + np.outer(2.0 * 0.429043 * x * z, c[7]) + np.outer(0.429043 * (x * x - y * y), c[8]))
    # three.js's constants have 6 digits: 2e-6 relative
    assert rel(t, baked["E"]) < 1e-5


@pytest.mark.external
def test_gltf_as_babylon_reads_it(baked):
    doc = json.loads(export(baked, "gltf"))
    c = np.array(doc["irradianceCoefficients"])
    assert c.shape == (9, 3)
    basis = [math.sqrt(1 / (4 * math.pi)), -math.sqrt(3 / (4 * math.pi)), math.sqrt(3 / (4 * math.pi)),
             -math.sqrt(3 / (4 * math.pi)), math.sqrt(15 / (4 * math.pi)), -math.sqrt(15 / (4 * math.pi)),
             math.sqrt(5 / (16 * math.pi)), -math.sqrt(15 / (4 * math.pi)), math.sqrt(15 / (16 * math.pi))]
    pre = c / math.pi * np.array(basis)[:, None]       # intensity 1, to Lambertian radiance, preScaleForRendering
    x, y, z = baked["dirs"].T
    x = -x                                              # glTF -> Babylon's left-handed world
    trig = np.stack([np.ones_like(x), y, z, x, y * x, y * z, 3 * z * z - 1, z * x, x * x - y * y], axis=1)
    assert rel(trig @ pre, baked["E"] / math.pi) < 1e-5


def glsl_eval(src: str, d: np.ndarray) -> np.ndarray:
    """The snippet's shIrradiance, statement by statement, on the coefficients it declares."""
    body = src.split("vec3[")[1].split(");")[0]
    coeffs = np.array([[float(v) for v in grp.split(")")[0].split(",")]
                       for grp in body.split("vec3(")[1:]])
    bands = int(src.split("SH_BANDS = ")[1].split(";")[0])
    out = np.zeros((len(d), 3))
    for i, v in enumerate(d):
        k = [math.sqrt((2 * l + 1) / (4 * math.pi)) for l in range(bands)]
        pmm, cm, sm = 1.0, 1.0, 0.0
        e = np.zeros(3)
        for m in range(bands):
            if m > 0:
                pmm *= 2 * m - 1
                c = cm * v[0] - sm * v[1]
                sm = sm * v[0] + cm * v[1]
                cm = c
                for l in range(m, bands):
                    k[l] *= 1 / math.sqrt((l + m) * (l - m + 1))
            p2, p1 = 0.0, pmm
            for l in range(m, bands):
                p = pmm if l == m else (2 * m + 1) * v[2] * pmm if l == m + 1 else \
                    ((2 * l - 1) * v[2] * p1 - (l + m - 1) * p2) / (l - m)
                if l > m:
                    p2, p1 = p1, p
                if m == 0:
                    e += coeffs[l * (l + 1)] * k[l] * p
                else:
                    kp = math.sqrt(2) * k[l] * p
                    e += coeffs[l * (l + 1) + m] * kp * cm + coeffs[l * (l + 1) - m] * kp * sm
        out[i] = np.maximum(e, 0)
    return out


@pytest.mark.external
@pytest.mark.parametrize("bands", [3, 5])
def test_glsl(baked, tmp_path, bands):
    src = export(baked, "glsl", "--bands", str(bands))
    d = baked["dirs"][:100]
    doc = json.loads(run_cli("sh", baked["env"], "--bands", str(bands), "--json", "-q").stdout)
    want = np.stack([sh.irradiance(np.asarray(doc["irradiance"])[:, c], d, bands) for c in range(3)], axis=-1)
    assert rel(glsl_eval(src, d), np.maximum(want, 0)) < 1e-5
    glsl_compiles(tmp_path / "probe.frag", src + "\nin vec3 N;\nout vec4 color;\n"
                  "void main() { color = vec4(shIrradiance(normalize(N)), 1.0); }\n")


@pytest.mark.external
def test_format_limits_and_files(baked, tmp_path):
    p = run_cli("sh", baked["env"], "--format", "threejs", "--bands", "4")
    assert p.returncode == 2 and "at most 3 bands" in p.stderr
    out = tmp_path / "probe.json"
    p = run_cli("sh", baked["env"], "--format", "threejs", "-o", out, "-q")
    assert p.returncode == 0 and json.loads(out.read_text())["generator"] == "iblbake"
    p = run_cli("sh", baked["env"], "--format", "threejs", "-o", out, "-q")        # its own export: replaced
    assert p.returncode == 0
    other = tmp_path / "notes.txt"
    other.write_text("mine")
    p = run_cli("sh", baked["env"], "--format", "filament", "-o", other)
    assert p.returncode == 1 and "--force" in p.stderr and other.read_text() == "mine"
    p = run_cli("sh", baked["env"], baked["env"], "--format", "filament", "-o", f"{tmp_path}/many/", "-q")
    assert p.returncode == 0 and (tmp_path / "many" / "city.txt").is_file()
