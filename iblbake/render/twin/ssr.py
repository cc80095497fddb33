"""Stochastic screen-space reflections (kernels/ssr.cl): the gathered frame, its depth pyramid, the
validated Hi-Z march, the resolve and the replacement of the reflected environment. numpy twin,
float64, the whole frame."""

from __future__ import annotations

import numpy as np

from iblbake.core import conventions, sampling
from iblbake.render.sources.ssr import march_lengths
from iblbake.render.twin import reflection_probes as rp_twin
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


RESOLVE_RADIUS = 3            # kernels/ssr.cl SSR_RESOLVE_RADIUS


def gather(cam: dict, gb, arrays, src):
    """Twin of ssr_gather: per pixel its first sample's (position, view depth: +inf nothing),
    (normal, roughness), lit radiance, object (-1 nothing)."""
    from iblbake.render.lightmaps.read import hit_objects
    w, h = cam["resolution"]
    spp = cam["spp"]
    first = np.arange(w * h) * spp
    hit = gb["hit"][first]
    v, n, _nov, (_b, _m, _e, rough, _f0, _f90) = surface(gb, arrays)
    rows = np.cumsum(gb["hit"]) - 1                  # surface() holds the hit samples only
    pos = np.zeros((w * h, 3))
    z = np.full(w * h, np.inf)
    nrm = np.tile([0.0, 0.0, 1.0], (w * h, 1))
    r = np.full(w * h, 2.0)
    lit = np.zeros((w * h, 3))
    k = first[hit]
    pos[hit] = gb["pos"][k]
    z[hit] = project(cam, pos[hit])[:, 2]
    nrm[hit] = n[rows[k]]
    r[hit] = rough[rows[k]]
    pix = {"pos": pos, "z": z, "n": nrm, "rough": r, "lit": lit, "obj": hit_objects(gb, arrays)[first]}
    # the lit radiance: the mean over the pixel's samples on the first one's plane
    k = np.nonzero(gb["hit"])[0]
    on = k[on_plane(gb, pix, k // spp, k)]
    sums, counts = np.zeros((w * h, 3)), np.zeros(w * h)
    np.add.at(sums, on // spp, src[on])
    np.add.at(counts, on // spp, 1)
    lit[hit] = sums[hit] / counts[hit, None]
    return pix


def on_plane(gb, pix, px, k):
    """Twin of ssr's same-surface test: whether samples k lie within 2% of the view depth of the
    tangent plane of their pixels px's first sample."""
    return np.abs(((gb["pos"][k] - pix["pos"][px]) * pix["n"][px]).sum(1)) <= 0.02 * pix["z"][px]


def hiz(z, w: int, h: int) -> list:
    """The min-depth pyramid of level 0 z (h w,), down to 1 x 1."""
    levels = [z.reshape(h, w)]
    while levels[-1].shape != (1, 1):
        a = levels[-1]
        hh, ww = (a.shape[0] + 1) // 2, (a.shape[1] + 1) // 2
        pad = np.full((2 * hh, 2 * ww), np.inf)
        pad[:a.shape[0], :a.shape[1]] = a
        levels.append(pad.reshape(hh, 2, ww, 2).min((1, 3)))
    return levels


def plausible(pix, cam, c, p0, l):
    """Twin of ssr_plausible: (plausibility, where the ray meets the plane of pixel c's surface)."""
    w, h = cam["resolution"]
    s, nc = pix["pos"][c], pix["n"][c]
    den = (l * nc).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((s - p0) * nc).sum(1) / den
    x = p0 + t[:, None] * l
    q = project(cam, x)
    d = q[:, :2] - np.stack([c % w + 0.5, c // w + 0.5], -1)
    conf = np.clip(2 - np.linalg.norm(d, axis=1), 0, 1)
    return np.where((den < 0) & (t > 0), conf, 0.0), x


def march(levels, s0, z0, s1, z1, ortho: bool, steps: int, thickness: float, pix, cam, p0, l):
    """Twin of ssr_march for rays (m): (the hit pixel's index y w + x or -1, its plausibility, where
    the ray meets its plane)."""
    h, w = levels[0].shape
    ds = s1 - s0
    m = len(s0)
    eps = 0.01 / np.maximum(np.linalg.norm(ds, axis=1), 1e-6)      # a hundredth of a pixel
    with np.errstate(divide="ignore", invalid="ignore"):
        edge = np.floor(s0) + (ds > 0)
        tt = (edge - s0) / ds
        tt = np.where(np.isnan(tt), np.inf, tt)
        t = np.minimum(tt.min(1), 1.0) + eps
    level = np.zeros(m, int)
    hit = np.full(m, -1)
    conf = np.zeros(m)
    xs = np.zeros((m, 3))
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
        cand = bottom & (np.minimum(za, zb) <= cell_min + thickness + depth_extent(levels[0], cx, cy))
        c = cy * w + cx
        pc, px = plausible(pix, cam, c, p0[idx], l[idx])
        got = cand & (pc > 0)
        hit[idx[got]] = c[got]
        conf[idx[got]] = pc[got]
        xs[idx[got]] = px[got]
        live[idx[got]] = False
        step_on = front | (bottom & ~got)
        t[idx[step_on]] = t_exit[step_on] + eps[idx[step_on]]
        level[idx[front]] = np.minimum(level[idx[front]] + 1, len(levels) - 1)
        level[idx[down]] -= 1
        live &= t < 1
    return hit, conf, xs


def depth_extent(z0, cx, cy):
    """Twin of ssr_depth_extent: the largest depth step from pixels (cx, cy) of level 0 to a
    neighbour (where both are finite)."""
    h, w = z0.shape
    e = np.zeros(len(cx))
    z = z0[np.clip(cy, 0, h - 1), np.clip(cx, 0, w - 1)]
    for dx, dy in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        qx, qy = cx + dx, cy + dy
        inside = (qx >= 0) & (qx < w) & (qy >= 0) & (qy < h)
        q = z0[np.clip(qy, 0, h - 1), np.clip(qx, 0, w - 1)]
        ok = inside & np.isfinite(q)
        with np.errstate(invalid="ignore"):
            e = np.where(ok, np.maximum(e, np.abs(q - z)), e)
    return e


def depth_at(z0, z1, t, ortho):
    return z0 + (z1 - z0) * t if ortho else 1 / (1 / z0 + (1 / z1 - 1 / z0) * t)


def held(captured, p, r, x, alpha, mine=None):
    """Twin of reflection_probes_hold: the share of the reflection along p + t r meeting x that the
    parallax probes at p hold (their proxy left within 3% of the travel from x), for lobes of GGX
    alpha, to each capture's resolution. mine: each point's own probes (rp_twin.own; None: every
    probe), as the reading weighs them."""
    out, wsum = np.zeros(len(p)), np.zeros(len(p))
    travel = np.linalg.norm(x - p, axis=1)
    mine = np.zeros(len(p), np.uint32) if mine is None else mine
    for k, c in enumerate(captured or []):
        st = c["settings"]
        w = np.where(rp_twin.kept(mine, k), rp_twin.weight(st, p), 0.0)
        wsum += w
        if st["parallax"]:
            e = rp_twin.exit_point(st, p, r)
            out += w * np.clip(1 - np.linalg.norm(e - x, axis=1) / (0.03 * travel), 0, 1) \
                * np.clip(alpha / np.float32(np.pi / st["size"]), 0, 1)
    return np.where(wsum > 1, out / np.where(wsum > 1, wsum, 1), out)


def trace(pix, cam: dict, s: dict, captured=None):
    """Twin of ssr_trace: per pixel (H, C), the mean over its rays of conf L_hit and of conf."""
    w, h = cam["resolution"]
    pos, fwd, _right, _up, ortho = pack.camera_vectors(cam)
    levels = hiz(pix["z"], w, h)
    sel = np.nonzero(np.isfinite(pix["z"]) & (pix["rough"] <= s["max_roughness"]))[0]
    out = np.zeros((w * h, 4))
    if not len(sel):
        return out
    p, n, rough = pix["pos"][sel], pix["n"][sel], pix["rough"][sel]
    v = np.broadcast_to(-fwd, p.shape) if ortho else (pos - p) / np.linalg.norm(pos - p, axis=1, keepdims=True)
    nov = np.maximum((n * v).sum(1), 1e-4)
    alpha = rough ** 2
    t, b = conventions.tangent_frame(n)
    vl = np.stack([(v * t).sum(1), (v * b).sum(1), nov], -1)
    fade_r = np.clip((s["max_roughness"] - rough) / (0.2 * s["max_roughness"]), 0, 1)
    count = np.maximum(1, np.ceil(s["rays"] * np.float32(rough) / max(s["max_roughness"], 1e-6))).astype(int)
    acc, csum = np.zeros((len(sel), 3)), np.zeros(len(sel))
    p0 = p + n * (1e-4 * (np.linalg.norm(p, axis=1) + np.linalg.norm(p - pos, axis=1)))[:, None]
    mine = None
    if captured:
        mine = rp_twin.own(captured, p, rp_twin.masks_of(captured, pix["obj"][sel]))
    for k in range(int(count.max())):
        u = sampling.Sampler(s["seed"], sel, k).next_2d()
        hl = np.where((alpha < DELTA_ALPHA)[:, None], [0.0, 0.0, 1.0], sampling.sample_ggx_vndf(vl, alpha, u))
        hv = t * hl[:, 0:1] + b * hl[:, 1:2] + n * hl[:, 2:3]
        l = 2 * (v * hv).sum(1, keepdims=True) * hv - v
        i = np.nonzero((k < count) & ((n * l).sum(1) > 0))[0]
        z0 = (p0[i] - pos) @ fwd
        dz = l[i] @ fwd
        length = np.full(len(i), s["ray_length"])
        if not ortho:
            with np.errstate(divide="ignore", invalid="ignore"):
                length = np.where(dz < 0, np.minimum(length, 0.99 * z0 / -dz), length)
        a = project(cam, p0[i])
        c = project(cam, p0[i] + length[:, None] * l[i])
        hit, conf, x = march(levels, a[:, :2], a[:, 2], c[:, :2], c[:, 2], ortho, s["steps"], s["thickness"], pix, cam,
                             p0[i], l[i])
        ok = hit >= 0
        hx, hy = (hit[ok] % w + 0.5) / w, (hit[ok] // w + 0.5) / h
        fade_e = np.clip(np.minimum(np.minimum(hx, 1 - hx), np.minimum(hy, 1 - hy)) / 0.05, 0, 1)
        f = conf[ok] * fade_r[i[ok]] * fade_e
        if captured and s["defer_to_probes"]:
            f = f * (1 - held(captured, p0[i[ok]], l[i[ok]], x[ok], alpha[i[ok]], mine[i[ok]]))
        acc[i[ok]] += f[:, None] * pix["lit"][hit[ok]]
        csum[i[ok]] += f
    out[sel, :3] = acc / count[:, None]
    out[sel, 3] = csum / count
    return out


def resolve(pix, hits, cam: dict, max_roughness: float):
    """Twin of ssr_resolve: each pixel's (H, C), the weighted mean over its neighbours on the same
    surface."""
    w, h = cam["resolution"]
    out = np.zeros((w * h, 4))
    for px in np.nonzero(np.isfinite(pix["z"]) & (pix["rough"] <= max_roughness))[0]:
        r = pix["rough"][px]
        radius = int(np.ceil(np.float32(RESOLVE_RADIUS) * np.sqrt(np.float32(min(r / max(max_roughness, 1e-6), 1.0)))))
        sigma2 = max(0.25 * radius * radius, 0.25)
        x, y = px % w, px // w
        acc, wsum = np.zeros(4), 0.0
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                qx, qy = x + dx, y + dy
                if not (0 <= qx < w and 0 <= qy < h):
                    continue
                q = qy * w + qx
                if q == px:
                    wt = 1.0
                elif not np.isfinite(pix["z"][q]):
                    wt = 0.0
                else:
                    cn = float(pix["n"][px] @ pix["n"][q])
                    dz = abs(pix["z"][q] - pix["z"][px]) / (0.02 * pix["z"][px])
                    dr = abs(pix["rough"][q] - r) / 0.1
                    wt = 0.0 if cn < 0.95 else np.exp(-0.5 * (dx * dx + dy * dy) / sigma2 - dz * dz - dr * dr) * cn ** 16
                acc += wt * hits[q]
                wsum += wt
        out[px] = acc / wsum
    return out


def ssr(gb, arrays, effects: dict, cam: dict, src, ssr_w, ssr_li, captured=None):
    """Twin of the ssr pass: the frame's radiance per sample (src, the lit frame) with the
    reflected environment (weight ssr_w, radiance ssr_li per hit sample) replaced by the resolved
    reflection of the sample's pixel, where the sample lies on that pixel's first sample's surface.
    `captured`: the reflection probes (the reflection_probes bake) where they are read."""
    s = {**effects["ssr_settings"], **march_lengths(effects["ssr_settings"], arrays, cam)}
    spp = cam["spp"]
    pix = gather(cam, gb, arrays, src)
    res = resolve(pix, trace(pix, cam, s, captured), cam, s["max_roughness"])
    out = src.copy()
    k = np.nonzero(gb["hit"])[0]
    px = k // spp
    same = on_plane(gb, pix, k // spp, k)
    live = same & (ssr_w > 0).any(1)
    r = res[px]
    out[k] = src[k] + np.where(live[:, None], ssr_w * (r[:, :3] - r[:, 3:4] * ssr_li), 0.0)
    return out
