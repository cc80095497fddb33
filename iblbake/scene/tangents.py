"""Tangent frames for normal maps, and the texture-space density of triangles.

A mesh's own tangents (glTF TANGENT) are used where it has them. Otherwise they are generated
the way MikkTSpace (Mikkelsen 2008, the algorithm glTF names) does for a mesh whose vertices are
already split at UV seams: per triangle the direction of increasing u, dp/du, from its UV
derivatives; per vertex the angle-weighted sum of its triangles' dp/du projected into the plane
of the vertex normal, kept apart for triangles whose UV mapping is mirrored; renormalised. The
bitangent's side w follows glTF: bitangent = w cross(normal, tangent) points up the image
(decreasing v, glTF's v runs down), so w = +1 where (u, v) is laid out as an image seen from the
front and -1 where it is mirrored. (Not the MikkTSpace library itself: the pymikktspace package on
PyPI does not build with today's Cython. What it adds beyond this, merging vertices of equal
position, normal and UV and splitting them where w changes, the split vertices of glTF files
already give.)
"""

from __future__ import annotations

import numpy as np

UNDEFINED_DENSITY = -64.0      # a triangle with no UV area: one texel covers all of it


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 1e-30, v / np.maximum(n, 1e-300), 0.0)


def _frame_tangent(n):
    """A tangent for normals with no UV layout: Duff et al.'s branchless basis (2017, JCGT 6(1); docs/conventions.md)."""
    s = np.where(n[..., 2] >= 0, 1.0, -1.0)
    a = -1.0 / (s + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    return np.stack([1.0 + s * n[..., 0] ** 2 * a, s * b, -s * n[..., 0]], axis=-1)


def face_derivatives(tri, uv):
    """(dp/du, dp/dv) of triangles tri (n, 3, 3) with texture coordinates uv (n, 3, 2); NaN where
    the UV triangle has no area."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    with np.errstate(all="ignore"):
        inv = np.where(np.abs(det) > 1e-30, 1.0 / det, np.nan)[:, None]
        return (d2[:, 1:2] * e1 - d1[:, 1:2] * e2) * inv, (d1[:, 0:1] * e2 - d2[:, 0:1] * e1) * inv


def corner_tangents(vertices, faces, corner_normals, uv0, file_tangents, transform) -> np.ndarray:
    """(n, 3, 4): per corner of every face a unit tangent in the plane of the corner's normal
    and w = +-1 (the bitangent's side). vertices are in world space, file_tangents (v, 4) in the
    file's (NaN rows: none), transform the object's 3 x 3 linear part."""
    n_faces = len(faces)
    out = np.zeros((n_faces, 3, 4))
    out[..., 3] = 1.0
    tri = vertices[faces]
    # the file's, where a face has them at all three corners
    ft = file_tangents[faces]                                         # (n, 3, 4)
    has_file = np.isfinite(ft).all(axis=(1, 2))
    det = np.linalg.det(transform)
    xyz = ft[..., :3] @ np.asarray(transform).T
    w_file = np.where(ft[..., 3] < 0, -1.0, 1.0) * (1.0 if det >= 0 else -1.0)
    # generated from TEXCOORD_0
    uv = uv0[faces]
    dpdu, dpdv = face_derivatives(tri, uv)
    fn = _unit(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]))
    gen = np.isfinite(dpdu).all(axis=1) & np.isfinite(uv).all(axis=(1, 2)) & ~has_file
    side = np.where(np.einsum("nc,nc->n", np.cross(fn, dpdu), -np.nan_to_num(dpdv)) < 0, 1, 0)   # 1: mirrored
    acc = np.zeros((len(vertices), 2, 3))
    if gen.any():
        g = np.flatnonzero(gen)
        t = np.nan_to_num(dpdu[g])
        for k in range(3):
            a, b = tri[g, (k + 1) % 3] - tri[g, k], tri[g, (k + 2) % 3] - tri[g, k]
            cosang = np.einsum("nc,nc->n", _unit(a), _unit(b)).clip(-1, 1)
            nk = corner_normals[g, k]
            proj = _unit(t - nk * np.einsum("nc,nc->n", nk, t)[:, None])
            np.add.at(acc, (faces[g, k], side[g]), proj * np.arccos(cosang)[:, None])
    for k in range(3):
        nk = corner_normals[:, k]
        t = np.where(has_file[:, None], xyz[:, k], np.where(gen[:, None], acc[faces[:, k], side], 0.0))
        t = t - nk * np.einsum("nc,nc->n", nk, t)[:, None]
        ok = np.linalg.norm(t, axis=1) > 1e-12
        out[:, k, :3] = np.where(ok[:, None], _unit(t), _frame_tangent(nk))
        out[:, k, 3] = np.where(has_file, w_file[:, k], np.where(gen & (side == 1), -1.0, 1.0))
    return out


def uv_density(tri, uv) -> np.ndarray:
    """0.5 log2(UV area / world area) of each triangle: the texture footprint's scale (its
    log2 texels per world unit, before the texture's own size). UNDEFINED_DENSITY where the UV
    triangle has no area or no coordinates."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    uv_area = np.abs(d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1])
    world = np.linalg.norm(np.cross(e1, e2), axis=1)
    with np.errstate(all="ignore"):
        d = 0.5 * np.log2(uv_area / world)
    return np.where(np.isfinite(d), d, UNDEFINED_DENSITY)
