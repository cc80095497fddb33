"""The reference pass's estimator with paths (kernels/paths/reference.cl with BOUNCES), sample for sample:
the same sample dimensions (Owen-scrambled Sobol pairs, sampling.Sampler.replicate), the environment's sampling
tables, the same strategies and MIS weights at every vertex (the first one's restricted to the
terms the frame asks for), the BSDF's lobe choice and Russian roulette. numpy twin, float64, for untextured
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
from iblbake.scene.layout import MAX_PATH, RR_DEPTH        # kernels/paths/paths.h reads them from layout.h


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


def env_direct(mt, v, n, nov, origin, ps, diffuse, specular, u_env, u_texel, img, pdf_table, dist, rot, arrays,
               alive=None):
    """kernels/paths/paths.h env_direct: the environment sampled at each vertex, MIS against the BSDF
    of the terms asked for, where unoccluded (only the `alive` rows traced)."""
    de, texel = dist.sample(np.concatenate([u_env, u_texel], 1))
    l = conventions.rotate_y(de, rot)
    pe = pdf_table[texel]
    f, pb = bsdf.evaluate(mt, v, n, nov, l, ps, diffuse, specular)
    ok = (pe > 0) & (f > 0).any(1)
    if alive is not None:
        ok &= alive
    ok &= ~occluded(origin, l, arrays) if ok.any() else ok
    with np.errstate(invalid="ignore", divide="ignore"):
        w = sampling.power_heuristic(pe, pb) / np.where(pe > 0, pe, 1)
    return np.where(ok[:, None], img[texel] * f * w[:, None], 0.0)


def env_missed(l, pb, img, pdf_table, rot, w, h):
    """kernels/paths/paths.h env_missed: the environment a BSDF-sampled ray leaving the scene finds, MIS
    against the panorama's sampling (1 for a mirror's ray, pdf inf)."""
    tx = env_texel(l, rot, w, h)
    with np.errstate(invalid="ignore"):
        mis = np.where(np.isinf(pb), 1.0, sampling.power_heuristic(pb, pdf_table[tx]))
    return img[tx] * mis[:, None]


def _vertex(arrays, mat, nov):
    """(the BSDF's material (core/bsdf.py), emission) of the materials `mat` seen at NoV nov."""
    base, metallic, emissive, rough, f0, f90 = _materials(arrays, mat)
    return bsdf.Material(f0, f90, rough ** 2, diffuse_weight(base, metallic, rough, f0, f90, nov)), emissive


def radiance(gb, arrays, effects: dict, env: dict, image, dist, samples: int, bounces=0):
    """The reference's mean over `samples` samples (numbers 0 .. samples - 1) per G-buffer sample
    (hits only; misses are 0), as kernels/paths/reference.cl computes it with BOUNCES = bounces (0:
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
    replicates = sampling.reference_replicates(effects["reference"]["target_noise"])
    for k in range(samples):
        sp = sampling.Sampler.replicate(seed, gid, k, replicates)
        # the first vertex is a path vertex of the terms asked for: the environment sampled (MIS
        # against the BSDF), one BSDF-sampled ray bringing the environment where it leaves the
        # scene (MIS against the panorama's sampling), the path where it meets a surface
        u_env, u_texel, u_dir = sp.next_2d(), sp.next_2d(), sp.next_2d()
        u_lobe, _ = sp.next_1d(), sp.next_1d()
        ps = bsdf.specular_probability(mt, nov, diffuse, specular)
        est = env_direct(mt, v, n, nov, origin, ps, diffuse, specular, u_env, u_texel, img, pdf_table, dist, rot,
                         arrays)
        beta, l, pb = bsdf.sample(mt, v, n, nov, ps, diffuse, specular, u_lobe, u_dir)
        alive = (beta > 0).any(1)
        env_part, emitted = np.zeros_like(est), np.zeros_like(est)
        o = origin.copy()
        th, mat, ng, found = closest(o, l, arrays)
        miss = alive & ~found
        est += np.where(miss[:, None], beta * env_missed(l, pb, img, pdf_table, rot, wid, hgt), 0.0)
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
            env_part += np.where(alive[:, None], beta * env_direct(mv, vv, nn, nv, org, psv, True, True, u_env, u_texel,
                                                                    img, pdf_table, dist, rot, arrays, alive), 0.0)
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
            env_part += np.where(miss[:, None], beta * env_missed(l, pb, img, pdf_table, rot, wid, hgt), 0.0)
            alive &= found
        total += (est + env_part) * scale + emitted
    out = np.zeros((len(hit), 3))
    out[hit] = total / samples
    return out
