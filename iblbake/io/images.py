"""Read and write panoramas and frames through OpenImageIO, with validation.

Reading: EXR (half/float; RGB, RGBA, Y), Radiance .hdr, PFM, float TIFF, anything OIIO reads.
The size is checked from the header before any pixel is decoded. Non-finite texels fail by
default (count and first position in the message), or are repaired with the nonfinite policy zero|clamp;
negative texels (every one of Blender's panoramas has tiny ones) are kept as stored by default,
counted and reported, or clamped / refused with the negative policy.
An integer (LDR: 8- or 16-bit PNG, JPEG) panorama is decoded from its transfer to linear (sRGB
unless the file declares linear or a gamma; the transfer policy overrides) with a one-line
warning that it clips highlights. Declared EXR chromaticities other than Rec.709 are used as
stored (primaries auto, with a warning; keep, without) or converted to Rec.709/D65 with a Bradford
adaptation (convert).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iblbake.io.color import REC709
from iblbake.errors import InputError, IblbakeError
from iblbake.io.atomic import atomic_path

DEFAULT_MAX_PIXELS = 8192 * 8192
# Values beyond this cannot be summed in float32 kernels (a row of 8192 of them overflows 3.4e38);
# no real radiance comes near it (Blender's suns peak at 3.4e4), but a corrupted file does.
MAX_ABS_VALUE = 1e30
# Negative values holding more than this share of a panorama's summed |value| are reported when
# kept: a filter's ringing holds far less (Blender's eight: at most 6.2e-7), a broken or offset
# file (every texel -1) all of it.
NEGATIVE_TINY_SHARE = 1e-4
NONFINITE_POLICIES = ("error", "zero", "clamp")
NEGATIVE_POLICIES = ("keep", "clamp", "error")
TRANSFERS = ("auto", "srgb", "linear")
PRIMARIES = ("auto", "keep", "convert")


@dataclass
class ImageInfo:
    path: str
    width: int
    height: int
    channels_in: tuple
    format: str
    sha256: str
    chromaticities: tuple | None = None
    nonfinite: int = 0
    nonfinite_policy: str = "error"
    negative: int = 0
    negative_min: float = 0.0
    negative_policy: str = "keep"
    negative_share: float = 0.0     # the negative values' share of the summed |value|
    warnings: list = field(default_factory=list)
    layout: str = "equirect"      # what the file held (bake.inputs.LAYOUTS); pixels are equirect

    @property
    def negative_tiny(self) -> bool:
        """Negatives no one would see: a resampling filter's undershoot (Blender's panoramas hold
        up to 6e-7 of their energy in them, >= -0.004), kept without a warning."""
        return self.negative_share <= NEGATIVE_TINY_SHARE

    def to_json(self) -> dict:
        return {
            "path": self.path,
            "width": self.width,
            "height": self.height,
            "channels": list(self.channels_in),
            "format": self.format,
            "sha256": self.sha256,
            "chromaticities": list(self.chromaticities) if self.chromaticities else None,
            "nonfinite_texels": self.nonfinite,
            "nonfinite_policy": self.nonfinite_policy,
            "negative_texels": self.negative,
            "negative_min": self.negative_min,
            "negative_policy": self.negative_policy,
        }


def max_pixels_default() -> int:
    return env_pixels("IBLBAKE_MAX_PIXELS", DEFAULT_MAX_PIXELS)


def env_pixels(name: str, default: int) -> int:
    """A pixel limit from the environment variable `name` (io/reads.py env_count)."""
    from iblbake.io import reads
    return reads.env_count(name, default, "pixels")


def file_sha256(path) -> str:
    """The file's sha256, read in blocks (a regular file only: a device or a FIFO never ends)."""
    from iblbake.io.reads import open_checked
    h = hashlib.sha256()
    with open_checked(path, 1 << 62) as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _oiio():
    import OpenImageIO as oiio  # 0.04 s; only commands that touch images pay it
    return oiio


@contextlib.contextmanager
def oiio_name(path):
    """`path` as OpenImageIO's Python binding takes it: UTF-8 text only, where a file name on
    Linux is any bytes (b'\\xff.exr' reaches Python as a str with a surrogate). Such a name is
    given to OpenImageIO as a link of a plain name, in a private temporary folder, to the file
    (its extension kept: OpenImageIO picks the format from it); read or write, the file is the same."""
    p = os.fspath(path)
    try:
        p.encode("utf-8")
    except UnicodeEncodeError:
        pass
    else:
        yield p
        return
    import tempfile
    ext = os.path.splitext(p)[1]
    ext = ext if ext.isascii() and ext.isprintable() else ""
    folder = tempfile.mkdtemp(prefix="iblbake-name-")
    link = os.path.join(folder, "image" + ext)
    try:
        os.symlink(os.path.abspath(p), link)
        yield link
    finally:
        with contextlib.suppress(OSError):
            os.unlink(link)
        with contextlib.suppress(OSError):
            os.rmdir(folder)


def _first_position(mask) -> str:
    j, i = np.argwhere(mask.any(axis=-1))[0]
    return f"x={i}, y={j}"


# How the read policies are named in messages: the caller says where each came from (a command-line
# flag, a scene key); the library itself knows neither. The pixel limit has no scene key: every
# command that reads a panorama takes --max-pixels (and $IBLBAKE_MAX_PIXELS).
POLICY_NAMES = {"max_pixels": "--max-pixels", "nonfinite": "nonfinite", "negative": "negative",
                "transfer": "transfer", "primaries": "primaries", "layout": "layout"}


def read_policies(nonfinite: str, negative: str, transfer: str = "auto", primaries: str = "auto",
                  layout: str = "auto") -> dict:
    """What a bake keys on besides the file's content: the read policies that change pixels (the
    new ones only where not their default, so keys made before them still hold)."""
    out = {"nonfinite": nonfinite, "negative": negative}
    if layout != "auto":
        out["layout"] = layout
    if transfer != "auto":
        out["transfer"] = transfer
    if primaries == "convert":              # auto and keep read the same pixels
        out["primaries"] = primaries
    return out


def _decode_transfer(data, spec, transfer: str, path: str, warnings: list, name: dict):
    """Integer (LDR) texels to linear; float texels as stored unless told they are sRGB."""
    from iblbake.io.color import srgb_decode

    integer = str(spec.format) in ("uint8", "uint16", "int8", "int16", "uint32", "int32")
    declared = str(spec.getattribute("oiio:ColorSpace") or "").lower()
    how = transfer
    gamma = None
    if transfer == "auto":
        if not integer or "linear" in declared or declared in ("lin_rec709", "scene_linear", "raw"):
            how = "linear"
        elif declared.startswith("gamma"):
            try:
                gamma, how = float(declared[5:].replace("_", ".")), "gamma"
            except ValueError:
                how = "srgb"
        else:
            how = "srgb"
    if integer:
        warnings.append(f"{path}: an LDR ({spec.format}) panorama: read as {how if how != 'gamma' else f'gamma {gamma:g}'}"
                        f" to linear, its highlights clipped at 1 (a sun or lamp far too dim for lighting); "
                        f"use an HDR panorama (EXR, .hdr), or {name['transfer']} to change the decoding")
    if how == "srgb":
        return srgb_decode(data).astype(np.float32)
    if how == "gamma":
        return np.power(np.maximum(data, 0.0), gamma).astype(np.float32)
    return data


# host bytes of reading a panorama, per pixel: the decoded float channels and their float32
# view (8 bytes a channel), the RGB image and the copy the policies repair, with their masks
DECODE_BYTES_PER_CHANNEL, DECODE_BYTES_PER_PIXEL = 8, 32


def _check_decode_fits(path, w: int, h: int, nc: int) -> None:
    """From the header, before decoding: an InputError saying how much memory the image needs
    where that is more than the process may still allocate (a limit under max_pixels' too)."""
    from iblbake.io.memory import host_bytes_available
    need = w * h * (DECODE_BYTES_PER_CHANNEL * nc + DECODE_BYTES_PER_PIXEL)
    free = host_bytes_available()
    if free is not None and need > free:
        raise InputError(f"{path}: {w}x{h} with {nc} channels needs about {need / 2**30:.3g} GiB to read, more than "
                         f"the {max(free, 0) / 2**30:.3g} GiB this process may still allocate; give a smaller image")


def read_panorama(path, *, max_pixels: int | None = None, nonfinite: str = "error", negative: str = "keep",
                  transfer: str = "auto", primaries: str = "auto",
                  names: dict | None = None) -> tuple[np.ndarray, ImageInfo]:
    """Read an HDR image as float32 RGB (H, W, 3) and validate it (see module doc). `names` maps
    max_pixels / nonfinite / negative to what messages call them (a flag or a scene key)."""
    name = {**POLICY_NAMES, **(names or {})}
    oiio = _oiio()
    path = str(path)
    limit = max_pixels_default() if max_pixels is None else int(max_pixels)
    if not os.path.exists(path):
        raise InputError(f"{path}: no such file")
    if os.path.isdir(path):
        raise InputError(f"{path}: is a folder, not an image")
    from iblbake.io import reads          # before OpenImageIO opens it: a FIFO blocks, a device never ends
    reads.check_file(path, reads.image_bytes(limit), "a panorama",
                     f" of at most {limit} pixels ({name['max_pixels']} or IBLBAKE_MAX_PIXELS raises it)")
    with oiio_name(path) as shown:        # the link a name that is not UTF-8 needs
        inp = oiio.ImageInput.open(shown)
        if inp is None:
            msg = " ".join(oiio.geterror().split()) or "unknown format"
            raise InputError(f"{path}: cannot read as an image ({msg[:200]}); expected EXR, HDR, PFM or float TIFF")
        try:
            spec = inp.spec()
            w, h, nc = spec.width, spec.height, spec.nchannels
            if w < 1 or h < 1 or nc < 1:
                raise InputError(f"{path}: empty image ({w}x{h}, {nc} channels)")
            if w * h > limit:
                raise InputError(
                    f"{path}: {w}x{h} is {w * h} pixels, over the limit of {limit}; "
                    f"raise it with {name['max_pixels']} or IBLBAKE_MAX_PIXELS if this is intended")
            _check_decode_fits(path, w, h, nc)
            names = tuple(spec.channelnames)
            chroma = spec.getattribute("chromaticities")
            data = inp.read_image(0, 0, 0, nc, oiio.FLOAT)
            if data is None or not isinstance(data, np.ndarray):
                msg = " ".join(inp.geterror().split()) or "pixel data unreadable"
                raise InputError(f"{path}: corrupt or truncated image ({msg[:200]})")
            fmt = str(spec.format)
            warnings = []
            data = _decode_transfer(np.asarray(data, dtype=np.float32), spec, transfer, path, warnings, name)
        finally:
            inp.close()
    # OIIO may report partial-read errors without failing read_image.
    err = oiio.geterror()
    if err and ("corrupt" in err.lower() or "truncat" in err.lower() or "error" in err.lower()):
        raise InputError(f"{path}: corrupt or truncated image ({' '.join(err.split())[:200]})")
    data = np.asarray(data, dtype=np.float32).reshape(h, w, nc)
    rgb = _to_rgb(data, names)

    info = ImageInfo(path=path, width=w, height=h, channels_in=names, format=fmt,
                     sha256=file_sha256(path), nonfinite_policy=nonfinite, negative_policy=negative)
    info.warnings += warnings
    if chroma is not None:
        info.chromaticities = tuple(float(c) for c in chroma)
        if not np.allclose(info.chromaticities, REC709, atol=2e-3):
            shown = tuple(round(c, 4) for c in chroma)
            if primaries == "convert":
                from iblbake.io.color import to_rec709
                m = to_rec709(info.chromaticities).astype(np.float32)
                rgb = np.ascontiguousarray(rgb @ m.T)
                info.warnings.append(f"{path}: converted from its chromaticities {shown} to Rec.709/D65 "
                                     f"(Bradford adaptation)")
            elif primaries == "auto":          # keep: the user knows, and is not told again
                info.warnings.append(f"{path}: declares non-Rec.709 chromaticities {shown}; pixels are used as "
                                     f"stored (Rec.709 assumed; {name['primaries']} convert converts them, "
                                     f"{name['primaries']} keep keeps them without this warning)")
    return validate_texels(rgb, info, names=name), info


def validate_texels(rgb: np.ndarray, info: ImageInfo, names: dict | None = None) -> np.ndarray:
    """Apply info's nonfinite and negative policies to rgb (..., 3): fail in one line, or repair
    and count (into info)."""
    name = {**POLICY_NAMES, **(names or {})}
    path, nonfinite, negative = info.path, info.nonfinite_policy, info.negative_policy
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(rgb) <= MAX_ABS_VALUE)   # NaN, +-Inf, and values no float32 sum survives
    info.nonfinite = int(bad.sum())
    if info.nonfinite:
        if nonfinite == "error":
            raise InputError(
                f"{path}: {info.nonfinite} non-finite (NaN/Inf or beyond +-1e30) values, first at "
                f"{_first_position(bad)}; repair with {name['nonfinite']} zero or {name['nonfinite']} clamp")
        if nonfinite == "zero":
            rgb[bad] = 0.0
        else:  # clamp: too large positive values to the largest valid value, the rest to 0
            good = rgb[~bad]
            top = float(good.max()) if good.size else 0.0
            with np.errstate(invalid="ignore"):
                rgb[bad & (rgb > 0)] = max(top, 0.0)
            rgb[bad & ~(rgb > 0)] = 0.0
        info.warnings.append(f"{path}: repaired {info.nonfinite} non-finite values ({name['nonfinite']} {nonfinite})")
    neg = rgb < 0
    info.negative = int(neg.sum())
    if info.negative:
        info.negative_min = float(rgb.min())
        info.negative_share = float(-rgb[neg].sum(dtype=np.float64) / max(np.abs(rgb).sum(dtype=np.float64), 1e-300))
        if negative == "keep" and not info.negative_tiny:      # counted and reported, as documented
            info.warnings.append(
                f"{path}: {info.negative} negative values kept as stored (min {info.negative_min:.3g}, "
                f"{100 * info.negative_share:.3g}% of the panorama's energy): they subtract light; "
                f"{name['negative']} clamp sets them to 0, {name['negative']} error refuses them")
        if negative == "error":
            raise InputError(
                f"{path}: {info.negative} negative values (min {info.negative_min:.3g}), first at "
                f"{_first_position(neg)}; use {name['negative']} keep or {name['negative']} clamp")
        if negative == "clamp":
            np.maximum(rgb, 0.0, out=rgb)
    return np.ascontiguousarray(rgb)


def _to_rgb(data: np.ndarray, names: tuple) -> np.ndarray:
    nc = data.shape[-1]
    upper = [n.upper().split(".")[-1] for n in names]
    if all(c in upper for c in "RGB"):
        idx = [upper.index(c) for c in "RGB"]
        return data[..., idx].copy()
    if nc >= 3:
        return data[..., :3].copy()
    # Y, YA, or a single/two-channel image: the first channel is luminance.
    return np.repeat(data[..., :1], 3, axis=-1)


# Cache entries are written and read far more often than they are copied: uncompressed EXR
# writes a 9-level chain 2.8x faster than zip (measured 18 ms against 50 ms for 8.4 MB), at 2.4x
# the size. Frames users keep are zip.
CACHE_COMPRESSION = "none"


def write_exr(path, image, *, half: bool = False, channels=("R", "G", "B"), attributes=None,
              compression: str = "zip", batch=None):
    """Write a linear float (or half) EXR atomically (with `batch`'s other outputs, where given),
    named iblbake's in its Software attribute."""
    from iblbake.io.guard import mark
    oiio = _oiio()
    image = np.ascontiguousarray(image, dtype=np.float32)
    if image.ndim == 2:
        image = image[..., None]
    h, w, nc = image.shape
    spec = oiio.ImageSpec(w, h, nc, oiio.HALF if half else oiio.FLOAT)
    spec.channelnames = tuple(channels[:nc])
    spec.attribute("compression", compression)
    spec.attribute("Software", mark())
    for k, v in (attributes or {}).items():
        spec.attribute(k, v)
    with atomic_path(path, batch) as tmp, oiio_name(tmp) as name:
        out = oiio.ImageOutput.create(name)
        if out is None:
            raise IblbakeError(f"{path}: no writer for this format ({oiio.geterror()})")
        ok = out.open(name, spec) and out.write_image(image)
        closed = out.close()            # the last tiles and the offset table are written here
        err = out.geterror() or oiio.geterror()
        if not (ok and closed) or err:
            raise IblbakeError(f"{path}: write failed ({_write_reason(tmp, image.nbytes, err)})")


def _write_reason(tmp, nbytes: int, err: str) -> str:
    """Why OpenImageIO's writer failed, in words: its messages do not carry the OS error, so a
    full disk (less free than the pixels take, or 64 KiB) is said as the OS would say it."""
    import shutil
    try:
        free = shutil.disk_usage(Path(tmp).parent).free
    except OSError:
        free = None
    text = " ".join(err.split())[:200] or "the writer gave no reason"
    if free is not None and free < max(nbytes, 1 << 16):
        return f"No space left on device: {free} bytes free; {text}"
    return text


def png_bytes(image_u8, colour: bool = True) -> bytes:
    """An 8-bit grey, RGB or RGBA PNG in memory (so that every byte of it is written by
    atomic.write_bytes, which checks each write: OpenImageIO's PNG writer reported no error on a
    full disk and left an empty file), named iblbake's in a tEXt Software chunk. colour: declared
    sRGB (sRGB and gAMA chunks); RGBD and other non-colour bytes declare nothing."""
    import io

    from PIL import Image, PngImagePlugin

    from iblbake.io.guard import mark
    image_u8 = np.ascontiguousarray(image_u8, dtype=np.uint8)
    if image_u8.ndim == 3 and image_u8.shape[2] == 1:
        image_u8 = image_u8[..., 0]
    info = PngImagePlugin.PngInfo()
    info.add_text("Software", mark())
    if colour:
        info.add(b"sRGB", b"\x00")
        info.add(b"gAMA", (45455).to_bytes(4, "big"))
    buf = io.BytesIO()
    Image.fromarray(image_u8).save(buf, format="PNG", compress_level=6, pnginfo=info)
    return buf.getvalue()


def write_png(path, image_u8, batch=None):
    """Write an 8-bit RGB(A) PNG atomically (with `batch`'s other outputs, where given)."""
    from iblbake.io.atomic import write_bytes
    write_bytes(path, png_bytes(image_u8), batch)


def read_exr(path, channels=None) -> np.ndarray:
    """Read back an EXR written by iblbake (cache files), float32 (H, W, C); `channels`: those
    names in that order (OpenImageIO puts R, G, B, A and Z before the layers, whatever order they
    were written in)."""
    inp = _open_exr(path)
    try:
        image = _exr_pixels(inp, path, inp.spec().nchannels)
        if channels is None:
            return image
        names = list(inp.spec().channelnames)
        missing = [c for c in channels if c not in names]
        if missing:
            raise InputError(f"{path}: no channel {missing[0]} (it holds {', '.join(names)}); write it again")
        return image[..., [names.index(c) for c in channels]]
    finally:
        inp.close()


def read_exrs_back_to_back(paths) -> list:
    """EXRs written by iblbake (a cache entry's levels) read into one float32 array, back to back,
    RGB: their (h, w, 3) views of it (each file's size from its header, read first)."""
    inputs = []
    try:
        for path in paths:
            inp = _open_exr(path)
            inputs.append((path, inp))
            if inp.spec().nchannels < 3:
                raise InputError(f"{path}: {inp.spec().nchannels} channels, not RGB")
        flat = np.empty(3 * sum(inp.spec().width * inp.spec().height for _, inp in inputs), np.float32)
        views, o = [], 0
        for path, inp in inputs:
            spec = inp.spec()
            view = flat[o:o + 3 * spec.width * spec.height].reshape(spec.height, spec.width, 3)
            view[...] = _exr_pixels(inp, path, 3)
            views.append(view)
            o += view.size
        return views
    finally:
        for _, inp in inputs:
            inp.close()


def _open_exr(path):
    oiio = _oiio()
    with oiio_name(path) as name:       # an open EXR input keeps its file: the link may go
        inp = oiio.ImageInput.open(name)
    if inp is None:
        raise InputError(f"{path}: cannot read ({' '.join(oiio.geterror().split())[:200]})")
    return inp


def _exr_pixels(inp, path, nchannels: int) -> np.ndarray:
    """The first nchannels of an open image, float32 (H, W, nchannels)."""
    spec = inp.spec()
    data = inp.read_image(0, 0, 0, nchannels, _oiio().FLOAT)
    if not isinstance(data, np.ndarray):
        raise InputError(f"{path}: corrupt or truncated EXR")
    return np.asarray(data, dtype=np.float32).reshape(spec.height, spec.width, nchannels)


def display_path(path) -> str:
    try:
        return str(Path(path).relative_to(Path.cwd()))
    except ValueError:
        return str(path)
