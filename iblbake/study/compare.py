"""Image comparison for CI checks: mean FLIP (NVIDIA's perceptual difference, LDR-FLIP for 8-bit
frames, HDR-FLIP for linear EXRs, through the flip-evaluator package) or the relative RMSE in
linear values, for whole frames or per cell of a sheet."""

from __future__ import annotations

import numpy as np

from iblbake.core.metrics import relative_rmse
from iblbake.errors import InputError
from iblbake.io import images

METRICS = ("flip", "rmse")


def read(path) -> tuple[np.ndarray, bool]:
    """(RGB float image, is HDR): a PNG as [0, 1] display values, anything else as linear."""
    p = str(path)
    if p.lower().endswith(".png"):
        import OpenImageIO as oiio
        buf = oiio.ImageBuf(p)
        px = buf.get_pixels(oiio.FLOAT)
        if px is None or buf.has_error:
            raise InputError(f"{p}: cannot read as an image ({' '.join(buf.geterror().split())[:160]})")
        return np.asarray(px)[..., :3], False
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
