"""The reference pass's estimator with paths (kernels/reference.cl with BOUNCES), sample for sample:
the same sample dimensions (Halton for the first 8, Owen-scrambled Sobol pairs after), the environment's sampling
tables, the same strategies and MIS weights at the first vertex, the BSDF's lobe choice, Russian
roulette and the environment sampled at every later vertex. numpy twin, float64, for untextured
frames of spheres and planes without analytic lights (those the kernel's closed-form tests
cover: tests/test_paths.py). Where float32 and float64 round a decision differently (a CDF
boundary, a roulette draw) one path differs; every other is the kernel's."""

from __future__ import annotations

import numpy as np

from iblbake.core import bsdf
from iblbake.core import conventions
from iblbake.core import sampling
from iblbake.render.twin.gbuffer import _plane_t, _sphere_roots, occluded, ray_offset
from iblbake.render.twin.surface import _materials, diffuse_weight, facing_normal, surface, to_env

RR_DEPTH, MAX_PATH = 3, 256           # kernels/paths.h


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


def _vertex(arrays, mat, nov):
    """(the BSDF's material (core/bsdf.py), emission) of the materials `mat` seen at NoV nov."""
    base, metallic, emissive, rough, f0, f90 = _materials(arrays, mat)
    return bsdf.Material(f0, f90, rough ** 2, diffuse_weight(base, metallic, rough, f0, f90, nov)), emissive


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
    mt = bsdf.Material(cols[4], cols[5], cols[3] ** 2, diffuse_weight(*cols[:2], cols[3], cols[4], cols[5], nov))
    origin = ray_offset(gb["pos"][hit], n, gb["dir"][hit], gb["t"][hit])
    total = np.zeros((len(gid), 3))
    for k in range(samples):
        sp = sampling.Sampler(seed, gid, k)
        u_env, u_ggx, u_cos, u_texel = sp.next_2d(), sp.next_2d(), sp.next_2d(), sp.next_2d()
        est = np.zeros((len(gid), 3))
        # the direct estimate, each term alone (kernels/reference.cl): the environment, MIS against
        # the term's BSDF pdf, then the term's BSDF (the cosine hemisphere, GGX visible normals),
        # MIS against the environment's
        de, texel = dist.sample(np.concatenate([u_env, u_texel], 1))
        l = conventions.rotate_y(de, rot)
        pe = pdf_table[texel]
        nol = (n * l).sum(1)
        ok = (nol > 0) & (pe > 0) & ~occluded(origin, l, arrays)
        li = img[texel]
        for term, ps_term, u_term in ((diffuse, 0.0, u_cos), (specular, 1.0, u_ggx)):
            if not term:
                continue
            f, pb = bsdf.evaluate(mt, v, n, nov, l, ps_term, not ps_term, bool(ps_term))
            with np.errstate(invalid="ignore", divide="ignore"):
                mis_e = sampling.power_heuristic(pe, pb) / np.where(pe > 0, pe, 1)
            est += np.where(ok[:, None], li * f * mis_e[:, None], 0.0)
        for term, ps_term, u_term in ((diffuse, 0.0, u_cos), (specular, 1.0, u_ggx)):
            if not term:
                continue
            wgt, lb, pb = bsdf.sample(mt, v, n, nov, ps_term, not ps_term, bool(ps_term), 1.0 - ps_term, u_term)
            tx = env_texel(lb, rot, wid, hgt)
            seen = (wgt > 0).any(1)
            seen &= ~occluded(origin, lb, arrays) if seen.any() else seen
            mis_b = np.where(np.isinf(pb), 1.0, sampling.power_heuristic(pb, pdf_table[tx]))
            est += np.where(seen[:, None], img[tx] * wgt * mis_b[:, None], 0.0)
        # the path: the surface the first vertex sees, then every later vertex
        u_lobe, u_dir = sp.next_1d(), sp.next_2d()
        ps = bsdf.specular_probability(mt, nov, diffuse, specular)
        beta, l, _ = bsdf.sample(mt, v, n, nov, ps, diffuse, specular, u_lobe, u_dir)
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
            mv, emission = _vertex(arrays, np.where(alive, mat, 0), nv)
            emitted += np.where(alive[:, None], beta * emission, 0.0)
            if 0 < bounces < bounce:
                break
            org = ray_offset(p, nn, l, np.where(alive, th, 0))
            psv = bsdf.specular_probability(mv, nv, True, True)
            u_env, u_texel, u_d = sp.next_2d(), sp.next_2d(), sp.next_2d()
            u_lb, u_rr = sp.next_1d(), sp.next_1d()
            de, texel = dist.sample(np.concatenate([u_env, u_texel], 1))
            le = conventions.rotate_y(de, rot)
            pe = pdf_table[texel]
            f, pb = bsdf.evaluate(mv, vv, nn, nv, le, psv, True, True)
            ok = alive & (pe > 0) & (f > 0).any(1)
            ok &= ~occluded(org, le, arrays) if ok.any() else ok
            env_part += np.where(ok[:, None], beta * img[texel] * f
                                 * (sampling.power_heuristic(pe, pb) / np.where(pe > 0, pe, 1))[:, None], 0.0)
            wgt, nl, pb = bsdf.sample(mv, vv, nn, nv, psv, True, True, u_lb, u_d)
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
