"""The lights pass (kernels/lights.cl): analytic lights with hard and soft shadows, and their
exact integral. numpy twin, float64."""

from __future__ import annotations

import numpy as np

from iblbake.core import brdf
from iblbake.core import bsdf
from iblbake.core import conventions
from iblbake.core import sampling
from iblbake.scene.layout import LIGHT_KINDS
from iblbake.render.twin.gbuffer import occluded, ray_offset
from iblbake.render.twin.surface import diffuse_weight, surface


def representative_point(n, v, l, sin_max, alpha):
    """Twin of kernels/lights.cl representative_point: (direction, energy scale) per hit."""
    r = 2 * (n * v).sum(-1, keepdims=True) * n - v
    c = (l * r).sum(-1, keepdims=True) * r - l
    cl = np.linalg.norm(c, axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        ls = l + c * np.minimum(sin_max[:, None] / cl, 1)
    ls = np.where(cl > 0, ls, l)
    ls /= np.linalg.norm(ls, axis=-1, keepdims=True)
    h = v + ls
    voh = np.maximum((v * h).sum(-1) / np.linalg.norm(h, axis=-1), 1e-4)
    a = np.maximum(alpha, brdf.ALPHA_MIN)
    energy = (a / np.minimum(a + 0.5 * sin_max / np.sqrt(voh), 1)) ** 2
    return np.where((sin_max > 0)[:, None], ls, l), np.where(sin_max > 0, energy, 1.0)


def disk_specular(mt, v, n, nov, wc, omc, sin_max, ns, samplers, visible=None):
    """Twin of kernels/lights.cl disk_specular: the specular f NoL over a light's disk or sphere per
    unit irradiance facing it, (1 / (pi sin^2)) integral over the cone of f NoL dw, by ns samples
    of the cone and ns of the GGX lobe's visible normals combined by the balance heuristic; sample
    k's two pairs from samplers(k) (the cone's first, as the soft shadows'). visible(l, k, lobe)
    the arriving share of directions l (None: all arrive)."""
    pd = 1 / (2 * np.pi * omc)
    acc = np.zeros((len(nov), 3))
    for k in range(ns):
        sp = samplers(k)
        ud, ul = sp.next_2d(), sp.next_2d()
        ld = _cone_direction(wc, omc, ud)
        f, pl = bsdf.evaluate(mt, v, n, nov, ld, 1.0, False, True)
        c = f / (pd + pl)[:, None]
        w, ll, pll = bsdf.sample(mt, v, n, nov, 1.0, False, True, 0.0, ul)
        inside = (((ll - wc) ** 2).sum(1) <= 2 * omc) & (w.sum(1) > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            share = 1 / (1 + pd / pll)       # a mirror's pdf is infinite: all of it
        cl = np.where(inside[:, None], w * share[:, None], 0.0)
        if visible is not None:
            c = c * visible(ld, k, False)[:, None]
            cl = cl * np.where(inside, visible(ll, k, True), 0.0)[:, None]
        acc += c + cl
    return acc / (ns * np.pi * sin_max ** 2)[:, None]


def light_brdf_cos(base, metallic, rough, f0, f90, n, v, nov, l, diffuse: bool, specular: bool, sin_max=None):
    """Twin of kernels/lights.cl light_brdf_cos (the real-time mode's): f(v, l) NoL, per hit and
    colour channel; with sin_max the specular term at the representative point of a light that size
    (a light with soft shadows: disk_specular's)."""
    nol = (n * l).sum(-1)
    out = np.zeros(l.shape[:-1] + (3,))
    if diffuse:
        out += np.where((nol > 0)[:, None], diffuse_weight(base, metallic, rough, f0, f90, nov) * np.maximum(nol, 0)[:, None], 0)
    if specular:
        alpha = rough ** 2
        ls, energy = representative_point(n, v, l, sin_max, alpha) if sin_max is not None else (l, 1.0)
        nols = (n * ls).sum(-1)
        h = v + ls
        h /= np.linalg.norm(h, axis=-1, keepdims=True)
        spec = (brdf.d_ggx((n * h).sum(-1), alpha) * brdf.v_smith_ggx_correlated(nov, np.maximum(nols, 0), alpha)
                * energy * np.maximum(nols, 0))[:, None] * brdf.f_schlick((v * h).sum(-1)[:, None], f0, f90)
        out += np.where((nols > 0)[:, None], spec, 0)
    return out


def _cone_direction(a, omc, u):
    """kernels/light.h cone_direction: directions uniform in the cone about a (n, 3) of 1 - cos omc."""
    x = u[..., 0] * omc
    ct, st, phi = 1 - x, np.sqrt(np.maximum(0, x * (2 - x))), 2 * np.pi * u[..., 1]
    t, b = conventions.tangent_frame(a)
    d = t * (st * np.cos(phi))[:, None] + b * (st * np.sin(phi))[:, None] + a * ct[:, None]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def light_toward(r, p):
    """kernels/light.h light_toward (and light_omc) of a light record r (LIGHT float4s, 4; float64)
    at points p (n, 3): (E (n, 3) what arrives facing it, the direction to its centre (n, 3), the
    shadow ray's length (n,), the sine of its angular radius (n,), 1 - cos of that radius (n,))."""
    e = np.broadcast_to(r[1, :3], (len(p), 3)).copy()
    if int(r[0, 3]) == LIGHT_KINDS["directional"]:
        wc = np.broadcast_to(r[0, :3], p.shape).copy()
        dist = np.full(len(p), np.inf)
        sin_max = np.full(len(p), r[2, 3])
    else:
        dv = r[0, :3] - p
        d = np.linalg.norm(dv, axis=-1)
        wc = dv / d[:, None]
        win = 1 / (d * d)
        if r[3, 2] > 0:
            win *= np.clip(1 - (d / r[3, 2]) ** 4, 0, 1) ** 2
        a = np.clip((wc @ -r[2, :3]) * r[3, 0] + r[3, 1], 0, 1)
        e *= (win * a * a)[:, None]
        sin_max = np.minimum(r[2, 3] / d, 1.0)
        dist = np.maximum(d - r[2, 3], 0)
    return e, wc, dist, sin_max, sin_max ** 2 / (1 + np.sqrt(np.maximum(0, 1 - sin_max ** 2)))


def lights(gb, arrays, records, effects: dict, *, diffuse=True, specular=True, exact=False, visibility=True,
           disk=True):
    """Per-sample radiance of the `lights` pass (hits only; misses are 0): records from
    scene.pack.light_records, effects the scene's (reference seed and max_samples);
    disk=False shades a light with a size from its centre alone (for comparison)."""
    hit = gb["hit"]
    out = np.zeros((len(hit), 3))
    v, n, nov, (base, metallic, _, rough, f0, f90) = surface(gb, arrays)
    p = gb["pos"][hit]
    origin = ray_offset(p, n, gb["dir"][hit], gb["t"][hit])
    sid = np.flatnonzero(hit)              # each G-buffer sample's random stream (one tile)
    seed = effects["reference"]["seed"]
    color = np.zeros((len(p), 3))
    # the exact mode shades with the paths' BSDF (kernels/lights.cl exact_brdf_cos: core/bsdf.py)
    mt = bsdf.Material(f0, f90, rough ** 2, diffuse_weight(base, metallic, rough, f0, f90, nov))
    shade = lambda l: bsdf.evaluate(mt, v, n, nov, l, 0.5, diffuse, specular)[0]   # noqa: E731
    for j, r in enumerate(records.astype(np.float64)):
        e, wc, dist, sin_max, omc = light_toward(r, p)
        ls = int(np.uint32(seed) ^ sampling.pcg_hash(j + 1))
        ns = effects["reference"]["max_samples"] if exact else int(r[3, 3])
        mode = int(r[1, 3])

        if exact and (sin_max > 0).any():
            le = e / (np.pi * sin_max ** 2)[:, None]
            acc = np.zeros((len(p), 3))
            for k in range(ns):
                l = _cone_direction(wc, omc, sampling.Sampler(ls, sid, k).next_2d())
                ok = ~occluded(origin, l, arrays, dist) if visibility else np.ones(len(p), bool)
                acc += np.where(ok[:, None], shade(l), 0.0)
            color += le * (2 * np.pi * omc)[:, None] * acc / ns
            mirror = (mt.alpha < bsdf.DELTA_ALPHA) & (sin_max > 0) if specular else np.zeros(len(p), bool)
            if mirror.any():        # F(NoV) Le where a mirror's one direction falls in the cone
                wm, lm, _ = bsdf.sample(mt, v, n, nov, 1.0, False, True, 0.0, np.zeros((len(p), 2)))
                mirror &= ((lm - wc) ** 2).sum(1) <= 2 * omc
                if visibility:
                    mirror &= ~occluded(origin, lm, arrays, dist)
                color += np.where(mirror[:, None], le * wm, 0.0)
            continue
        if exact:
            vis = (~occluded(origin, wc, arrays, dist)).astype(float) if visibility else np.ones(len(p))
            color += vis[:, None] * e * shade(wc)
            continue
        # real time: a point whose light's whole disk or sphere lies behind it adds nothing
        front = (n * wc).sum(1) > -sin_max
        soft = mode == 2 and (sin_max > 0).all()
        sized = specular and soft and disk
        vis = np.ones(len(p))
        if mode == 1 or (mode == 2 and not soft):
            vis = (~occluded(origin, wc, arrays, dist)).astype(float)
        elif soft:                  # the share of ns rays over the disk or sphere that arrive
            vis = sum(~occluded(origin, _cone_direction(wc, omc, sampling.Sampler(ls, sid, k).next_2d()), arrays, dist)
                      for k in range(ns)) / ns
        f = light_brdf_cos(base, metallic, rough, f0, f90, n, v, nov, wc, diffuse, specular and not sized,
                           sin_max if disk else None)
        if sized:                   # each sample traced
            spec = disk_specular(mt, v, n, nov, wc, omc, sin_max, ns, lambda k: sampling.Sampler(ls, sid, k),
                                 lambda l, k, lobe: (~occluded(origin, l, arrays, dist)).astype(float))
            color += np.where(front[:, None], e * spec, 0.0)
        color += np.where(front[:, None], vis[:, None] * e * f, 0.0)
    out[hit] = color
    return out
