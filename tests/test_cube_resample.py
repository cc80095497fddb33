"""Exact cube -> equirect resampling (iblbake/bake/cube_resample.py, kernels/cube_input.cl):
the overlaps of cube texels and equirect texels against closed forms that share none of its
code: a cube texel's solid angle (the atan formula of its corners), an equirect texel's
(dphi dy), a side-face texel's part inside a strip (a rectangle on the face), and against dense
sampling of the overlaps; a constant map at face 1024; the symmetric assembly against the
plain per-column sum; the kernel against the twin."""

import math

import numpy as np
import pytest

from iblbake.bake import cube_resample as cr
from iblbake.core import conventions


def all_overlaps(s):
    w, h = 4 * s, 2 * s
    rows = [(i, *o) for i in range(w) for o in cr.overlaps(s, w, h, i)]
    return np.array(rows, dtype=np.float64)          # i, face, row, col, j, area


def rect_solid_angle(a0, a1, b0, b1):
    """Solid angle of [a0, a1] x [b0, b1] on the face plane at distance 1 (corner formula)."""
    f = lambda a, b: math.atan2(a * b, math.sqrt(1 + a * a + b * b))  # noqa: E731
    return f(a1, b1) - f(a0, b1) - f(a1, b0) + f(a0, b0)


@pytest.mark.parametrize("s", [1, 2, 5, 6, 24])
def test_every_cube_texel_and_every_equirect_texel_is_covered_exactly(s):
    """Face 24 holds a triple point: the texel edge a = 1/2 on the top face, the meridian of
    120 degrees and the parallel of latitude 60 degrees meet in one point, a piece's corner on a
    row's edge (clipped great-circle arcs cut there lost 10% of an equirect texel)."""
    ov = all_overlaps(s)
    face, row, col = ov[:, 1].astype(int), ov[:, 2].astype(int), ov[:, 3].astype(int)
    # float64 rounding of terms as large as the strip (1/s of a face) for pieces 1/s^2 of one:
    # measured 5.6e-15 (texels) and 3.8e-15 (pixels) at s = 6, 1.2e-13 and 6.3e-14 at s = 24
    bound = 1e-15 + 3e-16 * s * s
    per_texel = np.zeros((6, s, s))
    np.add.at(per_texel, (face, row, col), ov[:, 5])
    assert np.abs(per_texel / conventions.cube_texel_solid_angles(s)[None] - 1).max() < bound
    per_pixel = np.zeros((2 * s, 4 * s))
    np.add.at(per_pixel, (ov[:, 4].astype(int), ov[:, 0].astype(int)), ov[:, 5])
    ys = cr.row_edges(2 * s)
    omega = (ys[:-1] - ys[1:])[:, None] * (2 * math.pi / (4 * s))
    assert np.abs(per_pixel / omega - 1).max() < bound
    assert ov[:, 5].min() > -bound * omega.min()          # no negative parts beyond rounding


def test_a_side_texel_inside_a_strip_is_a_rectangle_on_the_face():
    """Face +Z: a = x / z = tan(phi), so a strip is a < a_hi, a > a_lo on the face, and a texel's
    part in it the rectangle [max(a_lo, a0), min(a_hi, a1)] x [b0, b1]."""
    s = 6
    ov = all_overlaps(s)
    worst = 0.0
    for i in range(s + 1, 3 * s - 1):                 # strips crossing +Z (phi within pi/4 of 0)
        lo, hi = cr.strip_edges(4 * s, i)
        sel = (ov[:, 0] == i) & (ov[:, 1] == 4)
        for row in range(s):
            for col in range(s):
                a0, a1 = max(math.tan(lo), 2 * col / s - 1), min(math.tan(hi), 2 * (col + 1) / s - 1)
                want = rect_solid_angle(a0, a1, 2 * row / s - 1, 2 * (row + 1) / s - 1) if a1 > a0 else 0.0
                got = ov[sel & (ov[:, 2] == row) & (ov[:, 3] == col), 5].sum()
                worst = max(worst, abs(got - want) / rect_solid_angle(-1, 1, -1, 1) * 6)
    assert worst < 2e-15                                                                         # measured 5e-16


@pytest.mark.slow
def test_overlaps_match_dense_sampling():
    """600 x 600 points of equal solid angle in each of a few equirect texels (a pole, the face
    corners' latitude, the equator), each in the cube texel it falls in."""
    s, n = 5, 600
    w, h = 4 * s, 2 * s
    ys = cr.row_edges(h)
    worst = 0.0
    for i in (0, 3, 7, 10):
        got = {}
        for face, row, col, j, a in cr.overlaps(s, w, h, i):
            got[(face, row, col, j)] = got.get((face, row, col, j), 0.0) + a
        lo, hi = cr.strip_edges(w, i)
        phi = lo + (hi - lo) * (np.arange(n) + 0.5) / n
        for j in (0, 2, 4, 9):
            y = ys[j + 1] + (ys[j] - ys[j + 1]) * (np.arange(n) + 0.5) / n
            p, yy = np.meshgrid(phi, y)
            r = np.sqrt(1 - yy ** 2)
            f, u, t = conventions.cube_from_dir(np.stack([r * np.sin(p), yy, r * np.cos(p)], -1))
            key = np.stack([f, np.minimum((t * s).astype(int), s - 1), np.minimum((u * s).astype(int), s - 1)], -1)
            texels, counts = np.unique(key.reshape(-1, 3), axis=0, return_counts=True)
            omega = (hi - lo) * (ys[j] - ys[j + 1])
            want = {(*map(int, k), j): c / n / n * omega for k, c in zip(texels, counts)}
            mine = {k: v for k, v in got.items() if k[3] == j}
            for k in set(want) | set(mine):
                worst = max(worst, abs(want.get(k, 0.0) - mine.get(k, 0.0)) / omega)
    assert worst < 4e-4                    # the sampling's own error: measured 1.1e-4 of the equirect texel


@pytest.mark.parametrize("s", [1, 3, 4])
def test_symmetric_assembly_is_the_plain_sum(s):
    """The twin computes (s + 1) / 2 columns' northern halves and adds them to the 16 images;
    the plain per-column sum over every overlap gives the same panorama."""
    w, h = 4 * s, 2 * s
    f = np.random.default_rng(s).random((6, s, s, 3))
    plain = np.zeros((h, w, 3))
    for row in all_overlaps(s):
        i, face, r, c, j, a = row
        plain[int(j), int(i)] += a * f[int(face), int(r), int(c)]
    ys = cr.row_edges(h)
    plain /= ((ys[:-1] - ys[1:]) * (2 * math.pi / w))[:, None, None]
    assert np.abs(cr.cube_to_equirect(f, dtype=np.float64) - plain).max() < 2e-14           # measured 5e-15


@pytest.mark.parametrize("s", [1, 2, 3, 5, 8, 24])
def test_kernel_matches_twin(rt, s):
    f = np.random.default_rng(10 + s).exponential(1.0, (6, s, s, 3)).astype(np.float32)
    twin = cr.cube_to_equirect(f, dtype=np.float64)
    assert np.abs(cr.cube_to_equirect_cl(rt, f) / twin - 1).max() < 1.2e-7   # float32 storage (measured 6e-8)


def test_a_constant_cube_map_stays_constant_at_face_1024(rt):
    """Every equirect texel the mean of a constant: 1 to float32 rounding (measured: exactly 1;
    the clipped-arc code this replaced left 272 texels up to 2.7e-6 off, where a parallel cut
    close to a piece's corner)."""
    eq = cr.cube_to_equirect_cl(rt, np.ones((6, 1024, 1024, 3), np.float32))
    assert eq.shape == (2048, 4096, 3)
    assert np.abs(eq - 1.0).max() <= 1.2e-7
