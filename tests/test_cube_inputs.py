"""Cube-map environments (`--input-layout`, environment.layout): crosses, strips, six face files
and KTX2 cube maps all give the same equirect panorama bit for bit; faces built here from
Vulkan's face table (written out from the spec, not from iblbake's conventions) of a smooth
function come back as that function; a constant stays constant; energy is kept; the kernel
matches its float64 twin; bad cube maps are one-line errors; the KTX2 reader survives mutation.
The resampling's own exactness is tests/test_cube_resample.py's."""

import json

import numpy as np
import pytest

from iblbake.bake import cube_resample, inputs
from iblbake.core import conventions
from iblbake.errors import InputError
from iblbake.io import images, ktx2

from tests.helpers import run_cli

S = 32


def vulkan_face_dirs(s):
    """Texel-centre directions of the six faces from Vulkan's table: face, (sc, tc, ma) ->
    direction, with s = (sc/ma + 1)/2 across and t = (tc/ma + 1)/2 down."""
    c = 2 * (np.arange(s) + 0.5) / s - 1
    tc, sc = np.meshgrid(c, c, indexing="ij")
    one = np.ones_like(sc)
    faces = [(one, -tc, -sc), (-one, -tc, sc), (sc, one, tc), (sc, -one, -tc), (sc, -tc, one), (-sc, -tc, -one)]
    d = np.stack([np.stack(f, axis=-1) for f in faces])
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def smooth(d):
    return np.stack([1 + 0.5 * d[..., 0], 1 + 0.3 * d[..., 1] ** 2, 1.2 + 0.2 * d[..., 2]], axis=-1)


def layouts_of(faces):
    """The same faces as every layout's image."""
    s = faces.shape[1]
    blank = lambda c, r: np.zeros((r * s, c * s, 3), np.float32)  # noqa: E731
    h, v = blank(4, 3), blank(3, 4)
    for (c, r), f in zip(inputs.CROSS["hcross"], faces):
        h[r * s:(r + 1) * s, c * s:(c + 1) * s] = f
    for k, ((c, r), f) in enumerate(zip(inputs.CROSS["vcross"], faces)):
        v[r * s:(r + 1) * s, c * s:(c + 1) * s] = f[::-1, ::-1] if k == 5 else f
    return {"hcross": h, "vcross": v, "hstrip": np.concatenate(list(faces), axis=1),
            "vstrip": np.concatenate(list(faces), axis=0)}


@pytest.fixture(scope="module")
def cube(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cube")
    faces = smooth(vulkan_face_dirs(S)).astype(np.float32)
    paths = {}
    for name, img in layouts_of(faces).items():
        paths[name] = folder / f"{name}.exr"
        images.write_exr(paths[name], img)
    for n, f in zip(inputs.FACE_NAMES, faces):
        images.write_exr(folder / f"sky_{n}.exr", f)
    paths["faces"] = str(folder / "sky_{face}.exr")
    paths["ktx2"] = folder / "sky.ktx2"
    paths["ktx2"].write_bytes(ktx2.cube_bytes([faces], "rgba32f"))
    return faces, paths


def test_every_layout_gives_the_same_panorama(cube, rt):
    faces, paths = cube
    ref = cube_resample.cube_to_equirect_cl(rt, faces)
    for name, path in paths.items():
        img, info = inputs.read_environment(path)            # auto-detected
        assert np.array_equal(img, ref), name
        assert any("resampled" in w for w in info.warnings) and img.shape == (2 * S, 4 * S, 3)
    # the panorama is the smooth function, to the box texels' own error (a texel's mean)
    eq = conventions.equirect_texel_dirs(4 * S, 2 * S)
    assert np.abs(ref - smooth(eq)).max() < 0.03


def test_constant_and_energy(rt):
    c = np.full((6, S, S, 3), [0.25, 1.0, 4.0], np.float32)
    for eq in (cube_resample.cube_to_equirect(c), cube_resample.cube_to_equirect_cl(rt, c)):
        assert np.abs(eq / c[0, 0, 0] - 1).max() < 1.2e-7          # measured 0: a float32 rounding at most
    rng = np.random.default_rng(5)
    f = rng.exponential(1.0, (6, S, S, 3)).astype(np.float32)
    eq = cube_resample.cube_to_equirect(f, dtype=np.float64)
    e_eq = (eq * conventions.equirect_solid_angles(4 * S, 2 * S)[..., None]).sum(axis=(0, 1))
    e_cube = (f * conventions.cube_texel_solid_angles(S)[None, ..., None]).sum(axis=(0, 1, 2))
    assert np.abs(e_eq / e_cube - 1).max() < 2e-14                  # exact overlaps (measured 4e-15)
    cl = cube_resample.cube_to_equirect_cl(rt, f)
    rel = np.abs(cl - eq) / np.abs(eq)
    assert rel.max() < 1.2e-7                     # the kernel in double, stored as float32 (measured 6e-8)


def test_marks_land_where_vulkan_puts_them(tmp_path):
    """One bright texel per face, off centre: in the panorama each shows at its direction."""
    d = vulkan_face_dirs(S)
    faces = np.full((6, S, S, 3), 0.01, np.float32)
    spots = [(k, 5 + k, 20 - 2 * k) for k in range(6)]
    for k, r, c in spots:
        faces[k, r, c] = 1000.0
    eq = cube_resample.cube_to_equirect(faces)
    lum = eq[..., 0]
    for k, r, c in spots:
        u, v = conventions.equirect_uv_from_dir(d[k, r, c])
        row, col = int(v * 2 * S), int(u * 4 * S) % (4 * S)
        near = lum[max(row - 1, 0):row + 2, [(col + o) % (4 * S) for o in (-1, 0, 1)]]
        assert near.max() > 50, (k, r, c)


def test_bad_cube_maps_are_one_line(tmp_path, cube):
    faces, paths = cube
    data = paths["ktx2"].read_bytes()
    cases = {"short.ktx2": data[:50], "magic.ktx2": b"X" + data[1:], "cut.ktx2": data[:-100]}
    one = bytearray(data)
    one[12 + 6 * 4:12 + 7 * 4] = (1).to_bytes(4, "little")               # faceCount 1
    cases["faces.ktx2"] = bytes(one)
    for name, blob in cases.items():
        (tmp_path / name).write_bytes(blob)
        with pytest.raises(InputError) as e:
            inputs.read_environment(tmp_path / name)
        assert name in str(e.value) and "\n" not in str(e.value)
    images.write_exr(tmp_path / "odd.exr", np.ones((30, 40, 3), np.float32))       # 4:3, faces of 10 x 10
    with pytest.raises(InputError, match="not a vcross"):
        inputs.read_environment(tmp_path / "odd.exr", layout="vcross")
    with pytest.raises(InputError, match=r"\{face\}"):
        inputs.read_environment(tmp_path / "odd.exr", layout="faces")


@pytest.mark.slow
def test_ktx2_reader_survives_mutation(tmp_path, cube):
    """500 mutated files (bytes flipped, cut, duplicated): each reads or fails with an
    InputError; nothing else escapes."""
    data = ktx2.cube_bytes([cube[0][:, :4, :4]], "rgba16f")
    rng = np.random.default_rng(1)
    path = tmp_path / "m.ktx2"
    for _ in range(500):
        b = bytearray(data)
        how = rng.integers(3)
        if how == 0:
            for _ in range(rng.integers(1, 8)):
                b[rng.integers(len(b))] = rng.integers(256)
        elif how == 1:
            b = b[:rng.integers(len(b))]
        else:
            i = rng.integers(len(b))
            b = b[:i] + b[i:i + rng.integers(1, 64)] + b[i:]
        path.write_bytes(bytes(b))
        try:
            inputs.read_environment(path)
        except InputError:
            pass


def test_cli_reads_a_cross(tmp_path, cube):
    faces, paths = cube
    p = run_cli("sh", paths["hcross"], "--json")
    assert p.returncode == 0 and "hcross cube map" in p.stderr, p.stderr
    q = run_cli("sh", paths["vstrip"], "--json", "--input-layout", "vstrip")
    assert json.loads(p.stdout)["irradiance"] == json.loads(q.stdout)["irradiance"]
    p = run_cli("mips", paths["faces"], "--cache", tmp_path / "c", "--only", "radiance", "--json")
    assert p.returncode == 0, p.stderr
    p = run_cli("sh", paths["hstrip"], "--input-layout", "hcross")
    assert p.returncode == 1 and "not a hcross" in p.stderr and len(p.stderr.strip().splitlines()) == 1


def test_without_a_device_the_twin_resamples(cube, rt, monkeypatch):
    """No OpenCL device (or none with doubles): read_environment falls back on the float64 twin,
    which gives the kernel's panorama to float32 rounding."""
    faces, paths = cube
    want = cube_resample.cube_to_equirect_cl(rt, faces)
    monkeypatch.setattr(inputs, "_default_runtime", lambda: None)
    monkeypatch.setattr(cube_resample, "cube_to_equirect_cl", None)       # not called
    img, _ = inputs.read_environment(paths["hcross"])
    assert np.abs(img / want - 1).max() < 1.2e-7               # measured 0 (smooth faces: the same floats)
