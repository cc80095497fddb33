"""KTX2 cube maps (`iblbake mips --ktx2`) read back by real readers: ktx-parse (the parser of
three.js's KTX2Loader) must return every level and face equal to the EXR chain bit for bit
(float16 and float32; B10G11R11 equal to its round-to-nearest-even packing, E5B9G9R9 to the
shared-exponent encoding of EXT_texture_shared_exponent), and the libktx of
the official glTF Sample Viewer must open the file with the same format, size and orientation.
Faces follow Vulkan's cube-map face selection, written out here from the Vulkan specification
(not from iblbake's conventions): a panorama with six marked directions lands each on its face
and texel. The packed-float encoder matches a brute-force nearest-even search over every code."""

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from iblbake.core import conventions
from iblbake.io import images, ktx2

from tests.helpers import run_cli

NODE = Path(__file__).parent / "node"
VK = {"rgba16f": 97, "rgba32f": 109, "b10g11r11": 122, "e5b9g9r9": 123}
# the samples' channel ids (low 4 bits) and qualifiers (high 4) of each format's DFD
CHANNELS = {"rgba16f": [0xC0, 0xC1, 0xC2, 0xCF], "rgba32f": [0xC0, 0xC1, 0xC2, 0xCF], "b10g11r11": [0x80, 0x81, 0x82],
            "e5b9g9r9": [0x00, 0x20, 0x01, 0x21, 0x02, 0x22]}


@pytest.fixture(scope="module")
def readers():
    if shutil.which("node") is None or not (NODE / "node_modules" / "ktx-parse").is_dir():
        pytest.skip("the Node readers are not set up: run `make readers` (make test does)")

    def run(script, *paths):
        p = subprocess.run(["node", str(NODE / script), *map(str, paths)], capture_output=True, text=True,
                           timeout=120)
        assert p.returncode == 0, p.stderr
        return json.loads(p.stdout), p.stderr
    return run


def bake(tmp_path, env, fmt, *extra):
    out = tmp_path / f"chain-{fmt}.ktx2"
    p = run_cli("mips", env, "--cache", tmp_path / "c", "--ktx2", out, "--ktx2-format", fmt, "--size", "16",
                "--min-size", "1", "--only", "prefiltered", "--json", *extra)
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)["entries"]
    entry = Path(doc["prefiltered"]["path"])
    files = json.loads((entry / "manifest.json").read_text())["files"]
    chain = [images.read_exr(entry / f["name"])[..., :3] for f in files]
    return out, chain, doc


@pytest.mark.external
@pytest.mark.parametrize("fmt", list(VK))
def test_ktx_parse_reads_every_level_and_face_back(tmp_path, small_panoramas, readers, fmt):
    out, chain, doc = bake(tmp_path, small_panoramas["city"], fmt)
    got = readers("read_ktx2.mjs", out)[0][str(out)]
    assert "error" not in got, got
    assert (got["vkFormat"], got["pixelWidth"], got["pixelHeight"], got["pixelDepth"]) == (VK[fmt], 16, 16, 0)
    assert (got["faceCount"], got["layerCount"], got["supercompressionScheme"]) == (6, 0, 0)
    assert got["typeSize"] == {"rgba16f": 2, "rgba32f": 4}.get(fmt, 4)
    assert got["keyValue"]["KTXorientation"] == "rd" and got["keyValue"]["KTXwriter"].startswith("iblbake")
    assert json.loads(got["keyValue"]["iblbake.roughness"]) == pytest.approx(doc["prefiltered"]["roughness"])
    dfd = got["dfd"][0]
    assert (dfd["colorModel"], dfd["colorPrimaries"], dfd["transferFunction"]) == (1, 1, 1)   # RGBSDA, BT.709, linear
    assert [s["channelType"] for s in dfd["samples"]] == CHANNELS[fmt]
    if fmt == "e5b9g9r9":      # mantissas at 0, 9, 18 (9 bits), the shared exponent at 27 (5 bits, bias 15)
        assert [(s["bitOffset"], s["bitLength"], s["lower"], s["upper"]) for s in dfd["samples"]] == \
            [(0, 8, 0, 8448), (27, 4, 15, 31), (9, 8, 0, 8448), (27, 4, 15, 31), (18, 8, 0, 8448), (27, 4, 15, 31)]
    assert len(got["levels"]) == len(chain) == 5
    for k, (level, ref) in enumerate(zip(got["levels"], chain)):
        s = 16 >> k
        raw = np.frombuffer(__import__("base64").b64decode(level["data"]), dtype={
            "rgba16f": "<f2", "rgba32f": "<f4"}.get(fmt, "<u4"))
        ref = ref.reshape(6, s, s, 3)
        if fmt == "b10g11r11":
            packed = raw.reshape(6, s, s)
            assert np.array_equal(packed, ktx2.pack_b10g11r11(ref))
            back = ktx2.unpack_b10g11r11(packed)
            # round to nearest: half a unit in the last place, 2^-7 (R, G) and 2^-6 (B) relative
            rel = np.abs(back - ref) / np.maximum(ref, 2.0 ** -14)
            assert rel[..., :2].max() <= 2.0 ** -7 and rel[..., 2].max() <= 2.0 ** -6
        elif fmt == "e5b9g9r9":
            packed = raw.reshape(6, s, s)
            assert np.array_equal(packed, ktx2.pack_e5b9g9r9(ref))
            # half a unit of a 9-bit mantissa at the exponent of the texel's largest channel
            err = np.abs(ktx2.unpack_e5b9g9r9(packed) - ref).max(axis=-1)
            assert np.all(err <= 2.0 ** -9 * ref.max(axis=-1) * (1 + 1e-6))
        else:
            texels = raw.reshape(6, s, s, 4)
            assert np.array_equal(texels[..., :3], ref.astype(texels.dtype)) and np.all(texels[..., 3] == 1)
        assert level["uncompressedByteLength"] == raw.nbytes


@pytest.mark.external
def test_libktx_opens_the_file(tmp_path, small_panoramas, readers):
    outs = [bake(tmp_path, small_panoramas["city"], fmt)[0] for fmt in VK]
    got, _ = readers("libktx_info.cjs", *outs)
    for out, fmt in zip(outs, VK):
        info = got[str(out)]
        assert info["messages"] == [], info
        assert (info["vkFormat"], info["baseWidth"], info["baseHeight"]) == (VK[fmt], 16, 16)
        assert info["numComponents"] == (3 if fmt in ktx2.PACKED else 4)
        assert info["orientation"][:2] == [ord("r"), ord("d")]
    bad = tmp_path / "bad.ktx2"
    bad.write_bytes(b"X" + outs[0].read_bytes()[1:])
    got, _ = readers("libktx_info.cjs", bad)
    assert got[str(bad)]["error"] and "Not a KTX file" in " ".join(got[str(bad)]["messages"])  # it does check


def vulkan_face_texel(d, n):
    """Vulkan's cube-map face selection and (s, t) (the spec's table): face, row, column."""
    x, y, z = d
    ax = np.abs(d)
    if ax[0] >= ax[1] and ax[0] >= ax[2]:
        face, sc, tc, ma = (0, -z, -y, ax[0]) if x > 0 else (1, z, -y, ax[0])
    elif ax[1] >= ax[2]:
        face, sc, tc, ma = (2, x, z, ax[1]) if y > 0 else (3, x, -z, ax[1])
    else:
        face, sc, tc, ma = (4, x, -y, ax[2]) if z > 0 else (5, -x, -y, ax[2])
    s, t = 0.5 * (sc / ma + 1), 0.5 * (tc / ma + 1)
    return face, t * n - 0.5, s * n - 0.5             # in texel-centre units


@pytest.mark.external
def test_marked_directions_land_on_their_face_and_texel(tmp_path, readers):
    """Six small bright spots (3 degrees across), one inside each face and off its centre (so a
    flipped or rotated face shows); level 0 (roughness 0: the panorama at each texel's
    direction) holds each spot on the face Vulkan's face selection gives, centred within one
    texel of where it puts it, and nowhere else."""
    w, h, n = 1024, 512, 64
    dirs = conventions.equirect_texel_dirs(w, h)
    marks = [np.array(v, float) / np.linalg.norm(v) for v in
             ([1, 0.3, -0.5], [-1, -0.4, 0.2], [0.35, 1, 0.55], [-0.3, -1, 0.45], [0.5, -0.25, 1], [-0.45, 0.3, -1])]
    pano = np.full((h, w, 3), 0.01, np.float32)
    for m in marks:
        pano[dirs @ m > np.cos(np.radians(1.5))] = 1000.0
    env = tmp_path / "marks.exr"
    images.write_exr(env, pano)
    out, _, _ = bake(tmp_path, env, "rgba32f", "--size", str(n))
    got = readers("read_ktx2.mjs", out)[0][str(out)]
    level0 = np.frombuffer(__import__("base64").b64decode(got["levels"][0]["data"]), "<f4").reshape(6, n, n, 4)
    bright = level0[..., 0] > 100
    for m in marks:
        face, row, col = vulkan_face_texel(m, n)
        rows, cols = np.nonzero(bright[face])
        assert len(rows) >= 2, (m, face)
        assert abs(rows.mean() - row) <= 1 and abs(cols.mean() - col) <= 1, (m, face, row, col, rows, cols)
    assert bright.sum(axis=(1, 2)).min() >= 2            # one spot per face: each face has its own


def test_packed_float_encoder_is_nearest_even():
    """Every finite code decodes and re-encodes to itself; random values and every midpoint
    between codes encode to the nearest code, ties to even (a brute-force search)."""
    rng = np.random.default_rng(7)
    for bits in (6, 5):
        codes = np.arange(31 << bits, dtype=np.uint32)
        vals = ktx2.decode_ufloat(codes, bits).astype(np.float64)
        assert np.all(np.diff(vals) > 0)
        assert np.array_equal(ktx2.encode_ufloat(vals.astype(np.float32), bits), codes)
        x = np.concatenate([np.exp(rng.uniform(np.log(1e-9), np.log(6.5e4), 50000)),
                            (vals[:-1] + vals[1:]) / 2]).astype(np.float32)
        i = np.searchsorted(vals, x.astype(np.float64))
        lo, hi = np.clip(i - 1, 0, len(vals) - 1), np.clip(i, 0, len(vals) - 1)
        dlo, dhi = np.abs(x - vals[lo]), np.abs(vals[hi] - x)
        best = np.where(dlo < dhi, lo, np.where(dhi < dlo, hi, np.where(lo % 2 == 0, lo, hi)))
        assert np.array_equal(ktx2.encode_ufloat(x, bits), best)
    special = ktx2.encode_ufloat(np.array([-1.0, -0.0, 0.0, 1e9, np.inf, np.nan], np.float32), 6)
    assert list(special[:4]) == [0, 0, 0, (30 << 6) | 63] and special[4] == 31 << 6 and special[5] > 31 << 6


def test_shared_exponent_encoder():
    """EXT_texture_shared_exponent's encoding: every canonical code (the largest mantissa at
    least 2^8, or the exponent 0) decodes and re-encodes to itself; any value comes back within
    half a mantissa unit at its largest channel's exponent (2^-9 of that channel); negatives and
    NaN give 0, values beyond the largest (65408, +Inf too) give it."""
    rng = np.random.default_rng(11)
    m = rng.integers(0, 512, (200000, 3), dtype=np.uint32)
    e = rng.integers(0, 32, 200000, dtype=np.uint32)
    m[np.arange(200000), rng.integers(0, 3, 200000)] |= np.where(e > 0, 256, 0).astype(np.uint32)
    codes = m[:, 0] | (m[:, 1] << 9) | (m[:, 2] << 18) | (e << 27)
    codes = np.concatenate([codes, [0, 0x1FF, 0xF80001FF, 0xFFFFFFFF, 0x08000100]]).astype(np.uint32)
    assert np.array_equal(ktx2.pack_e5b9g9r9(ktx2.unpack_e5b9g9r9(codes)), codes)
    x = np.exp(rng.uniform(np.log(1e-8), np.log(6e4), (100000, 3))) * (rng.random((100000, 3)) < 0.9)
    back = ktx2.unpack_e5b9g9r9(ktx2.pack_e5b9g9r9(x)).astype(np.float64)
    # below 2^-15 the exponent is at its floor (0): half a unit there is 2^-25, absolute
    bound = np.maximum(2.0 ** -9 * x.max(axis=-1), 2.0 ** -25) * (1 + 1e-12)
    assert np.all(np.abs(back - x).max(axis=-1) <= bound)
    special = ktx2.unpack_e5b9g9r9(ktx2.pack_e5b9g9r9(np.array([[-1.0, np.nan, 1e9], [np.inf, 0.0, -0.0]])))
    assert special.tolist() == [[0.0, 0.0, ktx2.E5_MAX], [ktx2.E5_MAX, 0.0, 0.0]]


@pytest.mark.external
def test_bad_ktx2_requests_are_one_line(tmp_path, small_panoramas):
    env = small_panoramas["city"]
    cases = [(["--layout", "equirect"], "--ktx2 writes a cube map"),
             (["--level-sizes", "lobe"], "--level-sizes halving"),
             (["--size", "16", "--levels", "8"], "lower --levels or --min-size"),
             (["--only", "dfg"], "--only prefiltered")]
    for extra, says in cases:
        p = run_cli("mips", env, "--cache", tmp_path / "c", "--ktx2", tmp_path / "x.ktx2", *extra)
        assert p.returncode != 0 and says in p.stderr.strip().splitlines()[-1], (extra, p.stderr)
        assert "Traceback" not in p.stderr
        assert not (tmp_path / "x.ktx2").exists()


@pytest.mark.parametrize("fmt", list(VK))
def test_read_cube_gives_back_what_each_format_stores(tmp_path, fmt):
    """A cube map as input (`--input-layout ktx2`) reads level 0 as the format stores it."""
    rng = np.random.default_rng(2)
    faces = (rng.random((6, 8, 8, 3)) * 50).astype(np.float32)
    path = tmp_path / f"in-{fmt}.ktx2"
    path.write_bytes(ktx2.cube_bytes([faces, faces[:, ::2, ::2]], fmt))
    stored = {"b10g11r11": lambda f: ktx2.unpack_b10g11r11(ktx2.pack_b10g11r11(f)),
              "e5b9g9r9": lambda f: ktx2.unpack_e5b9g9r9(ktx2.pack_e5b9g9r9(f)),
              "rgba16f": lambda f: f.astype(np.float16).astype(np.float32), "rgba32f": lambda f: f}[fmt]
    assert np.array_equal(ktx2.read_cube(path, 1 << 30), stored(faces))
