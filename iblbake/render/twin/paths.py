"""The reference pass's estimator with paths (kernels/reference.cl with BOUNCES), sample for sample:
the same sample dimensions (Halton for the first 8, Owen-scrambled Sobol pairs after), the environment's sampling
tables, the same strategies and MIS weights at the first vertex, the BSDF's lobe choice, Russian
roulette and the environment sampled at every later vertex. numpy twin, float64, for untextured
frames of spheres and planes without analytic lights (those the kernel's closed-form tests
cover: tests/test_paths.py). Where float32 and float64 round a decision differently (a CDF
boundary, a roulette draw) one path differs; every other is the kernel's."""

from __future__ import annotations

import math

import numpy as np

from iblbake.core import brdf
from iblbake.core import conventions
from iblbake.core import sampling
from iblbake.core.metrics import luminance
from iblbake.render.twin.gbuffer import _plane_t, _sphere_roots, occluded, ray_offset
from iblbake.render.twin.surface import _materials, diffuse_weight, facing_normal, surface, to_env
from iblbake.scene.layout import DELTA_ALPHA

RR_DEPTH, MAX_PATH = 3, 256           # kernels/reference.cl


def dimension(seed, gid, k, d):
    """kernels/sampler.h sampler_1d: dimension d of sample k of G-buffer sample gid."""
    if d < 8:
        return sampling.qmc(seed, gid, k, d)
    gid = np.asarray(gid, np.uint64)
    k = np.asarray(k, np.uint64)
    stream_index = ((gid * 2 + (k & 1)) & sampling.M32).astype(np.uint32)       # G-buffer sample, replicate
    stream = sampling.pcg_hash(np.uint32(seed) ^ sampling.pcg_hash(stream_index))
    return sampling.owen_sobol(k >> 1, stream, (d - 8) >> 1, (d - 8) & 1)


class Dims:
    """The Sampler of one sample number k for every G-buffer sample gid: dimensions in order."""

    def __init__(self, seed, gid, k):
        self.seed, self.gid, self.k, self.d = seed, gid, k, 0

    def next(self):
        self.d += 1
        return dimension(self.seed, self.gid, self.k, self.d - 1)

    def next2(self):
        a = self.next()
        return np.stack([a, self.next()], -1)


def closest(o, d, arrays):
    """The nearest hit of rays o + t d, t > 0, among spheres and planes: (t, material, geometric
    normal (unit), hit) with t = inf where none."""
    n = len(o)
    t_best, mat, ng = np.full(n, np.inf), np.full(n, -1), np.zeros((n, 3))
    ints = lambda a: int(np.asarray(a, np.float32).view(np.int32))            # noqa: E731
    for sp in arrays.spheres.astype(np.float64):
        t0, t1 = _sphere_roots(o, d, sp)
        t = np.where(t0 > 0, t0, np.where(t1 > 0, t1, np.inf))
        b = t < t_best
        t_best[b] = t[b]
        nn = (o[b] + t[b, None] * d[b] - sp[0, :3]) / sp[0, 3]
        ng[b] = nn / np.linalg.norm(nn, axis=1, keepdims=True)
        mat[b] = ints(sp[1, 0])
    for pl in arrays.planes.astype(np.float64):
        t = _plane_t(o, d, pl)
        b = t < t_best
        t_best[b] = t[b]
        ng[b] = pl[1, :3]
        mat[b] = ints(pl[0, 3])
    return t_best, mat, ng, np.isfinite(t_best)


def env_texel(l, rot, w, h):
    """kernels/envmap.h env_texel_index of world directions."""
    u, v = conventions.equirect_uv_from_dir(to_env(l, rot))
    return np.minimum((v * h).astype(np.int64), h - 1) * w + np.minimum((u * w).astype(np.int64), w - 1)


def specular_probability(f0, f90, kd_pi, nov, diffuse: bool, specular: bool):
    s = luminance(brdf.f_schlick(nov[:, None], f0, f90)) if specular else np.zeros(len(nov))
    d = luminance(kd_pi) if diffuse else np.zeros(len(nov))
    with np.errstate(invalid="ignore", divide="ignore"):
        ps = np.clip(s / (s + d), 0.1, 0.9)
    return np.where(~(s > 0), 0.0, np.where(~(d > 0), 1.0, ps))


def bsdf_cos(m, v, n, nov, l, ps, diffuse: bool, specular: bool):
    """(f NoL, pdf) of the terms asked for (kernels/reference.cl bsdf_cos); m: the vertex's
    material columns (base, metallic, emissive, rough, f0, f90, kd)."""
    base, metallic, _, rough, f0, f90, kd = m
    alpha = rough ** 2
    nol = (n * l).sum(-1)
    f, pdf = np.zeros_like(l), np.zeros(len(l))
    up = nol > 0
    if diffuse:
        f += kd * np.maximum(nol, 0)[:, None]
        pdf += (1 - ps) * np.maximum(nol, 0) / math.pi
    if specular:
        lobe = up & (alpha >= DELTA_ALPHA)
        hv = v + l
        hv /= np.maximum(np.linalg.norm(hv, axis=-1, keepdims=True), 1e-300)
        noh, voh = np.maximum((n * hv).sum(-1), 0), np.maximum((v * hv).sum(-1), 0)
        a = np.maximum(alpha, 1e-30)
        dd = brdf.d_ggx(noh, a)
        spec = (brdf.f_schlick(voh[:, None], f0, f90) * (dd * brdf.v_smith_ggx_correlated(nov, np.maximum(nol, 0), a)
                                                         * np.maximum(nol, 0))[:, None])
        f += np.where(lobe[:, None], spec, 0.0)
        pdf += np.where(lobe, ps * sampling.g1_smith(nov, a) * dd / (4 * nov), 0.0)
    return np.where(up[:, None], f, 0.0), np.where(up, pdf, 0.0)


def bsdf_sample(m, v, n, nov, ps, diffuse, specular, u_lobe, u):
    """(f NoL / pdf, direction, pdf (inf for a mirror)) (kernels/reference.cl bsdf_sample)."""
    base, metallic, _, rough, f0, f90, kd = m
    alpha = rough ** 2
    t, b = conventions.tangent_frame(n)
    spec = u_lobe < ps
    mirror = spec & (alpha < DELTA_ALPHA)
    vl = np.stack([(v * t).sum(1), (v * b).sum(1), nov], -1)
    hl = sampling.sample_ggx_vndf(vl, np.maximum(alpha, 1e-30), u)
    hs = t * hl[:, 0:1] + b * hl[:, 1:2] + n * hl[:, 2:3]
    l_spec = 2 * (v * hs).sum(1, keepdims=True) * hs - v
    ll = sampling.sample_cosine_hemisphere(u)
    l_cos = t * ll[:, 0:1] + b * ll[:, 1:2] + n * ll[:, 2:3]
    l = np.where(spec[:, None], l_spec, l_cos)
    l = np.where(mirror[:, None], 2 * nov[:, None] * n - v, l)
    f, pdf = bsdf_cos(m, v, n, nov, l, ps, diffuse, specular)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where((pdf > 0)[:, None], f / np.where(pdf > 0, pdf, 1)[:, None], 0.0)
        w_mirror = brdf.f_schlick(nov[:, None], f0, f90) / np.where(ps > 0, ps, 1)[:, None]
    return np.where(mirror[:, None], w_mirror, w), l, np.where(mirror, np.inf, pdf)


def _columns(arrays, mat, nov):
    base, metallic, emissive, rough, f0, f90 = _materials(arrays, mat)
    return base, metallic, emissive, rough, f0, f90, diffuse_weight(base, metallic, rough, f0, f90, nov)


def radiance(gb, arrays, effects: dict, env: dict, image, dist, samples: int, bounces=0):
    """The reference's mean over `samples` samples (numbers 0 .. samples - 1) per G-buffer sample
    (hits only; misses are 0), as kernels/reference.cl computes it with BOUNCES = bounces (0:
    unbounded): image the panorama (H, W, 3+), dist its sampling tables (EnvironmentDistribution)."""
    diffuse, specular = effects["diffuse"] == "reference", effects["specular"] == "reference"
    seed, rot, scale = effects["reference"]["seed"], env["rotation_y"], env["intensity"]
    hit = gb["hit"]
    gid = np.flatnonzero(hit).astype(np.int64)
    img = image[..., :3].reshape(-1, 3).astype(np.float32).astype(np.float64)
    hgt, wid = image.shape[:2]
    pdf_table = dist.pdf.reshape(-1).astype(np.float64)
    v, n, nov, cols = surface(gb, arrays)
    m1 = cols + (diffuse_weight(*cols[:2], cols[3], cols[4], cols[5], nov),)
    kd = m1[6]
    alpha = m1[3] ** 2
    delta = alpha < DELTA_ALPHA
    origin = ray_offset(gb["pos"][hit], n, gb["dir"][hit], gb["t"][hit])
    t, b = conventions.tangent_frame(n)
    vl = np.stack([(v * t).sum(1), (v * b).sum(1), nov], -1)
    total = np.zeros((len(gid), 3))
    for k in range(samples):
        sp = Dims(seed, gid, k)
        u_env, u_ggx, u_cos, u_texel = sp.next2(), sp.next2(), sp.next2(), sp.next2()
        est = np.zeros((len(gid), 3))
        # the direct estimate: the environment, then the BSDF (kernels/reference.cl, strategies 1, 2)
        de, texel = dist.sample(np.concatenate([u_env, u_texel], 1))
        l = conventions.rotate_y(de, rot)
        pe = pdf_table[texel]
        nol = (n * l).sum(1)
        ok = (nol > 0) & (pe > 0) & ~occluded(origin, l, arrays)
        li = img[texel]
        if diffuse:
            est += np.where(ok[:, None], li * kd * (nol / np.where(pe > 0, pe, 1))[:, None]
                            * sampling.power_heuristic(pe, np.maximum(nol, 0) / math.pi)[:, None], 0.0)
        if specular:
            f, pb = bsdf_cos(m1, v, n, nov, l, np.ones(len(l)), False, True)
            est += np.where((ok & ~delta)[:, None], li * f / np.where(pe > 0, pe, 1)[:, None]
                            * sampling.power_heuristic(pe, pb)[:, None], 0.0)
        if diffuse:
            ll = sampling.sample_cosine_hemisphere(u_cos)
            lc = t * ll[:, 0:1] + b * ll[:, 1:2] + n * ll[:, 2:3]
            tx = env_texel(lc, rot, wid, hgt)
            pc = np.maximum(ll[:, 2], 0) / math.pi
            seen = (pc > 0) & ~occluded(origin, lc, arrays)
            est += np.where(seen[:, None], img[tx] * kd * math.pi * sampling.power_heuristic(pc, pdf_table[tx])[:, None], 0.0)
        if specular:
            r = 2 * nov[:, None] * n - v
            seen = ~occluded(origin, r, arrays)
            est += np.where((delta & seen)[:, None], img[env_texel(r, rot, wid, hgt)]
                            * brdf.f_schlick(nov[:, None], m1[4], m1[5]), 0.0)
            hl = sampling.sample_ggx_vndf(vl, np.maximum(alpha, 1e-30), u_ggx)
            hs = t * hl[:, 0:1] + b * hl[:, 1:2] + n * hl[:, 2:3]
            vh = (v * hs).sum(1)
            lg = 2 * vh[:, None] * hs - v
            nl = (n * lg).sum(1)
            good = ~delta & (nl > 0) & (vh > 0) & ~occluded(origin, lg, arrays)
            f, pb = bsdf_cos(m1, v, n, nov, lg, np.ones(len(lg)), False, True)
            tx = env_texel(lg, rot, wid, hgt)
            with np.errstate(invalid="ignore", divide="ignore"):
                wgt = f / np.where(pb > 0, pb, 1)[:, None]
            est += np.where(good[:, None], img[tx] * wgt * sampling.power_heuristic(pb, pdf_table[tx])[:, None], 0.0)
        # the path: the surface the first vertex sees, then every later vertex
        u_lobe, u_dir = sp.next(), sp.next2()
        ps = specular_probability(m1[4], m1[5], kd * math.pi, nov, diffuse, specular)
        beta, l, _ = bsdf_sample(m1, v, n, nov, ps, diffuse, specular, u_lobe, u_dir)
        alive = (beta > 0).any(1)
        env_part, emitted = np.zeros_like(est), np.zeros_like(est)
        o = origin.copy()
        th, mat, ng, found = closest(o, l, arrays)
        alive &= found
        for bounce in range(2, MAX_PATH + 1):
            if not alive.any():
                break
            p = o + np.where(alive, th, 0)[:, None] * l
            ng = np.where(((ng * l).sum(1) > 0)[:, None], -ng, ng)
            vv = -l
            nn = facing_normal(ng, vv)
            nv = np.maximum((nn * vv).sum(1), 1e-4)
            mv = _columns(arrays, np.where(alive, mat, 0), nv)
            emitted += np.where(alive[:, None], beta * mv[2], 0.0)
            if 0 < bounces < bounce:
                break
            org = ray_offset(p, nn, l, np.where(alive, th, 0))
            psv = specular_probability(mv[4], mv[5], mv[6] * math.pi, nv, True, True)
            u_env, u_texel, u_d = sp.next2(), sp.next2(), sp.next2()
            u_lb, u_rr = sp.next(), sp.next()
            de, texel = dist.sample(np.concatenate([u_env, u_texel], 1))
            le = conventions.rotate_y(de, rot)
            pe = pdf_table[texel]
            f, pb = bsdf_cos(mv, vv, nn, nv, le, psv, True, True)
            ok = alive & (pe > 0) & (f > 0).any(1)
            ok &= ~occluded(org, le, arrays) if ok.any() else ok
            env_part += np.where(ok[:, None], beta * img[texel] * f
                                 * (sampling.power_heuristic(pe, pb) / np.where(pe > 0, pe, 1))[:, None], 0.0)
            wgt, nl, pb = bsdf_sample(mv, vv, nn, nv, psv, True, True, u_lb, u_d)
            alive &= (wgt > 0).any(1)
            beta = np.where(alive[:, None], beta * wgt, beta)
            if bounce >= RR_DEPTH:
                q = np.minimum(beta.max(1), 0.95)
                alive &= u_rr < q
                beta = np.where(alive[:, None], beta / np.where(q > 0, q, 1)[:, None], beta)
            l, o = np.where(alive[:, None], nl, l), np.where(alive[:, None], org, o)
            th, mat, ng, found = closest(o, l, arrays)
            miss = alive & ~found
            tx = env_texel(l, rot, wid, hgt)
            mis = np.where(np.isinf(pb), 1.0, sampling.power_heuristic(pb, pdf_table[tx]))
            env_part += np.where(miss[:, None], beta * img[tx] * mis[:, None], 0.0)
            alive &= found
        total += (est + env_part) * scale + emitted
    out = np.zeros((len(hit), 3))
    out[hit] = total / samples
    return out
