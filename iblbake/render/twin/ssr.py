"""Stochastic screen-space reflections (kernels/ssr.cl): the depth pyramid, the Hi-Z march and
the replacement of the reflected environment. numpy twin, float64; one tile (the whole frame)."""

from __future__ import annotations

import numpy as np

from iblbake.core import conventions, sampling
from iblbake.render.twin.surface import surface
from iblbake.scene import pack
from iblbake.scene.layout import DELTA_ALPHA


def project(cam: dict, x):
    """Twin of ssr_project: (pixel x, pixel y, view depth) of points x (m, 3)."""
    pos, fwd, right, up, ortho = pack.camera_vectors(cam)
    w, h = cam["resolution"]
    d = x - pos
    z = d @ fwd
    sx, sy = d @ right / (right @ right), d @ up / (up @ up)
    if not ortho:
        with np.errstate(divide="ignore", invalid="ignore"):     # the eye itself (a miss's position)
            sx, sy = sx / z, sy / z
    return np.stack([0.5 * (sx + 1) * w, 0.5 * (1 - sy) * h, z], -1)


def hiz(cam: dict, gb, spp: int) -> list:
    """The min-depth pyramid, level 0 each pixel's first sample's view depth (+inf: nothing)."""
    w, h = cam["resolution"]
    first = np.arange(w * h) * spp
    z = np.where(gb["hit"][first], project(cam, gb["pos"][first])[:, 2], np.inf).reshape(h, w)
    levels = [z]
    while levels[-1].shape != (1, 1):
        a = levels[-1]
        hh, ww = (a.shape[0] + 1) // 2, (a.shape[1] + 1) // 2
        pad = np.full((2 * hh, 2 * ww), np.inf)
        pad[:a.shape[0], :a.shape[1]] = a
        levels.append(pad.reshape(hh, 2, ww, 2).min((1, 3)))
    return levels


def march(levels, s0, z0, s1, z1, ortho: bool, steps: int, thickness: float):
    """Twin of ssr_march for rays (m): the hit pixel's index y w + x, or -1."""
    h, w = levels[0].shape
    ds = s1 - s0
    m = len(s0)
    with np.errstate(divide="ignore", invalid="ignore"):
        edge = np.floor(s0) + (ds > 0)
        tt = (edge - s0) / ds
        tt = np.where(np.isnan(tt), np.inf, tt)
        t = np.minimum(tt.min(1), 1.0) + 1e-4
    level = np.zeros(m, int)
    hit = np.full(m, -1)
    live = t < 1
    for _ in range(steps):
        if not live.any():
            break
        s = s0 + t[:, None] * ds
        out = (s[:, 0] < 0) | (s[:, 1] < 0) | (s[:, 0] >= w) | (s[:, 1] >= h)
        live &= ~out
        idx = np.nonzero(live)[0]
        if not len(idx):
            break
        size = 1 << level[idx]
        lw = (w + size - 1) >> level[idx]
        lh = (h + size - 1) >> level[idx]
        cx = np.minimum(s[idx, 0].astype(int) >> level[idx], lw - 1)
        cy = np.minimum(s[idx, 1].astype(int) >> level[idx], lh - 1)
        ex = ((cx + (ds[idx, 0] > 0)) * size).astype(np.float64)
        ey = ((cy + (ds[idx, 1] > 0)) * size).astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            tx = (ex - s0[idx, 0]) / ds[idx, 0]
            ty = (ey - s0[idx, 1]) / ds[idx, 1]
        ti = t[idx]
        tx = np.where(np.isnan(tx) | (tx <= ti), np.inf, tx)
        ty = np.where(np.isnan(ty) | (ty <= ti), np.inf, ty)
        t_exit = np.minimum(np.minimum(tx, ty), 1.0)
        za = depth_at(z0[idx], z1[idx], ti, ortho)
        zb = depth_at(z0[idx], z1[idx], t_exit, ortho)
        cell_min = np.array([levels[lv][y, x] for lv, y, x in zip(level[idx], cy, cx)])
        front = np.maximum(za, zb) < cell_min
        down = ~front & (level[idx] > 0)
        bottom = ~front & (level[idx] == 0)
        got = bottom & (np.minimum(za, zb) <= cell_min + thickness)
        hit[idx[got]] = cy[got] * w + cx[got]
        live[idx[got]] = False
        step_on = front | (bottom & ~got)
        t[idx[step_on]] = t_exit[step_on] + 1e-4
        level[idx[front]] = np.minimum(level[idx[front]] + 1, len(levels) - 1)
        level[idx[down]] -= 1
        live &= t < 1
    return hit


def depth_at(z0, z1, t, ortho):
    return z0 + (z1 - z0) * t if ortho else 1 / (1 / z0 + (1 / z1 - 1 / z0) * t)


def ssr(gb, arrays, effects: dict, cam: dict, src, ssr_w, ssr_li):
    """Twin of the ssr kernel: the frame's radiance per sample (src, the lit frame) with the
    reflected environment (weight ssr_w, radiance ssr_li per hit sample) replaced where the rays
    meet the frame."""
    s = effects["ssr_settings"]
    spp = cam["spp"]
    w, h = cam["resolution"]
    hitmask = gb["hit"]
    out = src.copy()
    v, n, nov, (_base, _metallic, _emissive, rough, _f0, _f90) = surface(gb, arrays)
    alpha = rough ** 2
    rows = np.nonzero(hitmask)[0]
    sel = (rough <= s["max_roughness"]) & (ssr_w > 0).any(1)
    levels = hiz(cam, gb, spp)
    pos, fwd, _right, _up, ortho = pack.camera_vectors(cam)
    t, b = conventions.tangent_frame(n)
    vl = np.stack([(v * t).sum(1), (v * b).sum(1), nov], -1)
    fade_r = np.clip((s["max_roughness"] - rough) / (0.2 * s["max_roughness"]), 0, 1)
    acc = np.zeros((len(rows), 3))
    p = gb["pos"][hitmask]
    for k in range(s["rays"]):
        u = np.stack([sampling.qmc(s["seed"], rows, k, d) for d in (0, 1)], -1)
        hl = np.where((alpha < DELTA_ALPHA)[:, None], [0.0, 0.0, 1.0], sampling.sample_ggx_vndf(vl, alpha, u))
        hv = t * hl[:, 0:1] + b * hl[:, 1:2] + n * hl[:, 2:3]
        l = 2 * (v * hv).sum(1, keepdims=True) * hv - v
        got = ssr_li.copy()
        up = sel & ((n * l).sum(1) > 0)
        p0 = p + n * (1e-4 * (1 + gb["t"][hitmask]))[:, None]
        z0 = (p0 - pos) @ fwd
        dz = l @ fwd
        length = np.full(len(p), s["ray_length"])
        if not ortho:
            with np.errstate(divide="ignore", invalid="ignore"):
                length = np.where(dz < 0, np.minimum(length, 0.99 * (z0 - 1e-3) / -dz), length)
        a = project(cam, p0)
        c = project(cam, p0 + length[:, None] * l)
        i = np.nonzero(up)[0]
        hit = march(levels, a[i, :2], a[i, 2], c[i, :2], c[i, 2], ortho, s["steps"], s["thickness"])
        ok = hit >= 0
        hx, hy = (hit[ok] % w + 0.5) / w, (hit[ok] // w + 0.5) / h
        fade_e = np.clip(np.minimum(np.minimum(hx, 1 - hx), np.minimum(hy, 1 - hy)) / 0.05, 0, 1)
        f = (fade_r[i[ok]] * fade_e)[:, None]
        got[i[ok]] = ssr_li[i[ok]] * (1 - f) + src[hit[ok] * spp] * f
        acc += got
    new = src[hitmask] + np.where(sel[:, None], ssr_w * (acc / s["rays"] - ssr_li), 0.0)
    out[hitmask] = new
    return out
