"""The shared conventions of docs/conventions.md, in numpy (float64).

Mirrors kernels/common.h; tests/test_conventions.py checks the two against each other.

- World space: right-handed, +y up; directions point away from the shaded point.
- Equirect (the usual latitude-longitude mapping): u = 0.5 - atan2(x, z)/(2 pi), v = acos(y)/pi, v = 0 is the top row.
- Cube faces in the order +X -X +Y -Y +Z -Z, row 0 at the top of each face.
- Octahedral map with +y at the centre of the square.
"""

from __future__ import annotations

import math

import numpy as np

PI = np.pi
LAYOUTS = ("equirect", "cubemap", "octahedral")


def wrap_degrees(degrees: float) -> float:
    """An angle reduced into (-360, 360), exactly (math.fmod is exact in floating point), before
    anything turns it into radians: 1e300 degrees summed with pi lost every digit (`sh --rotate-y
    1e300` reported an error of 985% and numpy's cast warnings), and a float32 kernel reads inf."""
    return math.fmod(float(degrees), 360.0)


# --- equirect --------------------------------------------------------------------------

def equirect_uv_from_dir(d):
    """u in [0, 1), v in [0, 1] for unit directions d[..., 3]."""
    d = np.asarray(d, dtype=np.float64)
    u = 0.5 - np.arctan2(d[..., 0], d[..., 2]) / (2.0 * PI)
    u = u - np.floor(u)  # atan2 = -pi (the seam) gives u = 1: wrap it to 0
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / PI
    return u, v


def dir_from_equirect_uv(u, v):
    theta = PI * np.asarray(v, dtype=np.float64)
    phi = 2.0 * PI * (0.5 - np.asarray(u, dtype=np.float64))
    st = np.sin(theta)
    return np.stack([st * np.sin(phi), np.cos(theta), st * np.cos(phi)], axis=-1)


def equirect_phi(width: int, rotate_y_deg: float = 0.0):
    """Azimuth phi = atan2(x, z) of each texel-centre column, after rotating the panorama
    by `rotate_y_deg` about +y (a rotation about the image's polar axis is a shift in phi)."""
    u = (np.arange(width) + 0.5) / width
    return 2.0 * PI * (0.5 - u) + np.deg2rad(rotate_y_deg)


def equirect_theta(height: int):
    """Polar angle from +y of each texel-centre row."""
    return PI * (np.arange(height) + 0.5) / height


def equirect_texel_dirs(width: int, height: int, rotate_y_deg: float = 0.0):
    """Unit directions of texel centres, shape (height, width, 3)."""
    theta = equirect_theta(height)[:, None]
    phi = equirect_phi(width, rotate_y_deg)[None, :]
    st = np.sin(theta)
    return np.stack(np.broadcast_arrays(st * np.sin(phi), np.cos(theta), st * np.cos(phi)), axis=-1)


def equirect_row_solid_angles(width: int, height: int):
    """Exact solid angle of one texel in each row, shape (height,); sums to 4 pi over the image.

    dOmega(j) = (2 pi / W) (cos(pi j / H) - cos(pi (j+1) / H)), written as a product of
    sines so that rows near the poles keep their relative precision.
    """
    j = np.arange(height, dtype=np.float64)
    a, b = PI * j / height, PI * (j + 1) / height
    return (2.0 * PI / width) * 2.0 * np.sin(0.5 * (a + b)) * np.sin(0.5 * (b - a))


def equirect_solid_angles(width: int, height: int):
    """Solid angle of every texel, shape (height, width)."""
    return np.repeat(equirect_row_solid_angles(width, height)[:, None], width, axis=1)


def bilinear_equirect(image, u, v):
    """Bilinear lookup of image[H, W, C] at (u, v): wraps in u, clamps in v (texel centres at
    (i + 0.5)/W)."""
    image = np.asarray(image)
    h, w = image.shape[:2]
    x = np.asarray(u, dtype=np.float64) * w - 0.5
    y = np.clip(np.asarray(v, dtype=np.float64) * h - 0.5, 0.0, h - 1)
    x0 = np.floor(x)
    y0 = np.minimum(np.floor(y), h - 1)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    x0 = x0.astype(np.int64) % w
    x1 = (x0 + 1) % w
    y0 = y0.astype(np.int64)
    y1 = np.minimum(y0 + 1, h - 1)
    top = image[y0, x0] * (1 - fx) + image[y0, x1] * fx
    bottom = image[y1, x0] * (1 - fx) + image[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


# --- cube map ----------------------------------------------------------------------------

def dir_from_cube(face, s, t):
    """Direction (not normalised) of face coordinates s, t in [0, 1] (t = 0 is the top row).

    Faces +X -X +Y -Y +Z -Z (0..5), the OpenGL/D3D orientation.
    """
    a = 2.0 * np.asarray(s, dtype=np.float64) - 1.0
    b = 2.0 * np.asarray(t, dtype=np.float64) - 1.0
    one = np.ones_like(a + b)
    face = np.asarray(face) * np.ones_like(one, dtype=np.int64)
    table = [
        (one, -b, -a),   # +X
        (-one, -b, a),   # -X
        (a, one, b),     # +Y
        (a, -one, -b),   # -Y
        (a, -b, one),    # +Z
        (-a, -b, -one),  # -Z
    ]
    out = np.zeros(one.shape + (3,))
    for f, (x, y, z) in enumerate(table):
        m = face == f
        out[m] = np.stack([x, y, z], axis=-1)[m]
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def cube_from_dir(d):
    """(face, s, t) in [0, 1] of directions d[..., 3] (need not be unit): the inverse of
    dir_from_cube, by the major axis (Vulkan's cube-map face selection, ties to x, then y)."""
    d = np.asarray(d, dtype=np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    ax, ay, az = np.abs(x), np.abs(y), np.abs(z)
    xm = (ax >= ay) & (ax >= az)
    ym = ~xm & (ay >= az)
    face = np.where(xm, np.where(x > 0, 0, 1), np.where(ym, np.where(y > 0, 2, 3), np.where(z > 0, 4, 5)))
    ma = np.where(xm, ax, np.where(ym, ay, az))
    sel = [face == f for f in range(5)]
    sc = np.select(sel, [-z, z, x, x, x], -x)
    tc = np.select(sel, [-y, -y, z, -z, -y], -y)
    return face, 0.5 * (sc / ma + 1.0), 0.5 * (tc / ma + 1.0)


def cube_texel_dirs(size: int):
    """Directions of the texel centres of the six faces, shape (6, size, size, 3)."""
    c = (np.arange(size) + 0.5) / size
    t, s = np.meshgrid(c, c, indexing="ij")
    return np.stack([dir_from_cube(f, s, t) for f in range(6)])


def cube_texel_solid_angles(size: int):
    """Exact solid angle of each texel of one face, shape (size, size) (same for all faces)."""
    e = 2.0 * np.arange(size + 1) / size - 1.0

    def area(x, y):
        return np.arctan2(x * y, np.sqrt(x * x + y * y + 1.0))

    x0, y0 = e[None, :-1], e[:-1, None]
    x1, y1 = e[None, 1:], e[1:, None]
    return area(x0, y0) - area(x0, y1) - area(x1, y0) + area(x1, y1)


# --- octahedral --------------------------------------------------------------------------

def dir_from_octahedral(u, v):
    """Direction of octahedral coordinates u, v in [0, 1]; +y at the centre of the square."""
    x = 2.0 * np.asarray(u, dtype=np.float64) - 1.0
    z = 2.0 * np.asarray(v, dtype=np.float64) - 1.0
    x, z = np.broadcast_arrays(x, z)
    y = 1.0 - np.abs(x) - np.abs(z)
    lower = y < 0
    sx = np.where(x >= 0, 1.0, -1.0)
    sz = np.where(z >= 0, 1.0, -1.0)
    xf = np.where(lower, (1.0 - np.abs(z)) * sx, x)
    zf = np.where(lower, (1.0 - np.abs(x)) * sz, z)
    d = np.stack([xf, y, zf], axis=-1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def octahedral_uv_from_dir(d):
    d = np.asarray(d, dtype=np.float64)
    n = d / np.sum(np.abs(d), axis=-1, keepdims=True)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sx = np.where(x >= 0, 1.0, -1.0)
    sz = np.where(z >= 0, 1.0, -1.0)
    ox = np.where(y >= 0, x, (1.0 - np.abs(z)) * sx)
    oz = np.where(y >= 0, z, (1.0 - np.abs(x)) * sz)
    return 0.5 * ox + 0.5, 0.5 * oz + 0.5


def octahedral_texel_dirs(size: int):
    c = (np.arange(size) + 0.5) / size
    v, u = np.meshgrid(c, c, indexing="ij")
    return dir_from_octahedral(u, v)


# --- frames and rotations ----------------------------------------------------------------

def tangent_frame(n):
    """Orthonormal (t, b) with t x b = n, branchless and finite for every unit n
    (Duff et al. 2017, "Building an Orthonormal Basis, Revisited")."""
    n = np.asarray(n, dtype=np.float64)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = np.copysign(1.0, z)
    a = -1.0 / (sign + z)
    b = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=-1)
    bt = np.stack([b, sign + y * y * a, -y], axis=-1)
    return t, bt


def rotate_y(d, degrees: float):
    """Rotate directions about +y by `degrees` (right-handed: +x turns towards -z)."""
    d = np.asarray(d, dtype=np.float64)
    c, s = np.cos(np.deg2rad(degrees)), np.sin(np.deg2rad(degrees))
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([c * x + s * z, y, -s * x + c * z], axis=-1)
