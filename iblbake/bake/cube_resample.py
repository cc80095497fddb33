"""A cube map resampled to an equirect panorama by exact texel overlaps: each equirect texel the
mean of the cube map over its solid angle, the cube map read as the box texels it stores.

In the equal-area coordinates (phi, y) = (atan2(x, z), cos theta) solid angle is area
(dOmega = dphi dy): an equirect column is a strip phi in [phi_lo, phi_hi] and a texel of it the
band y in [y_{j+1}, y_j]. For every cube texel a strip meets:
- the part of the texel inside the strip (a "piece") is a convex polygon: the texel's square in
  face coordinates clipped by the two meridian planes of the strip's edges (each a line on the
  face); its edges are arcs of great circles on the sphere;
- its area below a parallel y = Y is, by Green's theorem in (phi, y), C(Y) = +-(sum over its
  edges of the integral of min(y(phi), Y) dphi). Along a great circle of normal n,
  y(phi) = -c sgn(n_y) / sqrt(n_y^2 + c^2) with c = n_x sin phi + n_z cos phi, and
  F = atan((n_x d_z - n_z d_x) / n_y) at the circle's point d is an antiderivative of y dphi,
  continuous all round the circle (so the integral of y along an arc is F(q) - F(p), taken as
  one atan2 of the two, with no square-root cancellation); min(y, Y) differs from y only on the
  arc's parts above Y, cut where the circle crosses the parallel. A meridian edge contributes
  nothing (dphi = 0);
- a piece holding a pole (a top or bottom face's centre) has it as a vertex, which in (phi, y)
  is the segment y = +-1 across the piece;
- the piece's share of band j is C(y_j) - C(y_{j+1}), evaluated only at the band edges that cross
  the piece;
- the sphere's symmetries that keep both grids (quarter turns about +y, the mirrors x -> -x
  and y -> -y) make the northern half of one column in 16 (8) stand for the rest.
Exact up to float64 rounding: a constant stays constant to 1e-13 and every cube texel's energy is
kept to 1e-13 of itself.

kernels/cube_input.cl is the OpenCL version (in double), this module its float64 twin: plain
Python over the pieces, for tests and for small faces; large faces go through the kernel.
"""

from __future__ import annotations

import functools
import math

import numpy as np

# face coordinates (a, b) in [-1, 1] (a = 2s - 1, b = 2t - 1, t down) -> direction (x, y, z) =
# origin + a * along_a + b * along_b, the table of iblbake.core.conventions.dir_from_cube
FACE_AXES = (
    ((1, 0, 0), (0, 0, -1), (0, -1, 0)),      # +X: (1, -b, -a)
    ((-1, 0, 0), (0, 0, 1), (0, -1, 0)),      # -X: (-1, -b, a)
    ((0, 1, 0), (1, 0, 0), (0, 0, 1)),        # +Y: (a, 1, b)
    ((0, -1, 0), (1, 0, 0), (0, 0, -1)),      # -Y: (a, -1, -b)
    ((0, 0, 1), (1, 0, 0), (0, -1, 0)),       # +Z: (a, -b, 1)
    ((0, 0, -1), (-1, 0, 0), (0, -1, 0)),     # -Z: (-a, -b, -1)
)
POLE = 1e-12          # a vertex of a top or bottom face this close to its centre is the pole
MERIDIAN = 1e-14      # |n_y| of a great circle below this: a meridian, vertical in (phi, y)


def strip_edges(width: int, i: int):
    """(phi_lo, phi_hi) of equirect column i: u = 0.5 - phi / (2 pi), so phi falls with i."""
    return 2.0 * math.pi * (0.5 - (i + 1) / width), 2.0 * math.pi * (0.5 - i / width)


def row_edges(height: int) -> np.ndarray:
    """y = cos(theta) at the top edge of every row, and the bottom of the last: (height + 1,),
    as sin(pi (h - 2j) / 2h): exactly 0 at the equator and odd about it."""
    return np.sin(math.pi * (height - 2 * np.arange(height + 1)) / (2 * height))


def _line(face: int, phi: float, sense: float):
    """(c, ca, cb): the half-plane c + ca a + cb b >= 0 of the face on the side of the meridian
    plane of azimuth phi given by sense (+1: azimuths above phi, -1: below): d . m with
    m = (cos phi, 0, -sin phi) is r sin(phi_d - phi)."""
    m = (math.cos(phi) * sense, 0.0, -math.sin(phi) * sense)
    return tuple(sum(FACE_AXES[face][k][i] * m[i] for i in range(3)) for k in range(3))


def clip(poly: list, line) -> list:
    """Sutherland-Hodgman: the part of a convex polygon (list of (a, b)) where line >= 0."""
    c, ca, cb = line
    out = []
    n = len(poly)
    for k in range(n):
        p, q = poly[k], poly[(k + 1) % n]
        fp, fq = c + ca * p[0] + cb * p[1], c + ca * q[0] + cb * q[1]
        if fp >= 0:
            out.append(p)
        if (fp >= 0) != (fq >= 0):
            w = fp / (fp - fq)
            out.append((p[0] + w * (q[0] - p[0]), p[1] + w * (q[1] - p[1])))
    return out


def _cross(p, q):
    return (p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0])


def _dot(p, q):
    return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]


def _azimuth_step(p, q) -> float:
    """phi(q) - phi(p), the azimuth turned from p to q, in (-pi, pi]."""
    return math.atan2(p[2] * q[0] - p[0] * q[2], p[0] * q[0] + p[2] * q[2])


def _arc_integral(n, a, b) -> float:
    """The integral of y dphi along the arc a -> b of the great circle of normal n: F(b) - F(a)
    for F = atan(X / n_y), X = n_x d_z - n_z d_x, as one atan2 (atan u - atan v = atan2(u - v, 1 + uv))."""
    xa, xb = n[0] * a[2] - n[2] * a[0], n[0] * b[2] - n[2] * b[0]
    return math.atan2((xb - xa) * n[1], n[1] * n[1] + xa * xb)


class _Edge:
    """A great-circle arc p -> q (unit vectors) of a piece's boundary."""

    def __init__(self, p, q):
        self.p, self.q = p, q
        n = _cross(p, q)
        norm = math.sqrt(_dot(n, n))
        self.n = (n[0] / norm, n[1] / norm, n[2] / norm) if norm > 0 else (0.0, 0.0, 0.0)
        self.meridian = abs(self.n[1]) < MERIDIAN     # vertical in (phi, y): no area under it
        self.dphi = 0.0 if self.meridian else _azimuth_step(p, q)
        self.integral = 0.0 if self.meridian else _arc_integral(self.n, p, q)
        ys = [p[1], q[1]]
        if self.meridian:                               # y runs straight between its ends
            self.bottom, self.top = min(ys), max(ys)
            return
        top = (-self.n[1] * self.n[0], 1.0 - self.n[1] * self.n[1], -self.n[1] * self.n[2])   # y's projection
        for e in (top, (-top[0], -top[1], -top[2])):                                          # highest, lowest
            if _dot(_cross(p, e), self.n) > 0 and _dot(_cross(e, q), self.n) > 0:
                ys.append(e[1] / math.sqrt(_dot(e, e)))
        self.bottom, self.top = min(ys), max(ys)

    def on_arc(self, d) -> bool:
        return _dot(_cross(self.p, d), self.n) >= 0 and _dot(_cross(d, self.q), self.n) >= 0

    def excess(self, big_y: float) -> float:
        """Integral of (y - Y) dphi over the arc's parts above Y (oriented p -> q)."""
        if self.meridian or self.top <= big_y:
            return 0.0
        if self.bottom >= big_y:
            return self.integral - big_y * self.dphi
        n = self.n
        rho2 = n[0] * n[0] + n[2] * n[2]
        # the circle meets the parallel y = Y where n_x x + n_z z = -n_y Y and x^2 + z^2 = 1 - Y^2
        h2 = 1.0 - big_y * big_y - (n[1] * big_y) ** 2 / rho2
        h = math.sqrt(max(h2, 0.0) / rho2)
        t = -n[1] * big_y / rho2
        cuts = []
        for sign in (1.0, -1.0):
            d = (t * n[0] - sign * h * n[2], big_y, t * n[2] + sign * h * n[0])
            if self.on_arc(d):
                cuts.append((-_dot(self.p, d), d))
        cuts.sort(key=lambda c: c[0])                   # in order from p
        points = [self.p] + [d for _, d in cuts] + [self.q]
        above = self.p[1] > big_y if self.p[1] != big_y else not (self.q[1] > big_y)
        total = 0.0
        for a, b in zip(points[:-1], points[1:]):
            if above:
                total += _arc_integral(n, a, b) - big_y * _azimuth_step(a, b)
            above = not above
        return total


class Piece:
    """A texel's part inside a strip, from its polygon in face coordinates: C(Y), the solid angle
    below the parallel y = Y, and its y range."""

    def __init__(self, face: int, poly: list):
        o, ea, eb = FACE_AXES[face]
        verts = []                                  # unit vectors, None for the pole
        for a, b in poly:
            if face in (2, 3) and abs(a) < POLE and abs(b) < POLE:
                if verts and verts[-1] is None:
                    continue
                verts.append(None)
                continue
            d = [o[i] + a * ea[i] + b * eb[i] for i in range(3)]
            r = math.sqrt(_dot(d, d))
            verts.append((d[0] / r, d[1] / r, d[2] / r))
        if len(verts) > 1 and verts[0] is None and verts[-1] is None:
            verts.pop()
        self.edges, self.pole, self.pole_dphi = [], None, 0.0
        n = len(verts) if len(verts) >= 3 else 0     # fewer is a sliver of no area at the pole
        for k in range(n):
            p, q = verts[k], verts[(k + 1) % n]
            if p is None:            # the pole: the segment y = +-1 from the previous vertex's azimuth to the next's
                prev, nxt = verts[k - 1], q
                self.pole = 1.0 if face == 2 else -1.0
                self.pole_dphi = _azimuth_step(prev, nxt)
            elif q is not None and p != q:
                self.edges.append(_Edge(p, q))
        total = sum(e.integral for e in self.edges) + (self.pole or 0.0) * self.pole_dphi
        self.sign = 1.0 if total >= 0 else -1.0
        self.area = abs(total)
        ys = [e.bottom for e in self.edges] + [e.top for e in self.edges] + ([self.pole] if self.pole else [])
        self.bottom, self.top = (min(ys), max(ys)) if ys else (0.0, 0.0)

    def below(self, big_y: float) -> float:
        """C(Y): the solid angle of the piece where y < Y."""
        excess = sum(e.excess(big_y) for e in self.edges)
        if self.pole is not None and self.pole > big_y:
            excess += (self.pole - big_y) * self.pole_dphi
        return self.sign * (self.sign * self.area - excess)


def strip_pieces(face: int, size: int, phi_lo: float, phi_hi: float):
    """(row, column, Piece) for every texel of the face the strip phi in [phi_lo, phi_hi] meets."""
    lines = (_line(face, phi_lo, 1.0), _line(face, phi_hi, -1.0))
    wedge = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
    for line in lines:
        wedge = clip(wedge, line)
    if len(wedge) < 3:
        return
    edges = [2.0 * k / size - 1.0 for k in range(size + 1)]
    b_min, b_max = min(v[1] for v in wedge), max(v[1] for v in wedge)
    for row in range(max(0, int((b_min + 1) * size / 2)), min(size - 1, int((b_max + 1) * size / 2)) + 1):
        band = clip(clip(wedge, (-edges[row], 0.0, 1.0)), (edges[row + 1], 0.0, -1.0))
        if len(band) < 3:
            continue
        a_min, a_max = min(v[0] for v in band), max(v[0] for v in band)
        for col in range(max(0, int((a_min + 1) * size / 2)), min(size - 1, int((a_max + 1) * size / 2)) + 1):
            square = [(edges[col], edges[row]), (edges[col + 1], edges[row]), (edges[col + 1], edges[row + 1]),
                      (edges[col], edges[row + 1])]
            for line in lines:
                square = clip(square, line)
            if len(square) >= 3:
                piece = Piece(face, square)
                if piece.area > 0:
                    yield row, col, piece


def overlaps(size: int, width: int, height: int, i: int, north: bool = False):
    """(face, row, column, j, solid angle) of every cube texel overlapping an equirect texel of
    column i, for an equirect panorama width x height; with `north`, only the northern rows
    (j < height / 2), which with the mirror y -> -y give the rest."""
    ys = row_edges(height)
    last = height // 2 - 1 if north else height - 1
    phi_lo, phi_hi = strip_edges(width, i)
    for face in range(6):
        if north and face == 3:
            continue
        for row, col, piece in strip_pieces(face, size, phi_lo, phi_hi):
            if north and piece.top <= 0.0:
                continue
            j_top = min(last, int(math.acos(min(1.0, piece.top)) * height / math.pi))
            j_bottom = min(last, int(math.acos(max(0.0 if north else -1.0, piece.bottom)) * height / math.pi))
            upper = piece.area
            for j in range(j_top, j_bottom + 1):
                lower = piece.below(ys[j + 1]) if ys[j + 1] > piece.bottom else 0.0
                if upper != lower:
                    yield face, row, col, j, upper - lower
                upper = lower


def columns_of(size: int, i: int) -> list:
    """The columns of a 4 size wide panorama that column i (< (size + 1) / 2) stands for under
    the symmetries, as (column, symmetry index without the y mirror): quarter turns shift by
    size columns, the mirror x -> -x takes column i to width - 1 - i; the middle column of an
    odd size is its own mirror image."""
    w = 4 * size
    mirrors = 1 if 2 * i + 1 == size else 2
    return [(((w - 1 - i) if m else i) - k * size) % w for k in range(4) for m in range(mirrors)], mirrors


def image_texel(sym: np.ndarray, g: int, face: int, row: int, col: int, size: int):
    """(face, row, column) of a texel's image under symmetry g (see symmetries)."""
    f2, code = sym[g, face]
    r, c = (col, row) if code & 4 else (row, col)
    return f2, (size - 1 - r if code & 1 else r), (size - 1 - c if code & 2 else c)


def cube_to_equirect(faces: np.ndarray, dtype=np.float32) -> np.ndarray:
    """The equirect panorama (4s x 2s: its texels at the equator as wide as the faces' at their
    centres) whose every texel is the mean of the cube map (6, s, s, c) over its solid angle.
    As the kernel: each of the first (s + 1) / 2 columns' northern overlaps, added to the 16 (8)
    columns and halves it stands for."""
    s = faces.shape[1]
    h, w = 2 * s, 4 * s
    ys = row_edges(h)
    sym = symmetries()
    out = np.zeros((h, w, faces.shape[-1]), np.float64)
    f = faces.astype(np.float64)
    for i in range((s + 1) // 2):
        cols, mirrors = columns_of(s, i)
        for face, row, col, j, area in overlaps(s, w, h, i, north=True):
            for k in range(4):
                for m in range(mirrors):
                    for v in range(2):
                        out[h - 1 - j if v else j, cols[k * mirrors + m]] += \
                            area * f[image_texel(sym, (k * 2 + m) * 2 + v, face, row, col, s)]
    out /= ((ys[:-1] - ys[1:]) * (2.0 * math.pi / w))[:, None, None]
    return out.astype(dtype)


@functools.lru_cache(maxsize=1)
def symmetries() -> np.ndarray:
    """(16, 6, 2) int32 for the kernel: for the sphere's symmetries that keep the cube and the
    equirect grid (k quarter turns about +y, the mirror x -> -x, the mirror y -> -y, index
    (k * 2 + m) * 2 + v), the face each face's texels land on and how (row, column) move: bit 4
    swapped, then bit 1 row flipped, bit 2 column flipped. Found from the cube-map convention on
    a 3 x 3 face."""
    from iblbake.core import conventions

    s = 3
    c = (np.arange(s) + 0.5) / s
    t, u = np.meshgrid(c, c, indexing="ij")
    rows, cols = np.meshgrid(np.arange(s), np.arange(s), indexing="ij")
    out = np.zeros((16, 6, 2), np.int32)
    for k in range(4):
        for m in range(2):
            for v in range(2):
                for face in range(6):
                    x, y, z = np.moveaxis(conventions.dir_from_cube(face, u, t), -1, 0)
                    y, x = (-y if v else y), (-x if m else x)
                    for _ in range(k):
                        x, z = z, -x                     # a quarter turn: phi + pi / 2
                    f2, u2, t2 = conventions.cube_from_dir(np.stack([x, y, z], axis=-1))
                    r2, c2 = np.floor(t2 * s).astype(int), np.floor(u2 * s).astype(int)
                    for code in range(8):
                        r, cc = (cols, rows) if code & 4 else (rows, cols)
                        r, cc = (s - 1 - r if code & 1 else r), (s - 1 - cc if code & 2 else cc)
                        if (r == r2).all() and (cc == c2).all():
                            out[(k * 2 + m) * 2 + v, face] = (f2.flat[0], code)
    return out


def device_supports(rt) -> bool:
    """Whether the runtime's device computes in double (cl_khr_fp64), as the kernel needs."""
    return "cl_khr_fp64" in rt.info.device.extensions


def cube_to_equirect_cl(rt, faces: np.ndarray) -> np.ndarray:
    """cube_to_equirect on the OpenCL device (kernels/cube_input.cl): a work-item per column on
    a GPU; on a CPU 8 per core, each taking every 8 x cores-th column with one column's scratch
    (fresh memory costs this CPU 0.45 ms/MB, and a scratch per column was 0.2 GB at face 1024)."""
    s = faces.shape[1]
    h, w = 2 * s, 4 * s
    columns = (s + 1) // 2
    items = columns if rt.info.kind != "CPU" else min(columns, 8 * rt.info.device.max_compute_units)
    out = rt.empty(h * w * 12)
    scratch = rt.empty(items * 8 * h * 3 * 8)
    k = rt.kernel("cube_input.cl", "cube_to_equirect")
    rt.run(k, (items,), (1,) if rt.info.kind == "CPU" else None,
           rt.to_device(np.ascontiguousarray(faces[..., :3], np.float32)), rt.to_device(symmetries()),
           np.int32(s), np.int32(w), np.int32(h), scratch, out)
    return rt.read_mapped(out, (h, w, 3))
