"""Panorama colour on input: LDR (8/16-bit PNG) panoramas decoded from sRGB to linear (against
colour-science's sRGB decoding) with a one-line warning, `--input-transfer` overriding it; EXR
chromaticities converted to Rec.709/D65 by a Bradford adaptation (against colour-science's
matrix_RGB_to_RGB, 1e-12), white kept white, Rec.709 left alone; bakes key on the policies."""

import json
from pathlib import Path

import numpy as np
import pytest

from iblbake.io import color
from iblbake.io import images

from tests.helpers import run_cli

colour = pytest.importorskip("colour")

CITY = (0.6484, 0.3309, 0.3212, 0.5979, 0.1559, 0.0661, 0.3457, 0.3585)   # what city.exr declares
ADOBE_D50 = (0.64, 0.33, 0.21, 0.71, 0.15, 0.06, 0.3457, 0.3585)          # Adobe RGB primaries, D50 white


def write_png(path, codes, dtype):
    import OpenImageIO as oiio
    h, w, _ = codes.shape
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, 3, oiio.UINT8 if dtype == np.uint8 else oiio.UINT16))
    out.write_image(codes.astype(dtype))
    out.close()


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_ldr_png_decodes_srgb_to_linear(tmp_path, dtype):
    top = np.iinfo(dtype).max
    rng = np.random.default_rng(3)
    codes = rng.integers(0, top + 1, (16, 32, 3))
    codes[0, :4] = [[0, 0, 0], [top, top, top], [1, 1, 1], [top // 2] * 3]
    path = tmp_path / "ldr.png"
    write_png(path, codes, dtype)
    img, info = images.read_panorama(path)
    expected = colour.cctf_decoding(codes / top, function="sRGB")
    assert np.abs(img - expected).max() < 2e-7
    assert len([w for w in info.warnings if "LDR" in w]) == 1
    assert img.max() == pytest.approx(1.0) and np.all(img >= 0)
    lin, _ = images.read_panorama(path, transfer="linear")
    assert np.abs(lin - codes / top).max() < 1e-7


def test_float_images_stay_linear_unless_told(tmp_path):
    v = np.linspace(0, 4, 32 * 16 * 3, dtype=np.float32).reshape(16, 32, 3)
    images.write_exr(tmp_path / "f.exr", v)
    img, info = images.read_panorama(tmp_path / "f.exr")
    assert np.array_equal(img, v) and not any("LDR" in w for w in info.warnings)
    img, _ = images.read_panorama(tmp_path / "f.exr", transfer="srgb")
    assert np.allclose(img[v <= 1], colour.cctf_decoding(v[v <= 1], function="sRGB"), atol=2e-7)


@pytest.mark.parametrize("chroma", [CITY, ADOBE_D50])
def test_bradford_conversion_matches_colour_science(chroma):
    xy = np.array(chroma[:6]).reshape(3, 2)
    src = colour.RGB_Colourspace("src", xy, np.array(chroma[6:]), use_derived_matrix_RGB_to_XYZ=True,
                                 use_derived_matrix_XYZ_to_RGB=True)
    dst = colour.RGB_Colourspace("rec709", np.array(color.REC709[:6]).reshape(3, 2), np.array(color.REC709[6:]),
                                 use_derived_matrix_RGB_to_XYZ=True, use_derived_matrix_XYZ_to_RGB=True)
    ref = colour.matrix_RGB_to_RGB(src, dst, chromatic_adaptation_transform="Bradford")
    m = color.to_rec709(chroma)
    assert np.abs(m - ref).max() < 1e-12
    assert np.abs(m @ np.ones(3) - 1).max() < 1e-12           # the source white is D65 white
    assert np.abs(color.to_rec709(color.REC709) - np.eye(3)).max() < 1e-12


def test_primaries_convert_on_a_declared_exr(tmp_path):
    """An EXR declaring Adobe RGB (D50): keep leaves its values and warns; convert applies the
    matrix (a saturated green leaves the Rec.709 gamut: a negative red, counted)."""
    v = np.zeros((16, 32, 3), np.float32)
    v[..., 1] = 1.0
    v[:8] = 0.5
    import OpenImageIO as oiio
    path = tmp_path / "adobe.exr"
    spec = oiio.ImageSpec(32, 16, 3, oiio.FLOAT)
    spec.attribute("chromaticities", oiio.TypeDesc("float[8]"), ADOBE_D50)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    out.write_image(v)
    out.close()
    kept, info = images.read_panorama(path)
    assert np.array_equal(kept, v) and any("primaries convert converts" in w for w in info.warnings)
    conv, info = images.read_panorama(path, primaries="convert")
    m = color.to_rec709(ADOBE_D50)
    assert np.abs(conv - v @ m.T.astype(np.float32)).max() < 1e-6
    assert np.abs(conv[0, 0] - 0.5).max() < 1e-6                  # grey stays grey
    assert conv[-1, 0, 0] < -0.1 and info.negative > 0


@pytest.mark.external
def test_bakes_key_on_the_policies(tmp_path, small_panoramas):
    runs = {}
    for name, extra in [("keep", []), ("convert", ["--primaries", "convert"]), ("srgb", ["--input-transfer", "srgb"])]:
        p = run_cli("mips", small_panoramas["city"], "--cache", tmp_path / "c", "--only", "radiance", "--json", *extra)
        assert p.returncode == 0, p.stderr
        runs[name] = json.loads(p.stdout)["entries"]["radiance"]
    assert len({r["path"] for r in runs.values()}) == 3 and not any(r["cached"] for r in runs.values())
    city = Path(__file__).resolve().parents[1] / "examples" / "panoramas" / "city.exr"   # declares D50 sRGB
    docs = []
    said = {}
    for how in ("auto", "keep", "convert"):
        p = run_cli("sh", city, "--primaries", how, "--json")
        assert p.returncode == 0, p.stderr
        said[how] = p.stderr.strip().splitlines()
        docs.append(np.array(json.loads(p.stdout)["irradiance"], dtype=float))
    # auto says what it kept; keep, asked for, is silent (a new user could not silence it); convert
    # says what it did
    assert len(said["auto"]) == 1 and "declares non-Rec.709" in said["auto"][0] and not said["keep"]
    assert len(said["convert"]) == 1 and "Bradford" in said["convert"][0]
    assert np.array_equal(docs[0], docs[1])
    docs = [docs[0], docs[2]]
    # city's primaries are sRGB's adapted to D50: converting back moves its colours by ~1e-4
    rel = np.abs(docs[1] - docs[0]).max() / np.abs(docs[0]).max()
    assert 1e-6 < rel < 1e-3


