"""Colour of the panoramas read in: the sRGB transfer's decode (its encode, for frames out, is
core.tonemap.srgb_encode), and RGB primaries to Rec.709/D65 through XYZ with a Bradford chromatic adaptation of the white point (the method
and matrix as in Lindbloom's "Chromatic Adaptation" and "RGB/XYZ Matrices")."""

from __future__ import annotations

import numpy as np

# CIE xy of the red, green, blue primaries and the white point (OpenEXR's chromaticities order)
REC709 = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)

# cone-response matrix of the Bradford transform (Lam 1985, as Lindbloom lists it)
BRADFORD = np.array([[0.8951, 0.2664, -0.1614],
                     [-0.7502, 1.7135, 0.0367],
                     [0.0389, -0.0685, 1.0296]])


def srgb_decode(v):
    """IEC 61966-2-1 sRGB code values in [0, 1] to linear (the inverse of tonemap.srgb_encode)."""
    v = np.asarray(v, np.float64)
    return np.where(v <= 0.04045, v / 12.92, np.power((np.maximum(v, 0.04045) + 0.055) / 1.055, 2.4))


def xy_to_xyz(x: float, y: float) -> np.ndarray:
    return np.array([x / y, 1.0, (1.0 - x - y) / y])


def rgb_to_xyz(chromaticities) -> np.ndarray:
    """The matrix from linear RGB with these primaries and white to CIE XYZ (white -> Y = 1)."""
    rx, ry, gx, gy, bx, by, wx, wy = chromaticities
    p = np.stack([xy_to_xyz(rx, ry), xy_to_xyz(gx, gy), xy_to_xyz(bx, by)], axis=1)
    return p * np.linalg.solve(p, xy_to_xyz(wx, wy))[None, :]


def bradford(src_white_xy, dst_white_xy) -> np.ndarray:
    """XYZ under one white to XYZ under another, by scaling Bradford's cone responses."""
    s, d = BRADFORD @ xy_to_xyz(*src_white_xy), BRADFORD @ xy_to_xyz(*dst_white_xy)
    return np.linalg.inv(BRADFORD) @ np.diag(d / s) @ BRADFORD


def to_rec709(chromaticities) -> np.ndarray:
    """The 3x3 matrix taking linear RGB in `chromaticities` to linear Rec.709 with a D65 white."""
    adapt = bradford(chromaticities[6:8], REC709[6:8])
    return np.linalg.inv(rgb_to_xyz(REC709)) @ adapt @ rgb_to_xyz(chromaticities)
