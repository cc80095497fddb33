"""Luminance and the image error metrics shared by the bakes, the renderer's noise estimate,
the accuracy study, tests and benchmarks (kernels/common.h: luminance() is the same weights)."""

from __future__ import annotations

import math

import numpy as np

# Rec. 709 / sRGB relative luminance Y of linear RGB (ITU-R BT.709-6, item 3.2; the primaries
# iblbake works in: docs/conventions.md)
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def luminance(rgb) -> np.ndarray:
    """Y of linear Rec. 709 RGB in the last axis (float64)."""
    return np.asarray(rgb, np.float64)[..., :3] @ LUMINANCE


def _rms(b) -> float:
    """The RMS a relative RMSE divides by (floored: an all-black reference gives no division by zero)."""
    return max(math.sqrt(np.mean(b ** 2)), 1e-300)


def relative_rmse(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(math.sqrt(np.mean((a - b) ** 2)) / _rms(b))


def bulk_relative_rmse(a, b, keep: float = 0.99):
    """relative_rmse over the fraction `keep` of rows (pixels) where a and b differ least, still
    over the RMS of all of b: at most relative_rmse, and far below it where a few pixels make most
    of the difference (a caustic's rare bright paths in a Monte Carlo frame)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if not len(a):
        return 0.0
    d2 = ((a - b) ** 2).reshape(len(a), -1).sum(1)
    kept = d2[d2 <= np.quantile(d2, keep)]
    return float(math.sqrt(kept.sum() / (len(kept) * (a.size // len(a)))) / _rms(b))


def object_mask(hdr) -> np.ndarray:
    """Pixels fully covered by objects (coverage 1 in every sample of the G-buffer)."""
    return hdr[..., 3] >= 1.0


def error_metrics(got, ref, mask, flip: bool = True) -> dict:
    """Over the mask, luminance-based except relative RMSE (RGB, metrics.relative_rmse):
    mean and max of |L - L_ref| / (L_ref + eps), eps = 1% of the mean reference luminance (so
    black pixels do not divide by zero), and mean HDR-FLIP over the mask."""
    g, r = got[..., :3][mask].astype(np.float64), ref[..., :3][mask].astype(np.float64)
    lg, lr = luminance(g), luminance(r)
    eps = 0.01 * max(lr.mean(), 1e-30)
    rel = np.abs(lg - lr) / (lr + eps)
    out = {"relative_rmse": relative_rmse(g, r), "mean_relative_error": float(rel.mean()),
           "max_relative_error": float(rel.max()), "flip": None}
    if flip:
        out["flip"] = hdr_flip(got, ref, mask)
    return out


def region_errors(got, ref, mask, regions) -> dict:
    """{region id: relative error of the region's mean colour} over the mask's pixels of each
    region id (an object index AOV: -1 none): |mean - mean_ref| summed over RGB over the reference
    mean's sum. A region's mean is what a viewer reads off a surface (how bright, what colour),
    and Monte Carlo noise in the reference averages out of it."""
    out = {}
    for rid in np.unique(regions[mask]):
        if rid < 0:
            continue
        sel = mask & (regions == rid)
        g = got[..., :3][sel].astype(np.float64).mean(0)
        r = ref[..., :3][sel].astype(np.float64).mean(0)
        out[int(rid)] = float(np.abs(g - r).sum() / max(r.sum(), 1e-30))
    return out


def mean_errors(got_mean, ref_mean) -> dict:
    """How far a region's mean colour is from the truth's, in absolute terms (issue 59): `ratio`
    of their luminances (15 is 15x too bright), `channel` the worst channel's |difference| over
    the truth's mean channel (a colour shift, a red wall turned blue), `absolute` the larger of
    |ratio - 1| and channel: what a bound on a region reads. `tint`: the channel's figure once the
    luminances match, the colour shift alone: a saturated colour's channel error is its
    luminance error times its largest channel over its mean (a sphere of [0.8, 0.15, 0.1] 10% too
    bright: channel 22%, tint 0)."""
    g, r = np.asarray(got_mean, np.float64), np.asarray(ref_mean, np.float64)
    ratio = float(luminance(g) / max(luminance(r), 1e-30))
    channel = float(np.abs(g - r).max() / max(r.mean(), 1e-30))
    tint = float(np.abs(g / max(ratio, 1e-30) - r).max() / max(r.mean(), 1e-30))
    return {"ratio": ratio, "channel": channel, "tint": tint, "absolute": max(abs(ratio - 1.0), channel)}


def region_absolute(got, ref, mask, regions, min_pixels: int = 1) -> dict:
    """{region id: mean_errors of the region's mean colour and its pixel count} over the mask's
    pixels of each region id (-1: none; or {name: boolean mask}, each its own region), regions of
    fewer than min_pixels left out, and those black in both (a metal's diffuse term)."""
    out = {}
    parts = regions if isinstance(regions, dict) else \
        {int(k): regions == k for k in np.unique(regions[mask]) if k >= 0}
    for k, where in parts.items():
        sel = mask & where
        if sel.sum() >= max(min_pixels, 1) and (ref[..., :3][sel].any() or got[..., :3][sel].any()):
            out[k] = {**mean_errors(got[..., :3][sel].astype(np.float64).mean(0),
                                    ref[..., :3][sel].astype(np.float64).mean(0)), "pixels": int(sel.sum())}
    return out


def _near(a, width: int) -> np.ndarray:
    """Pixels with a True pixel of `a` within `width` pixels (8-neighbour steps; none beyond the border)."""
    out = a.copy()
    h, w = a.shape
    for dy in range(-width, width + 1):
        for dx in range(-width, width + 1):
            out[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)] |= \
                a[max(-dy, 0):h + min(-dy, 0), max(-dx, 0):w + min(-dx, 0)]
    return out


def junctions(mask, regions, normals, crease: float = 0.5) -> np.ndarray:
    """Pixels of the mask next to (8 neighbours) a pixel of the mask on another region or whose
    shading normal turns away by more than acos(crease) (60 degrees): where a wall meets a floor, a
    wall or another object, whether they are one mesh or several; a sphere's neighbouring normals
    turn by a few degrees and are no junction. An object's outline over another counts too (no
    depth is read; the reference's G-buffer samples are the frame's, so its pixels are the same hits)."""
    h, w = mask.shape
    out = np.zeros_like(mask)
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = (slice(0, h - dy), slice(max(-dx, 0), w - max(dx, 0)))
        b = (slice(dy, h), slice(max(dx, 0), w - max(-dx, 0)))
        both = mask[a] & mask[b]
        split = both & ((regions[a] != regions[b]) | ((normals[a] * normals[b]).sum(-1) < crease))
        out[a] |= split
        out[b] |= split
    return out


def edge_over_interior(got, ref, mask, regions, normals, width: int = 1, clearance: int = 3):
    """A seam as one number: the luminance ratio got / ref (sums) over the junctions' band (pixels
    within width - 1 of a junction pixel, junctions()) over the same ratio in the interior (pixels
    over `clearance` pixels from any junction): 1 where the frame's edges are as bright, relative
    to the truth, as its surfaces' insides; a one-pixel band 1.3x too bright along walls whose
    insides are right reads 1.3 where the region means barely move. Sums, not per-pixel ratios:
    the reference's noise averages over the band. None where the band or the interior is empty."""
    j = junctions(mask, regions, normals)
    band = mask & _near(j, width - 1) if width > 1 else j
    interior = mask & ~_near(j, clearance)
    lg, lr = luminance(got), luminance(ref)
    if not band.any() or not interior.any() or lr[band].sum() <= 0 or lr[interior].sum() <= 0:
        return None
    return float((lg[band].sum() / lr[band].sum()) / max(lg[interior].sum() / lr[interior].sum(), 1e-30))


def halves(normals, where, min_pixels: int = 4) -> dict:
    """The halves of a region by the side its surface faces (its shading normal's sign along each
    world axis: '+x', '-y', ...): a sphere's six hemispheres, a box's faces grouped. Halves of
    fewer than min_pixels are left out."""
    out = {}
    for i, axis in enumerate("xyz"):
        for sign, name in ((1, "+"), (-1, "-")):
            sel = where & (sign * normals[..., i] > 0)
            if sel.sum() >= min_pixels:
                out[name + axis] = sel
    return out


def hdr_flip(got, ref, mask) -> float:
    import flip_evaluator

    a = np.ascontiguousarray(np.clip(ref[..., :3], 0, None), np.float32)
    b = np.ascontiguousarray(np.clip(got[..., :3], 0, None), np.float32)
    if min(a.shape[:2]) < 2:
        return float(np.abs(a - b)[mask].mean())
    err = flip_evaluator.evaluate(a, b, "HDR", applyMagma=False)[0]     # the per-pixel error map
    return float(np.asarray(err).reshape(mask.shape)[mask].mean())


def error_image(got, ref, mask, top: float = 0.5) -> np.ndarray:
    """An 8-bit heat map (magma) of |L - L_ref| / (L_ref + eps), 0 .. top; black off the mask."""
    from matplotlib import colormaps

    lg, lr = luminance(got[..., :3]), luminance(ref[..., :3])
    eps = 0.01 * max(float(lr[mask].mean()) if mask.any() else 0.0, 1e-30)
    rel = np.clip(np.abs(lg - lr) / (lr + eps) / top, 0, 1)
    rgb = (colormaps["magma"](rel)[..., :3] * 255 + 0.5).astype(np.uint8)
    rgb[~mask] = 0
    return rgb
