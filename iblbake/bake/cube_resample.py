"""A cube map resampled to an equirect panorama by exact texel overlaps: each equirect texel the
mean of the cube map over its solid angle, the cube map read as the box texels it stores.

An equirect column is a strip between two meridians, phi in [phi_lo, phi_hi], and a texel of it
the band between two parallels, y = cos theta in [y_{j+1}, y_j] (solid angle dphi dy). Every cube
texel the strip meets leaves a part inside it (a "piece"), and the piece's share of band j is
C(y_j) - C(y_{j+1}), C(Y) its solid angle below the parallel y = Y, evaluated only at the band
edges that cross it. On a face at distance 1, dOmega = dA / (1 + rho^2)^(3/2) (rho: distance
from the face's centre), and both kinds of face have closed forms:
- a side face (SidePiece): meridians are the lines a = const (phi = centre + atan a), so a piece
  is the rectangle [a0, a1] x [e0, e1] in the face's coordinates a and e = -b (up); the parallel
  y = Y = sin(beta) is the curve e = t sqrt(1 + a^2), t = tan(beta); the solid angle of
  [p, q] x [0, e] is F(q, e) - F(p, e), F(a, e) = atan(a e / sqrt(1 + a^2 + e^2)), and under
  the parallel's curve it is Y (atan q - atan p);
- the top and bottom faces (CapPiece): meridians are lines through the face's centre and
  parallels the circles rho = sqrt(1 - Y^2) / |Y| about it, so a piece is a convex polygon (the
  texel's square clipped by the strip's two lines), and its solid angle within a circle is a sum
  over its edges of the triangle the edge makes with the centre (Van Oosterom and Strackee's
  formula) where the edge runs inside the circle and of the circle's sector, (1 - |Y|) times its
  angle, where it runs outside.
Each is well conditioned (no point on the sphere is normalised, no arc cut), and every formula
reads Y from the table of row edges, so parts of a band add up to dphi (y_j - y_{j+1}) as the
table gives it: a constant stays constant to 1e-13 and every cube texel's energy is kept to
1e-12 of itself, at any face size. The sphere's symmetries that keep both grids (quarter turns
about +y, the mirrors x -> -x and y -> -y) make the northern half of one column in 16 (8) stand
for the rest.

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


def _cross2(p, q) -> float:
    return p[0] * q[1] - p[1] * q[0]


def _triangle(p, q) -> float:
    """Signed solid angle of the triangle (face centre, p, q) on a face, p and q in face
    coordinates: Van Oosterom and Strackee's tan(Omega / 2) = [o u v] / (|o||u||v| + (o.u)|v| +
    (o.v)|u| + (u.v)|o|) for o = (0, 0, 1), u = (p, 1), v = (q, 1)."""
    lu, lv = math.sqrt(1.0 + p[0] * p[0] + p[1] * p[1]), math.sqrt(1.0 + q[0] * q[0] + q[1] * q[1])
    return 2.0 * math.atan2(_cross2(p, q), lu * lv + lu + lv + 1.0 + p[0] * q[0] + p[1] * q[1])


def _angle(p, q) -> float:
    """Signed angle at the face centre from p to q."""
    return math.atan2(_cross2(p, q), p[0] * q[0] + p[1] * q[1])


def _fan_within(p, q, rho2: float, cap: float) -> float:
    """Signed solid angle of the triangle (face centre, p, q) within rho^2 <= rho2, cap = 1 - |Y|
    the solid angle per radian of the disk: the triangle where the edge runs inside the circle,
    the disk's sector where it runs outside (the edge p + t (q - p) meets the circle at the
    roots of A t^2 + 2 B t + C = 0)."""
    d = (q[0] - p[0], q[1] - p[1])
    a = d[0] * d[0] + d[1] * d[1]
    b = p[0] * d[0] + p[1] * d[1]
    c = p[0] * p[0] + p[1] * p[1] - rho2
    disc = b * b - a * c
    if a == 0.0 or disc <= 0.0:
        return cap * _angle(p, q)
    # the root of larger magnitude first, the other from their product c / a: no cancellation
    root = -(b + math.copysign(math.sqrt(disc), b))
    t1, t2 = sorted((root / a, c / root if root != 0.0 else 0.0))
    lo, hi = max(t1, 0.0), min(t2, 1.0)
    if lo >= hi:
        return cap * _angle(p, q)
    x1, x2 = (p[0] + lo * d[0], p[1] + lo * d[1]), (p[0] + hi * d[0], p[1] + hi * d[1])
    return cap * (_angle(p, x1) + _angle(x2, q)) + _triangle(x1, x2)


class CapPiece:
    """A top (face 2) or bottom (face 3) texel's part inside a strip: a convex polygon in face
    coordinates (see the module doc), with its solid angle, y range and C(Y)."""

    def __init__(self, face: int, poly: list):
        self.pole = 1.0 if face == 2 else -1.0
        self.edges = list(zip(poly, poly[1:] + poly[:1]))      # (p, q), read again for every band edge
        total = sum(_triangle(p, q) for p, q in self.edges)
        self.sign = 1.0 if total >= 0.0 else -1.0
        self.area = abs(total)
        far2 = max(p[0] * p[0] + p[1] * p[1] for p in poly)
        near2 = min(_distance2(p, q) for p, q in self.edges)
        if _contains_centre(self.edges):
            near2 = 0.0
        ys = sorted((self.pole / math.sqrt(1.0 + near2), self.pole / math.sqrt(1.0 + far2)))
        self.bottom, self.top = ys

    def below(self, big_y: float) -> float:
        """C(Y): on the top face the piece outside the circle of Y, on the bottom face inside it."""
        if big_y * self.pole <= 0.0:
            return 0.0 if self.pole > 0.0 else self.area
        z = abs(big_y)
        rho2 = (1.0 - z) * (1.0 + z) / (z * z)
        inside = self.sign * sum(_fan_within(p, q, rho2, 1.0 - z) for p, q in self.edges)
        return self.area - inside if self.pole > 0.0 else inside


def _distance2(p, q) -> float:
    """Squared distance from the face centre to the segment p q."""
    d = (q[0] - p[0], q[1] - p[1])
    a = d[0] * d[0] + d[1] * d[1]
    t = min(1.0, max(0.0, -(p[0] * d[0] + p[1] * d[1]) / a)) if a > 0.0 else 0.0
    x = (p[0] + t * d[0], p[1] + t * d[1])
    return x[0] * x[0] + x[1] * x[1]


def _contains_centre(edges) -> bool:
    """Whether the convex polygon of these edges holds the face centre (on its boundary counts)."""
    sides = [_cross2(p, q) for p, q in edges]
    return all(c >= 0.0 for c in sides) or all(c <= 0.0 for c in sides)


# azimuth at a side face's centre: phi = centre + atan(a) on it
SIDE_CENTRE = {0: math.pi / 2, 1: -math.pi / 2, 4: 0.0, 5: math.pi}


def _under(p: float, q: float, e: float) -> float:
    """Solid angle of [p, q] x [0, e] on a face (signed): F(q, e) - F(p, e) for
    F(a, e) = atan(a e / sqrt(1 + a^2 + e^2)), as one atan2 (atan u - atan v = atan2(u - v, 1 + uv))."""
    u, v = q * e / math.sqrt(1.0 + q * q + e * e), p * e / math.sqrt(1.0 + p * p + e * e)
    return math.atan2(u - v, 1.0 + u * v)


def _reach(e: float, t: float) -> float:
    """|a| beyond which the parallel's curve e = t sqrt(1 + a^2) (t >= 0) runs above e."""
    if e <= t:
        return 0.0
    return math.sqrt((e / t) ** 2 - 1.0) if t > 0.0 else math.inf


class SidePiece:
    """A side-face texel's part inside a strip: the rectangle [a0, a1] x [e0, e1] (see the module
    doc), with its solid angle, y range and C(Y), as CapPiece."""

    def __init__(self, a0: float, a1: float, e0: float, e1: float):
        self.a0, self.a1, self.e0, self.e1 = a0, a1, e0, e1
        self.area = _under(a0, a1, e1) - _under(a0, a1, e0)
        near = 0.0 if a0 < 0.0 < a1 else min(abs(a0), abs(a1))      # y = e / sqrt(1 + a^2 + e^2)
        far = max(abs(a0), abs(a1))
        self.top = e1 / math.sqrt(1.0 + (near if e1 > 0.0 else far) ** 2 + e1 * e1)
        self.bottom = e0 / math.sqrt(1.0 + (far if e0 > 0.0 else near) ** 2 + e0 * e0)

    def below(self, big_y: float) -> float:
        """C(Y); below a southern parallel, the rectangle less the part of its mirror image
        (e -> -e) below the northern one."""
        if big_y < 0.0:
            return self.area - _side_below(self.a0, self.a1, -self.e1, -self.e0, -big_y)
        return _side_below(self.a0, self.a1, self.e0, self.e1, big_y)


def _side_below(a0: float, a1: float, e0: float, e1: float, big_y: float) -> float:
    """C(Y) of the rectangle [a0, a1] x [e0, e1] for 0 <= Y < 1: its columns under the curve
    e = t sqrt(1 + a^2) whole where the curve runs above e1 (|a| >= reach(e1)), none where it runs
    below e0 (|a| <= reach(e0)), and from e0 up to the curve between."""
    t = big_y / math.sqrt((1.0 - big_y) * (1.0 + big_y))
    r0, r1 = _reach(e0, t), _reach(e1, t)
    cuts = [a for a in (-r1, -r0, r0, r1) if a0 < a < a1]
    total = 0.0
    for p, q in zip([a0, *cuts], [*cuts, a1]):
        mid = abs(p + q) / 2.0
        if mid >= r1:
            total += _under(p, q, e1) - _under(p, q, e0)
        elif mid >= r0:
            total += big_y * math.atan2(q - p, 1.0 + p * q) - _under(p, q, e0)
    return total


def side_span(face: int, phi_lo: float, phi_hi: float):
    """(a_lo, a_hi): the strip phi in [phi_lo, phi_hi] on a side face, or None if it misses it."""
    lo = math.remainder(phi_lo - SIDE_CENTRE[face], 2.0 * math.pi)
    hi = lo + (phi_hi - phi_lo)
    if hi <= -math.pi / 4 or lo >= math.pi / 4:
        return None
    return (-1.0 if lo <= -math.pi / 4 else math.tan(lo)), (1.0 if hi >= math.pi / 4 else math.tan(hi))


def strip_pieces(face: int, size: int, phi_lo: float, phi_hi: float):
    """(row, column, Piece) for every texel of the face the strip phi in [phi_lo, phi_hi] meets."""
    edges = [2.0 * k / size - 1.0 for k in range(size + 1)]
    if face in SIDE_CENTRE:
        span = side_span(face, phi_lo, phi_hi)
        if span is None:
            return
        a_lo, a_hi = span
        for row in range(size):
            for col in range(max(0, int((a_lo + 1) * size / 2)), min(size - 1, int((a_hi + 1) * size / 2)) + 1):
                a0, a1 = max(a_lo, edges[col]), min(a_hi, edges[col + 1])
                if a1 > a0:
                    yield row, col, SidePiece(a0, a1, -edges[row + 1], -edges[row])
        return
    lines = (_line(face, phi_lo, 1.0), _line(face, phi_hi, -1.0))
    wedge = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
    for line in lines:
        wedge = clip(wedge, line)
    if len(wedge) < 3:
        return
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
                piece = CapPiece(face, square)
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
    a GPU; on a CPU 4 per core, each taking blocks of 8 adjacent columns with one block's scratch
    (fresh memory costs this CPU 0.45 ms/MB, and a scratch per column was 0.2 GB at face 1024;
    a block writes its texels out a cache line at a time)."""
    s = faces.shape[1]
    h, w = 2 * s, 4 * s
    columns = (s + 1) // 2
    cpu = rt.info.kind == "CPU"
    block = 8 if cpu else 1
    items = min(-(-columns // block), 4 * rt.info.device.max_compute_units) if cpu else columns
    out = rt.empty(h * w * 12)
    scratch = rt.empty(items * block * 8 * h * 3 * 8)
    rt.launch("cube_input.cl", "cube_to_equirect", {"BLOCK": block}, (items,), local_size=(1,) if cpu else None,
              faces=rt.to_device(np.ascontiguousarray(faces[..., :3], np.float32)), sym=rt.to_device(symmetries()),
              ys=rt.to_device(row_edges(h)), s=s, w=w, h=h, scratch=scratch, out=out)
    return rt.read_mapped(out, (h, w, 3))
