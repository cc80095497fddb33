"""Image IO: every input format issue 2 names reads back as RGB float, and writes are atomic."""

import math

import numpy as np
import OpenImageIO as oiio
import pytest

from iblbake.io import images


def write_with_oiio(path, pixels, fmt, channels):
    h, w, nc = pixels.shape
    spec = oiio.ImageSpec(w, h, nc, fmt)
    spec.channelnames = channels
    out = oiio.ImageOutput.create(str(path))
    assert out is not None, oiio.geterror()
    assert out.open(str(path), spec) and out.write_image(pixels), out.geterror()
    out.close()


CASES = [
    ("float.exr", oiio.FLOAT, ("R", "G", "B")),
    ("half.exr", oiio.HALF, ("R", "G", "B")),
    ("rgba.exr", oiio.HALF, ("R", "G", "B", "A")),
    ("gray.exr", oiio.FLOAT, ("Y",)),
    ("radiance.hdr", oiio.FLOAT, ("R", "G", "B")),
    ("pfm.pfm", oiio.FLOAT, ("R", "G", "B")),
    ("float.tif", oiio.FLOAT, ("R", "G", "B")),
]


@pytest.mark.parametrize("name,fmt,channels", CASES)
def test_formats_read_as_rgb(tmp_path, name, fmt, channels):
    h, w = 8, 16
    rgb = np.stack([np.full((h, w), 0.25), np.full((h, w), 1.5), np.full((h, w), 3.0)], -1)
    if channels == ("Y",):
        pix = np.full((h, w, 1), 0.75)
        expect = np.full((h, w, 3), 0.75)
    else:
        pix = np.concatenate([rgb, np.full((h, w, 1), 0.5)], -1) if len(channels) == 4 else rgb
        expect = rgb
    path = tmp_path / name
    write_with_oiio(path, pix.astype(np.float32), fmt, channels)
    img, info = images.read_panorama(path)
    assert img.shape == (h, w, 3) and img.dtype == np.float32
    # .hdr stores RGBE (8-bit mantissas): 1% there, exact (half-representable values) elsewhere
    tol = 1e-2 if name.endswith(".hdr") else 1e-6
    assert np.abs(img / expect - 1).max() < tol, name
    assert info.width == w and info.height == h and len(info.sha256) == 64


def test_write_exr_and_png_atomic(tmp_path):
    img = np.random.default_rng(0).random((4, 8, 3)).astype(np.float32)
    images.write_exr(tmp_path / "a.exr", img)
    assert np.array_equal(images.read_exr(tmp_path / "a.exr"), img)
    images.write_exr(tmp_path / "h.exr", img, half=True)
    assert np.abs(images.read_exr(tmp_path / "h.exr") - img).max() < 1e-3
    images.write_png(tmp_path / "a.png", (img * 255).astype(np.uint8))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr", "a.png", "h.exr"]


def test_size_limit_is_checked_before_decoding(tmp_path, monkeypatch):
    path = tmp_path / "big.exr"
    images.write_exr(path, np.ones((64, 128, 3), np.float32))
    monkeypatch.setenv("IBLBAKE_MAX_PIXELS", "100")
    with pytest.raises(images.InputError, match="over the limit of 100"):
        images.read_panorama(path)
    # and a decode never happens: the limit is read from the header alone
    called = []
    orig = oiio.ImageInput.read_image
    monkeypatch.setattr(oiio.ImageInput, "read_image", lambda *a, **k: called.append(1) or orig(*a, **k),
                        raising=False)
    with pytest.raises(images.InputError):
        images.read_panorama(path)
    assert not called
    # positive control: under the limit the same hook does see the decode
    monkeypatch.setenv("IBLBAKE_MAX_PIXELS", "100000")
    images.read_panorama(path)
    assert called


@pytest.mark.external
def test_chromaticities_warning_for_city(panoramas):
    _, info = images.read_panorama(panoramas["city"])
    assert info.chromaticities and any("non-Rec.709" in w for w in info.warnings)
    _, info = images.read_panorama(panoramas["studio"])
    assert not any("non-Rec.709" in w for w in info.warnings)
    assert math.isclose(info.negative_min, -3.0398369e-06, rel_tol=1e-3) and info.negative == 3


def test_atomic_writes_get_normal_permissions(tmp_path):
    """Frames, EXRs and JSON written atomically are readable like any open()-created file
    (0666 minus the umask), not the temporary file's 0600."""
    import os
    from iblbake.io import atomic
    old = os.umask(0o022)
    try:
        atomic.write_json(tmp_path / "a.json", {"x": 1})
        images.write_png(tmp_path / "a.png", np.zeros((2, 3, 3), np.uint8))
        images.write_exr(tmp_path / "a.exr", np.zeros((2, 3, 3), np.float32))
        os.umask(0o077)
        atomic.write_text(tmp_path / "b.txt", "x")
    finally:
        os.umask(old)
    for name in ("a.json", "a.png", "a.exr"):
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o644, name
    assert (tmp_path / "b.txt").stat().st_mode & 0o777 == 0o600


# a file name that is not UTF-8 (any bytes are legal on Linux): Python reads it as a str with a surrogate
NOT_UTF8 = "\udcff"


def test_names_that_are_not_utf8_are_read_and_written(tmp_path):
    """OpenImageIO's binding takes only UTF-8 names (it raised `TypeError: open(): incompatible
    function arguments`): such a name is read and written through a link, the same pixels."""
    img = np.random.default_rng(1).random((4, 8, 3)).astype(np.float32)
    folder = tmp_path / f"{NOT_UTF8}dir"
    images.write_exr(folder / f"{NOT_UTF8}.exr", img)
    assert np.array_equal(images.read_exr(folder / f"{NOT_UTF8}.exr"), img)
    pano, info = images.read_panorama(folder / f"{NOT_UTF8}.exr")
    assert np.array_equal(pano, img) and info.width == 8
    assert sorted(p.name for p in folder.iterdir()) == [f"{NOT_UTF8}.exr"]     # no link or temp file left


def test_the_longest_legal_output_name_is_written(tmp_path):
    """A name of 255 bytes is legal on ext4: the temporary file beside it (18 bytes longer before)
    must fit too."""
    from iblbake.io import atomic
    img = np.ones((2, 3, 3), np.float32)
    for name in ("e" * 251 + ".exr", "j" * 250 + ".json", "é" * 125 + "x.png", "n" * 255):
        assert len(name.encode()) == 255
        images.write_exr(tmp_path / name, img) if name.endswith(".exr") else atomic.write_text(tmp_path / name, "x")
        assert (tmp_path / name).exists()
    assert np.array_equal(images.read_exr(tmp_path / ("e" * 251 + ".exr")), img)
    assert len(list(tmp_path.iterdir())) == 4
