"""Ground-truth ambient occlusion (kernels/gtao.cl): the horizon search over the frame's depth
buffer and its denoise. numpy twin, float64."""

from __future__ import annotations

import math

import numpy as np

from iblbake.scene.pack import camera_vectors
from iblbake.render.twin.surface import facing_normal


def _fract(x):
    return x - np.floor(x)


def gtao_noise(x, y):
    return _fract(52.9829189 * _fract(0.06711056 * x + 0.00583715 * y))


def _pixel_footprint(cam: dict, p):
    pos, fwd, right, _up, ortho = camera_vectors(cam)
    s = 2 * np.linalg.norm(right) / cam["resolution"][0]
    return np.full(len(p), s) if ortho else s * ((p - pos) @ fwd)


def acos_fast(x):
    """Twin of gtao.cl acos_fast (Abramowitz and Stegun 4.4.45, 7e-5 rad)."""
    a = np.abs(x)
    r = np.sqrt(np.maximum(1 - a, 0)) * (1.5707288 + a * (-0.2121144 + a * (0.0742610 - 0.0187293 * a)))
    return np.where(x >= 0, r, math.pi - r)


def _gtao_arc(ch, sh, cos_n, sin_n, ang_n):
    """Twin of gtao.cl gtao_arc: one side's cosine-weighted arc, through the horizon's cosine."""
    h = sh * acos_fast(ch)
    sin_h = sh * np.sqrt(np.maximum(1 - ch * ch, 0))
    return 0.25 * (cos_n + 2 * h * sin_n - ((2 * ch * ch - 1) * cos_n + 2 * ch * sin_h * sin_n))


def _gtao_blocks(cam: dict, g: dict):
    from iblbake.render.passes.gtao import gtao_step

    w, h = cam["resolution"]
    step = gtao_step(g)
    wl, hl = -(-w // step), -(-h // step)
    return step, wl, hl


def gtao(gb, cam: dict, effects: dict):
    """Twin of kernels/gtao.cl gtao: the raw visibility of every block (one pixel, or 2x2 at
    resolution half) from its first pixel's first sample, unclamped; (hl * wl,)."""
    from iblbake.render.passes.gtao import GTAO_LEVELS

    w, h = cam["resolution"]
    spp = cam["spp"]
    g = effects["gtao"]
    step, wl, hl = _gtao_blocks(cam, g)
    first = np.arange(w * h) * spp
    hit, pos = gb["hit"][first], gb["pos"][first]
    raw = np.ones(wl * hl)
    bx, by = np.arange(wl * hl) % wl, np.arange(wl * hl) // wl
    centre = by * step * w + bx * step
    idx = np.flatnonzero(hit[centre])
    bx, by, centre = bx[idx], by[idx], centre[idx]
    x, y = bx * step, by * step
    p = pos[centre]
    v = -gb["dir"][first][centre]
    nrm = facing_normal(gb["normal"][first][centre], v)
    radius = effects["ao_radius"] * g["radius_scale"]
    radius_px = radius / _pixel_footprint(cam, p)
    fall_mul, fall_add = -1 / (g["falloff"] * radius), (1 - g["falloff"]) / g["falloff"] + 1
    _pos, _fwd, right, up, _ortho = camera_vectors(cam)
    right, up = right / np.linalg.norm(right), up / np.linalg.norm(up)
    min_s = 1 / radius_px
    noise_slice, noise_step = gtao_noise(bx, by), gtao_noise(by + 17, bx + 31)
    dot = lambda a, b: (a * b).sum(-1)
    vis = np.zeros(len(idx))
    for sl in range(g["slices"]):
        phi = (sl + noise_slice) * math.pi / g["slices"]
        c, s = np.cos(phi), np.sin(phi)
        d3 = c[:, None] * right + s[:, None] * up
        odir = d3 - dot(d3, v)[:, None] * v
        axis = np.cross(odir, v)
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        pn = nrm - axis * dot(nrm, axis)[:, None]
        pn_len = np.linalg.norm(pn, axis=1)
        cos_n = np.clip(dot(pn, v) / pn_len, 0, 1)
        sgn = np.where(dot(odir, pn) >= 0, 1.0, -1.0)
        sin_n, ang_n = sgn * np.sqrt(1 - cos_n ** 2), sgn * acos_fast(cos_n)
        lows = (-sin_n, sin_n)
        hc = [lows[0].copy(), lows[1].copy()]
        for st in range(g["steps"]):
            jit = _fract(noise_step + (sl + st * g["slices"]) * 0.6180339887)
            t = ((st + jit) / g["steps"]) ** 2 + min_s
            # round half away from zero, as OpenCL's round()
            ox = np.trunc(t * c * radius_px + np.copysign(0.5, c)).astype(int)
            oy = np.trunc(-t * s * radius_px + np.copysign(0.5, -s)).astype(int)
            # far samples read pixel (qx, qy) snapped down to a multiple of 2^k (the kernel's pyramid)
            m = np.maximum(np.abs(ox), np.abs(oy))
            k = np.where(m < 16, 0, np.minimum(np.floor(np.log2(np.maximum(m, 1))).astype(int) - 3, GTAO_LEVELS))
            for side, sign in ((0, 1), (1, -1)):
                qx, qy = x + sign * ox, y + sign * oy
                inside = (qx >= 0) & (qy >= 0) & (qx < w) & (qy < h)
                q = np.where(inside, ((qy >> k) << k) * w + ((qx >> k) << k), 0)
                ok = inside & hit[q]
                dv = pos[q] - p
                dist = np.linalg.norm(dv, axis=1)
                ok &= dist > 0
                with np.errstate(divide="ignore", invalid="ignore"):
                    shc = dot(dv, v) / dist
                wgt = np.clip(dist * fall_mul + fall_add, 0, 1)
                cand = lows[side] + (shc - lows[side]) * wgt
                hc[side] = np.where(ok, np.maximum(hc[side], cand), hc[side])
        vis += pn_len * (_gtao_arc(np.clip(hc[1], -1, 1), -1.0, cos_n, sin_n, ang_n)
                         + _gtao_arc(np.clip(hc[0], -1, 1), 1.0, cos_n, sin_n, ang_n))
    raw[idx] = np.where(radius_px < 1, 1.0, vis / g["slices"])
    return raw


def gtao_denoise(gb, cam: dict, effects: dict, raw):
    """Twin of kernels/gtao.cl gtao_denoise: every sample's mean raw value over the blocks
    around its own whose first pixels lie on its surface, clamped and raised to the power."""
    w, h = cam["resolution"]
    spp = cam["spp"]
    g = effects["gtao"]
    step, wl, hl = _gtao_blocks(cam, g)
    r = g["denoise"]
    first = np.arange(w * h) * spp
    hit = gb["hit"]
    out = np.ones(len(hit))
    sid = np.flatnonzero(hit)
    pix = sid // spp
    bx, by = (pix % w) // step, (pix // w) // step
    p = gb["pos"][sid]
    v = -gb["dir"][sid]
    nrm = facing_normal(gb["normal"][sid], v)
    tau = 3 * step * _pixel_footprint(cam, p)
    total, count = np.zeros(len(sid)), np.zeros(len(sid))
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            qx, qy = bx + dx, by + dy
            inside = (qx >= 0) & (qy >= 0) & (qx < wl) & (qy < hl)
            f = first[np.where(inside, qy * step * w + qx * step, 0)]
            ok = inside & gb["hit"][f] & ((gb["normal"][f] * nrm).sum(1) >= 0.8) & \
                (np.abs(((gb["pos"][f] - p) * nrm).sum(1)) <= tau)
            total += np.where(ok, raw[np.where(inside, qy * wl + qx, 0)], 0)
            count += ok
    vis = np.clip(np.where(count > 0, total / np.maximum(count, 1), raw[by * wl + bx]), 0, 1)
    out[sid] = vis ** g["power"]
    return out
