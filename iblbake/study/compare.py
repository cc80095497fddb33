"""Image comparison for CI checks: mean FLIP (NVIDIA's perceptual difference, LDR-FLIP for 8-bit
frames, HDR-FLIP for linear EXRs, through the flip-evaluator package) or the relative RMSE in
linear values, for whole frames or per cell of a sheet."""

from __future__ import annotations

import contextlib
import os

import numpy as np

from iblbake.core.metrics import relative_rmse
from iblbake.errors import InputError
from iblbake.io import images

METRICS = ("flip", "rmse")


def read_layout(path, reference) -> list:
    """The boxes (name, x, y, w, h) of a sheet layout (iblbake sheet --layout) for the reference's
    kind (the PNG's or the EXR's)."""
    import json

    from iblbake.io import reads
    try:
        cells = json.loads(reads.read_text(path, reads.JSON_BYTES, "a sheet layout"))["cells"]
        key = "exr_box" if str(reference).lower().endswith(".exr") else "png_box"
        return [(f"r{c['row']}c{c['column']} {c['label']}".strip(), *c[key]) for c in cells if c.get(key)]
    except InputError:
        raise
    except (ValueError, KeyError, TypeError) as e:
        raise InputError(f"{path}: not a sheet layout written by iblbake sheet --layout "
                         f"({' '.join(str(e).split())[:120]})") from None


@contextlib.contextmanager
def _native_stderr_held():
    """File descriptor 2 pointed at /dev/null while a native decoder runs (its messages come back
    through OpenImageIO's geterror, as one line of ours)."""
    import sys
    sys.stderr.flush()
    saved = os.dup(2)
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)


def read(path) -> tuple[np.ndarray, bool]:
    """(RGB float image, is HDR): a PNG as [0, 1] display values, anything else as linear."""
    p = str(path)
    if p.lower().endswith(".png"):
        import OpenImageIO as oiio

        from iblbake.io import reads
        if not os.path.exists(p):
            raise InputError(f"{p}: no such file")
        reads.check_file(p, reads.image_bytes(images.max_pixels_default()), "a PNG frame",
                         " (IBLBAKE_MAX_PIXELS raises it)")
        # ImageInput, not ImageBuf: a broken file's ImageBuf printed OpenImageIO's pending-error dump
        # on stdout (breaking --json), an assertion on stderr and its message over and over
        with images.oiio_name(p) as name:
            inp = oiio.ImageInput.open(name)
            if inp is None:
                msg = " ".join(dict.fromkeys(oiio.geterror().split("\n")))
                raise InputError(f"{p}: cannot read as a PNG ({' '.join(msg.split())[:160] or 'unknown format'})")
            try:
                spec = inp.spec()
                with _native_stderr_held():      # libpng prints its own line before OIIO reports it
                    px = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
                err = inp.geterror()
            finally:
                inp.close()
        if not isinstance(px, np.ndarray) or err:
            raise InputError(f"{p}: corrupt or truncated PNG ({' '.join(err.split())[:160] or 'no pixels'})")
        px = np.asarray(px, np.float32).reshape(spec.height, spec.width, spec.nchannels)
        if spec.nchannels < 3:
            px = np.repeat(px[..., :1], 3, axis=-1)
        return px[..., :3], False
    img, _ = images.read_panorama(p, nonfinite="zero")
    return img, True


def difference(a: np.ndarray, b: np.ndarray, hdr: bool, metric: str) -> float:
    """The metric of test image b against reference a (same shape, RGB)."""
    if metric == "rmse":
        return relative_rmse(b, a)
    import flip_evaluator as flip
    # flip-evaluator exits the process on arguments it dislikes: give it only what it accepts
    a = np.ascontiguousarray(np.clip(a, 0, None if hdr else 1), np.float32)
    b = np.ascontiguousarray(np.clip(b, 0, None if hdr else 1), np.float32)
    if a.shape[0] < 2 or a.shape[1] < 2:
        return float(np.abs(a - b).max())
    return float(flip.evaluate(a, b, "HDR" if hdr else "LDR", applyMagma=False)[1])


def compare(ref_path, test_path, metric: str = "flip", boxes=None) -> list:
    """[(name, error)]: the whole image, or each named box (name, x, y, w, h) of a sheet."""
    if metric not in METRICS:
        raise InputError(f"--metric {metric!r}: use one of {', '.join(METRICS)}")
    a, hdr_a = read(ref_path)
    b, hdr_b = read(test_path)
    if hdr_a != hdr_b:
        raise InputError(f"{test_path}: compare a PNG with a PNG and an EXR with an EXR ({ref_path} is "
                         f"{'linear' if hdr_a else '8-bit'})")
    if a.shape != b.shape:
        raise InputError(f"{test_path}: {b.shape[1]}x{b.shape[0]} against {ref_path}'s {a.shape[1]}x{a.shape[0]}; "
                         f"compare images of one size")
    if not boxes:
        return [("image", difference(a, b, hdr_a, metric))]
    out = []
    for name, x, y, w, h in boxes:
        if x < 0 or y < 0 or x + w > a.shape[1] or y + h > a.shape[0]:
            raise InputError(f"cell {name}: its box {w}x{h}+{x}+{y} is outside the {a.shape[1]}x{a.shape[0]} image")
        out.append((name, difference(a[y:y + h, x:x + w], b[y:y + h, x:x + w], hdr_a, metric)))
    return out
