"""numpy twin of the render kernels (kernels/gbuffer.cl, shade.cl, reference.cl), float64, for
tests on small frames.

primary()      G-buffer by brute force (every ray against every sphere, plane and triangle)
shade()        SH diffuse, importance-sampled, prefiltered and lobe specular, emission
lights()       analytic lights with hard and soft shadows, and their exact integral
ambient_occlusion(), gtao(), gtao_denoise()   the AO passes
exact()        the integral the `reference` pass estimates, by quadrature: every texel of the
               panorama (piecewise constant), split into s x s parts with exact solid angles,
               each direction traced for occlusion (occluded) unless visibility is off
"""

from __future__ import annotations

import math

import numpy as np

from iblbake.core import brdf
from iblbake.core import conventions
from iblbake.bake.dfg import dfg_lookup
from iblbake.bake import prefilter
from iblbake.bake import radiance
from iblbake.core import sampling
from iblbake.core import sh
from iblbake.scene.pack import camera_vectors, pixel_jitter

LUM = np.array([0.2126, 0.7152, 0.0722])


def _sphere_t(o, d, sp):
    """Nearest t > 0 of rays o + t d with sphere record sp (inf where none)."""
    lo, hi = _sphere_roots(o, d, sp)
    return np.where(lo > 0, lo, np.where(hi > 0, hi, np.inf))


def _plane_t(o, d, pl):
    p0, nrm, tt, bb = pl[0, :3], pl[1, :3], pl[2, :3], pl[3, :3]
    den = d @ nrm
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((p0 - o) @ nrm) / den
        q = o + t[..., None] * d - p0
    inside = (np.abs(q @ tt) <= pl[2, 3]) & (np.abs(q @ bb) <= pl[3, 3])
    return np.where((np.abs(den) >= 1e-20) & (t > 0) & inside, t, np.inf)


def _triangle_t(o, d, tri):
    """(t, u, v) of rays with one triangle record (Moller-Trumbore, float64)."""
    v0 = tri[0, :3]
    e1, e2 = tri[1, :3] - v0, tri[2, :3] - v0
    p = np.cross(d, e2)
    det = p @ e1
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        sv = o - v0
        u = (sv * p).sum(-1) * inv
        qv = np.cross(sv, e1)
        v = (d * qv).sum(-1) * inv
        t = (qv @ e2) * inv
    ok = (det != 0) & (u >= 0) & (u <= 1) & (v >= 0) & (u + v <= 1) & (t > 0)
    return np.where(ok, t, np.inf), u, v


def occluded(o, d, arrays, tmax=np.inf):
    """Any hit along o + t d, 0 < t < tmax (twin of kernels/scene.h occluded, occluded_to): a
    boolean per ray."""
    hit = np.zeros(np.broadcast_shapes(o.shape, d.shape)[:-1], bool)
    for sp in arrays.spheres.astype(np.float64):
        hit |= _sphere_t(o, d, sp) < tmax
    for pl in arrays.planes.astype(np.float64):
        hit |= _plane_t(o, d, pl) < tmax
    for tri in arrays.tris.astype(np.float64):
        hit |= _triangle_t(o, d, tri)[0] < tmax
    return hit


def ray_offset(p, n, d, t):
    """Twin of kernels/scene.h ray_offset: off the surface, towards the viewer, relative to |p| + t."""
    eps = 1e-5 * (np.abs(p).max(-1) + t)
    return p + eps[..., None] * (n - d)


def _sphere_roots(o, d, sp):
    """Both roots t0 <= t1 of rays with a sphere (inf where it is missed): the stable quadratic."""
    c, r = sp[0, :3], sp[0, 3]
    f = o - c
    b = -(f * d).sum(-1)
    perp = f + b[..., None] * d
    disc = r * r - (perp ** 2).sum(-1)
    q = b + np.copysign(np.sqrt(np.maximum(disc, 0)), b)
    cc = (f ** 2).sum(-1) - r * r
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = np.where(q != 0, cc / q, 0.0)
    lo, hi = np.minimum(t0, q), np.maximum(t0, q)
    miss = disc < 0
    return np.where(miss, np.inf, lo), np.where(miss, np.inf, hi)


def primary(cam: dict, arrays, tex=None):
    """Hit records per sample (pixel-major, spp-minor, like the kernel): position, distance,
    shading normal towards the viewer, material, and what was hit (kind 1 sphere, 2 plane, 3
    triangle; its index; a triangle's barycentrics of v1, v2). With `tex` (textures()) a material's
    cut-outs and back faces are not hit, as kernels/scene.h surface_present."""
    w, h = cam["resolution"]
    spp = cam["spp"]
    pos, fwd, right, up, ortho = camera_vectors(cam)
    jit = pixel_jitter(spp)
    px = np.arange(w * h * spp)
    s, pix = px % spp, px // spp
    sx = 2.0 * ((pix % w) + jit[s, 0]) / w - 1.0
    sy = 1.0 - 2.0 * ((pix // w) + jit[s, 1]) / h
    if ortho:
        o = pos + sx[:, None] * right + sy[:, None] * up
        d = np.broadcast_to(fwd, o.shape).copy()
    else:
        d = fwd + sx[:, None] * right + sy[:, None] * up
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        o = np.broadcast_to(pos, d.shape).copy()
    n = len(d)
    t_best = np.full(n, np.inf)
    ng = np.zeros((n, 3))
    ns = np.zeros((n, 3))
    mat = np.full(n, -1)
    kind, index, bary = np.zeros(n, np.int64), np.full(n, -1), np.zeros((n, 2))
    ints = lambda a: np.asarray(a, np.float32).view(np.int32)
    present = (lambda k, i, t, b: _present(k, i, o, d, t, b, arrays, tex)) if tex is not None else None
    for i, sp in enumerate(arrays.spheres.astype(np.float64)):
        t0, t1 = _sphere_roots(o, d, sp)
        t = np.where(t0 > 0, t0, t1)
        if present is not None:            # the near side cut out or a back face: the far side
            t = np.where(present(1, i, np.where(np.isfinite(t), t, 0), None) | ~np.isfinite(t), t,
                         np.where(t1 > t, t1, np.inf))
            t = np.where(np.isfinite(t) & present(1, i, np.where(np.isfinite(t), t, 0), None), t, np.inf)
        t = np.where(t > 0, t, np.inf)
        better = t < t_best
        t_best[better] = t[better]
        c, r = sp[0, :3], sp[0, 3]
        nn = (o[better] + t[better, None] * d[better] - c) / r
        ng[better] = ns[better] = nn / np.linalg.norm(nn, axis=1, keepdims=True)
        mat[better] = ints(sp[1, 0])
        kind[better], index[better] = 1, i
    for i, pl in enumerate(arrays.planes.astype(np.float64)):
        t = _plane_t(o, d, pl)
        if present is not None:
            t = np.where(np.isfinite(t) & present(2, i, np.where(np.isfinite(t), t, 0), None), t, np.inf)
        better = t < t_best
        t_best[better] = t[better]
        ng[better] = ns[better] = pl[1, :3]
        mat[better] = ints(pl[0, 3])
        kind[better], index[better] = 2, i
    tris = arrays.tris.astype(np.float64)
    for k in range(len(tris)):
        t, u, v = _triangle_t(o, d, tris[k])
        if present is not None:
            fin = np.isfinite(t)
            t = np.where(fin & present(3, k, np.where(fin, t, 0), np.stack([u, v], 1)), t, np.inf)
        better = t < t_best
        if not better.any():
            continue
        t_best[better] = t[better]
        v0 = tris[k, 0, :3]
        fn = np.cross(tris[k, 1, :3] - v0, tris[k, 2, :3] - v0)
        fn /= np.linalg.norm(fn)
        b0 = 1 - u[better] - v[better]
        sn = b0[:, None] * tris[k, 3, :3] + u[better, None] * tris[k, 4, :3] + v[better, None] * tris[k, 5, :3]
        ln = np.linalg.norm(sn, axis=1, keepdims=True)
        sn = np.where(ln > 1e-12, sn / np.maximum(ln, 1e-300), fn)
        sn = np.where((sn @ fn)[:, None] < 0, -sn, sn)
        ng[better] = fn
        ns[better] = sn
        mat[better] = ints(tris[k, 0, 3])
        kind[better], index[better] = 3, k
        bary[better] = np.stack([u[better], v[better]], 1)
    hit = np.isfinite(t_best)
    flip = ((ng * d).sum(1) > 0)[:, None]
    ng_front = ng.copy()
    ng = np.where(flip, -ng, ng)
    ns_front = ns.copy()
    ns = np.where(flip, -ns, ns)
    return {"hit": hit, "t": t_best, "pos": o + np.where(hit, t_best, 0)[:, None] * d, "normal": ns,
            "material": mat, "dir": d, "kind": kind, "index": index, "bary": bary, "flip": flip[:, 0],
            "geometric": ng, "front_normal": ns_front, "front_geometric": ng_front}


# --- textures: the twin of kernels/scene.h hit_texcoords and surface_present, gbuffer.cl's
# surface coordinates and kernels/material.cl -------------------------------------------------

def textures(scene, arrays):
    """What the kernels read of the scene's textures: {"set": TextureSet, "slots", "mat_maps"},
    decoded and filtered by the same host code the renderer uses."""
    from iblbake.scene import materials, textures as scene_textures

    ts, slots = materials.load_textures(arrays.records, scene.source)
    _texels, levels, info = ts.arrays()
    return {"set": ts, "slots": slots, "mat_maps": materials.device_arrays(
        arrays.records, slots, scene_textures.sizes(levels, info))[1].astype(np.float64)}


def _hit_material(kind, index, p, arrays):
    """(material, front geometric normal) per ray of one primitive."""
    ints = lambda a: np.asarray(a, np.float32).view(np.int32)
    if kind == 1:
        sp = arrays.spheres[index].astype(np.float64)
        g = (p - sp[0, :3]) / sp[0, 3]
        return int(ints(arrays.spheres[index, 1, 0])), g / np.linalg.norm(g, axis=-1, keepdims=True)
    if kind == 2:
        return int(ints(arrays.planes[index, 0, 3])), np.broadcast_to(arrays.planes[index, 1, :3].astype(np.float64), p.shape)
    tri = arrays.tris[index].astype(np.float64)
    fn = np.cross(tri[1, :3] - tri[0, :3], tri[2, :3] - tri[0, :3])
    return int(ints(arrays.tris[index, 0, 3])), np.broadcast_to(fn / np.linalg.norm(fn), p.shape)


def hit_texcoords(kind, index, p, bary, arrays):
    """(u0, v0, u1, v1) per ray of one primitive (kernels/scene.h hit_texcoords)."""
    if kind == 1:
        sp = arrays.spheres[index].astype(np.float64)
        nl = (p - sp[0, :3]) / sp[0, 3]
        u = 0.5 - np.arctan2(nl[:, 0], nl[:, 2]) / (2 * np.pi)
        v = np.arccos(np.clip(nl[:, 1], -1, 1)) / np.pi
        return np.stack([u, v, u, v], 1)
    if kind == 2:
        pl = arrays.planes[index].astype(np.float64)
        q = p - pl[0, :3]
        a, b = q @ pl[2, :3], q @ pl[3, :3]
        u = a if np.isinf(pl[2, 3]) else 0.5 + 0.5 * a / pl[2, 3]
        v = -b if np.isinf(pl[3, 3]) else 0.5 - 0.5 * b / pl[3, 3]
        return np.stack([u, v, u, v], 1)
    at = arrays.tri_attr[index].astype(np.float64)
    b1, b2 = bary[:, 0:1], bary[:, 1:2]
    return (1 - b1 - b2) * at[0] + b1 * at[1] + b2 * at[2]


def _slot(tex, m, kind):
    """(texture, UV set, KHR_texture_transform's 2 x 3 rows, mip level offset) of a material's map
    slot (kernels/texture.h map_slot, map_uv, map_lod)."""
    from iblbake.scene.layout import MAP_KINDS
    k = MAP_KINDS.index(kind)
    rows = tex["mat_maps"][m, 2 + 3 * k:5 + 3 * k]
    texture = int(np.asarray(rows[0, 3], np.float32).view(np.int32))
    texcoord = int(np.asarray(rows[1, 3], np.float32).view(np.int32))
    return texture, texcoord, rows[:2, :3], rows[2, 0]


def map_uv(rows, texcoord, uv01):
    uv = uv01[:, 2:4] if texcoord == 1 else uv01[:, 0:2]
    return uv @ rows[:, :2].T + rows[:, 2]


def _present(kind, index, o, d, t, bary, arrays, tex):
    """Whether each ray's candidate hit on one primitive is there (kernels/scene.h surface_present)."""
    from iblbake.scene import textures as scene_textures

    p = o + t[:, None] * d
    m, g = _hit_material(kind, index, p, arrays)
    mm = tex["mat_maps"][m]
    ok = np.ones(len(t), bool)
    if mm[1, 0] > 0.5:
        ok &= (g * d).sum(1) <= 0
    if mm[0, 1] >= 0:
        alpha = np.full(len(t), mm[0, 0])
        texture, texcoord, rows, _lod = _slot(tex, m, "base_color")
        if texture >= 0:
            uv = map_uv(rows, texcoord, hit_texcoords(kind, index, p, bary, arrays))
            alpha = alpha * scene_textures.sample(tex["set"].textures[texture], uv, np.zeros(len(t)))[:, 3]
        ok &= alpha >= mm[0, 1]
    return ok


def gbuffer_coords(gb, arrays, cam):
    """The texture coordinates, tangent (w: the bitangent's side, negated with the tangent on a
    back face) and footprint level of each set at every hit (kernels/gbuffer.cl hit_tangent)."""
    hit = gb["hit"]
    n = len(hit)
    uv, tan, lod = np.zeros((n, 4)), np.zeros((n, 4)), np.zeros((n, 2))
    _pos, _fwd, _right, up, ortho = camera_vectors(cam)
    pixel = 2 * np.linalg.norm(up) / (cam["resolution"][1] * math.sqrt(cam["spp"]))
    for kind in (1, 2, 3):
        for index in np.unique(gb["index"][hit & (gb["kind"] == kind)]):
            sel = hit & (gb["kind"] == kind) & (gb["index"] == index)
            p, ns, bary = gb["pos"][sel], gb["front_normal"][sel], gb["bary"][sel]
            uv[sel] = hit_texcoords(kind, index, p, bary, arrays)
            if kind == 1:
                sp = arrays.spheres[index].astype(np.float64)
                nl = (p - sp[0, :3]) / sp[0, 3]
                t = np.stack([-nl[:, 2], np.zeros(len(p)), nl[:, 0]], 1)
                w = -np.ones(len(p))
                st = np.maximum(np.sqrt(np.maximum(0, 1 - nl[:, 1] ** 2)), 1e-4)
                dens = np.repeat((-0.5 * np.log2(2 * np.pi ** 2 * sp[0, 3] ** 2 * st))[:, None], 2, 1)
            elif kind == 2:
                pl = arrays.planes[index].astype(np.float64)
                t = np.broadcast_to(pl[2, :3], p.shape).copy()
                w = -np.ones(len(p))
                dd = (0.0 if np.isinf(pl[2, 3]) else -np.log2(2 * pl[2, 3])) + \
                     (0.0 if np.isinf(pl[3, 3]) else -np.log2(2 * pl[3, 3]))
                dens = np.full((len(p), 2), 0.5 * dd)
            else:
                at = arrays.tri_attr[index].astype(np.float64)
                b1, b2 = bary[:, 0:1], bary[:, 1:2]
                t = ((1 - b1 - b2) * at[3] + b1 * at[4] + b2 * at[5])[:, :3]
                w = np.full(len(p), -1.0 if at[3, 3] < 0 else 1.0)
                dens = np.broadcast_to(at[6, :2], (len(p), 2))
            t = t - ns * (ns * t).sum(1, keepdims=True)
            lt = np.linalg.norm(t, axis=1, keepdims=True)
            frame = conventions.tangent_frame(ns)[0]
            t = np.where(lt > 1e-12, t / np.maximum(lt, 1e-300), frame)
            flip = gb["flip"][sel][:, None]
            tan[sel] = np.concatenate([np.where(flip, -t, t), np.where(flip[:, 0], -w, w)[:, None]], 1)
            cone = pixel if ortho else pixel * gb["t"][sel]
            cos = np.abs((gb["front_geometric"][sel] * gb["dir"][sel]).sum(1))
            lod[sel] = np.log2(cone / np.maximum(cos, 1e-6))[:, None] + dens
    gb.update(uv=uv, tangent=tan, lod=lod)
    return gb


def resolve_materials(gb, arrays, tex):
    """Each hit's material from its factors and maps (kernels/material.cl): gb["resolved"] =
    (base, metallic, emissive, roughness, shading normal, occlusion) of the hits."""
    from iblbake.scene import textures as scene_textures

    hit = gb["hit"]
    idx = gb["material"][hit]
    m = arrays.materials.astype(np.float64)[idx]
    base, metallic, emissive, rough = m[:, 0, :3].copy(), m[:, 0, 3].copy(), m[:, 1, :3].copy(), m[:, 1, 3].copy()
    nrm, occ = gb["normal"][hit].copy(), np.ones(len(idx))
    uv01, lods, tan = gb["uv"][hit], gb["lod"][hit], gb["tangent"][hit]
    for mi in np.unique(idx):
        sel = idx == mi
        mm = tex["mat_maps"][mi]

        def fetch(kind):
            texture, texcoord, rows, offset = _slot(tex, mi, kind)
            if texture < 0:
                return None
            lod = lods[sel, 1 if texcoord == 1 else 0] + offset
            return scene_textures.sample(tex["set"].textures[texture], map_uv(rows, texcoord, uv01[sel]), lod)

        c = fetch("base_color")
        if c is not None:
            base[sel] *= c[:, :3]
        c = fetch("metallic_roughness")
        if c is not None:
            metallic[sel] *= c[:, 2]
            rough[sel] *= c[:, 1]
        c = fetch("normal")
        if c is not None:
            tn = c[:, :3].copy()
            tn[:, :2] *= mm[0, 2]
            nn = nrm[sel]
            bt = tan[sel, 3:4] * np.cross(nn, tan[sel, :3])
            pp = tan[sel, :3] * tn[:, 0:1] + bt * tn[:, 1:2] + nn * tn[:, 2:3]
            lp = np.linalg.norm(pp, axis=1, keepdims=True)
            nrm[sel] = np.where(lp > 1e-12, pp / np.maximum(lp, 1e-300), nn)
        c = fetch("occlusion")
        if c is not None:
            occ[sel] = 1 + mm[0, 3] * (c[:, 0] - 1)
        c = fetch("emissive")
        if c is not None:
            emissive[sel] *= c[:, :3]
    gb["resolved"] = (base, np.clip(metallic, 0, 1), emissive, np.clip(rough, 0, 1), nrm, np.clip(occ, 0, 1))
    return gb


def _materials(arrays, idx):
    m = arrays.materials.astype(np.float64)[idx]
    base, metallic, emissive, rough = m[:, 0, :3], m[:, 0, 3], m[:, 1, :3], m[:, 1, 3]
    f0 = 0.04 * (1 - metallic[:, None]) + base * metallic[:, None]
    return base, metallic, emissive, rough, f0


def facing_normal(n, v):
    nov = (n * v).sum(1, keepdims=True)
    bent = n + (1e-4 - nov) * v
    bent /= np.linalg.norm(bent, axis=1, keepdims=True)
    return np.where(nov >= 1e-4, n, bent)


def to_env(d, rotation_y_deg):
    return conventions.rotate_y(d, -rotation_y_deg)


def surface(gb, arrays):
    """Twin of surface_at for every hit sample: view vectors, bent shading normals, NoV and the
    material columns (base, metallic, emissive, roughness, F0): from the material table, or
    resolve_materials()'s where it ran."""
    hit = gb["hit"]
    v = -gb["dir"][hit]
    if "resolved" in gb:
        base, metallic, emissive, rough, nrm, _occ = gb["resolved"]
        n = facing_normal(nrm, v)
        f0 = 0.04 * (1 - metallic[:, None]) + base * metallic[:, None]
        return v, n, np.maximum((n * v).sum(1), 1e-4), (base, metallic, emissive, rough, f0)
    n = facing_normal(gb["normal"][hit], v)
    return v, n, np.maximum((n * v).sum(1), 1e-4), _materials(arrays, gb["material"][hit])


def material_occlusion(gb):
    """The resolved materials' occlusion (1 without textures), per hit."""
    return gb["resolved"][5] if "resolved" in gb else np.ones(int(gb["hit"].sum()))


def diffuse_weight(base, metallic, rough, f0, nov):
    kd = (1 - brdf.f_schlick_roughness(nov[:, None], f0, rough[:, None])) * (1 - metallic[:, None])
    return kd * base / math.pi


def shade(gb, arrays, effects: dict, env: dict, *, sh_coeffs=None, chain=None, prefiltered=None, dfg=None,
          ao=None):
    """Per-sample radiance of the `shade` pass, with the `importance` pass's sums for it (hits
    only; misses are 0); `ao` the ambient occlusion of every sample (ambient_occlusion) where
    effects.ao is on. The importance estimate is summed with Fresnel inside, which the kernels
    split around f0: the same sum, to float rounding."""
    hit = gb["hit"]
    out = np.zeros((len(hit), 3))
    v, n, nov, (base, metallic, emissive, rough, f0) = surface(gb, arrays)
    alpha = rough ** 2
    rot, scale = env["rotation_y"], env["intensity"]
    color = np.zeros_like(emissive)
    occ = ao[hit] if ao is not None else np.ones(len(n))
    spec_occ = specular_occlusion(nov, occ, rough)[:, None]
    if effects["diffuse"] == "sh":
        e = np.maximum(sh.evaluate(sh_coeffs, to_env(n, rot), effects["sh_bands"]), 0.0)
        diff_occ = ao_multibounce(occ, base * (1 - metallic[:, None])) if effects["ao_multibounce"] else occ[:, None]
        color += diff_occ * diffuse_weight(base, metallic, rough, f0, nov) * scale * e
    if effects["specular"] == "importance":
        nsamp = effects["samples"]
        pts = sampling.hammersley(nsamp).astype(np.float32).astype(np.float64)
        t, b = conventions.tangent_frame(n)
        h0, w0 = chain[0].shape[:2]
        acc = np.zeros((len(n), 3))
        accepted = np.zeros(len(n))
        for u in pts:
            hl = sampling.sample_ggx_half(np.broadcast_to(u, (len(n), 2)), alpha)
            h = t * hl[:, 0:1] + b * hl[:, 1:2] + n * hl[:, 2:3]
            voh = (v * h).sum(1)
            l = 2 * voh[:, None] * h - v
            nol = (n * l).sum(1)
            ok = (nol > 0) & (voh > 0)
            noh = np.maximum(hl[:, 2], 1e-7)
            le = to_env(l, rot)
            if effects["force_mip0"]:
                lod = np.zeros(len(n))
            else:
                pdf = brdf.d_ggx(noh, alpha) * noh / (4 * np.maximum(voh, 1e-30))
                with np.errstate(divide="ignore"):
                    lod = 0.5 * (np.log2(1.0 / (nsamp * pdf)) - np.log2(radiance.texel_solid_angle_at(w0, h0, le))) \
                        + effects["mip_bias"]
            li = radiance.chain_lookup_twin(chain, le, lod)
            wgt = brdf.v_smith_ggx_correlated(nov, nol, alpha) * 4 * nol * voh / noh
            contrib = li * brdf.f_schlick(voh[:, None], f0) * wgt[:, None]
            acc += np.where(ok[:, None], contrib, 0.0)
            accepted += ok
        div = np.maximum(accepted, 1)[:, None] if effects["normalize"] == "accepted" else nsamp
        color += spec_occ * scale * acc / div
    elif effects["specular"] == "prefiltered":
        r = 2 * (n * v).sum(1, keepdims=True) * n - v
        if effects["prefilter"]["dominant_direction"]:
            s = np.clip(1 - alpha, 0, 1)[:, None]
            r = n + (r - n) * (s * (np.sqrt(s) + alpha[:, None]))
            r /= np.linalg.norm(r, axis=1, keepdims=True)
        pre = radiance.chain_lookup_twin(prefiltered, to_env(r, rot), rough * (len(prefiltered) - 1))
        ab = dfg_lookup(dfg, nov, rough)
        color += spec_occ * scale * pre * (f0 * ab[:, 0:1] + ab[:, 1:2])
    elif effects["specular"] == "lobe":
        color += spec_occ * scale * lobe(v, n, nov, alpha, rough, f0, rot, effects["lobe"]["samples"],
                              effects["lobe"]["spread"], prefiltered, dfg)
    out[hit] = color * material_occlusion(gb)[:, None] + emissive
    return out


def specular_occlusion(nov, ao, roughness):
    """Twin of shade.cl specular_occlusion (Lagarde and de Rousiers 2014)."""
    return np.clip((nov + ao) ** np.exp2(-16 * roughness - 1) - 1 + ao, 0, 1)


def ao_multibounce(ao, albedo):
    """Twin of shade.cl ao_multibounce (Jimenez et al. 2016, eq. 10)."""
    a, b, c = 2.0404 * albedo - 0.3324, -4.7951 * albedo + 0.6417, 2.7552 * albedo + 0.6903
    v = ao[:, None]
    return np.maximum(v, ((v * a + b) * v + c) * v)


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
    from iblbake.render.passes.ao import gtao_step

    w, h = cam["resolution"]
    step = gtao_step(g)
    wl, hl = -(-w // step), -(-h // step)
    return step, wl, hl


def gtao(gb, cam: dict, effects: dict):
    """Twin of kernels/gtao.cl gtao: the raw visibility of every block (one pixel, or 2x2 at
    resolution half) from its first pixel's first sample, unclamped; (hl * wl,)."""
    from iblbake.render.passes.ao import GTAO_LEVELS

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


def ambient_occlusion(gb, arrays, effects: dict):
    """Twin of kernels/ao.cl: per G-buffer sample (misses 1) the fraction of ao_samples
    cosine-weighted rays with no hit closer than ao_radius."""
    hit = gb["hit"]
    out = np.ones(len(hit))
    v = -gb["dir"][hit]
    n = facing_normal(gb["normal"][hit], v)
    origin = ray_offset(gb["pos"][hit], n, gb["dir"][hit], gb["t"][hit])
    t, b = conventions.tangent_frame(n)
    sid = np.flatnonzero(hit)
    seed = effects["reference"]["seed"] ^ 0x5A0
    k_n = effects["ao_samples"]
    open_ = np.zeros(len(sid))
    for k in range(k_n):
        l = sampling.sample_cosine_hemisphere(_qmc2(seed, sid, k))
        d = t * l[:, 0:1] + b * l[:, 1:2] + n * l[:, 2:3]
        open_ += ~occluded(origin, d, arrays, effects["ao_radius"])
    out[hit] = open_ / k_n
    return out


def lobe(v, n, nov, alpha, rough, f0, rot, k, spread, prefiltered, dfg):
    """Twin of shade.cl's SPECULAR_LOBE block (see the comment there): K visible-normal samples,
    each reading the prefiltered chain at its share of the lobe, their weighted mean times the
    DFG table's albedo."""
    pts = sampling.lobe_points(k).astype(np.float32).astype(np.float64)
    t, b = conventions.tangent_frame(n)
    vl = np.stack([(v * t).sum(1), (v * b).sum(1), nov], -1)
    g1 = sampling.g1_smith(nov, alpha)
    nlev = len(prefiltered)
    num = np.zeros((len(n), 3))
    den = np.zeros((len(n), 3))
    for u in pts:
        hl = sampling.sample_ggx_vndf(vl, alpha, np.broadcast_to(u, (len(n), 2)))
        h = t * hl[:, 0:1] + b * hl[:, 1:2] + n * hl[:, 2:3]
        voh = (v * h).sum(1)
        l = 2 * voh[:, None] * h - v
        nol = (n * l).sum(1)
        ok = (nol > 0) & (voh > 0)
        pdf = g1 * brdf.d_ggx(hl[:, 2], alpha) / (4 * nov)
        a = np.minimum(np.sqrt(spread / (4 * np.pi * k * pdf)), alpha)
        w = brdf.f_schlick(voh[:, None], f0) * (brdf.v_smith_ggx_correlated(nov, nol, alpha) * 4 * nov * nol / g1)[:, None]
        w = np.where(ok[:, None], w, 0.0)
        num += w * radiance.chain_lookup_twin(prefiltered, to_env(l, rot), np.sqrt(a) * (nlev - 1))
        den += w
    r = 2 * nov[:, None] * n - v
    fallback = radiance.chain_lookup_twin(prefiltered, to_env(r, rot), rough * (nlev - 1))
    li = np.where(den[:, :1] > 0, num / np.where(den > 0, den, 1.0), fallback)
    ab = dfg_lookup(dfg, nov, rough)
    return li * (f0 * ab[:, 0:1] + ab[:, 1:2])


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


def light_brdf_cos(base, metallic, rough, f0, n, v, nov, l, diffuse: bool, specular: bool, sin_max=None):
    """Twin of kernels/lights.cl light_brdf_cos: f(v, l) NoL, per hit and colour channel; with
    sin_max the specular term at the representative point of a light that size."""
    nol = (n * l).sum(-1)
    out = np.zeros(l.shape[:-1] + (3,))
    if diffuse:
        out += np.where((nol > 0)[:, None], diffuse_weight(base, metallic, rough, f0, nov) * np.maximum(nol, 0)[:, None], 0)
    if specular:
        alpha = rough ** 2
        ls, energy = representative_point(n, v, l, sin_max, alpha) if sin_max is not None else (l, 1.0)
        nols = (n * ls).sum(-1)
        h = v + ls
        h /= np.linalg.norm(h, axis=-1, keepdims=True)
        spec = (brdf.d_ggx((n * h).sum(-1), alpha) * brdf.v_smith_ggx_correlated(nov, np.maximum(nols, 0), alpha)
                * energy * np.maximum(nols, 0))[:, None] * brdf.f_schlick((v * h).sum(-1)[:, None], f0)
        out += np.where((nols > 0)[:, None], spec, 0)
    return out


def _qmc2(seed, sid, k):
    """Sample k of the 2D stream of each sample sid (kernels/sampling.h qmc, dimensions 0 and 1)."""
    return np.stack([sampling.qmc(seed, sid, k, 0), sampling.qmc(seed, sid, k, 1)], -1)


def _cone_direction(a, omc, u):
    x = u[..., 0] * omc
    ct, st, phi = 1 - x, np.sqrt(np.maximum(0, x * (2 - x))), 2 * np.pi * u[..., 1]
    t, b = conventions.tangent_frame(a)
    d = t * (st * np.cos(phi))[:, None] + b * (st * np.sin(phi))[:, None] + a * ct[:, None]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def lights(gb, arrays, records, effects: dict, *, diffuse=True, specular=True, exact=False, visibility=True,
           representative=True):
    """Per-sample radiance of the `lights` pass (hits only; misses are 0): records from
    scene.pack.light_records, effects the scene's (reference seed and max_samples);
    representative=False shades a light with a size from its centre alone (for comparison)."""
    hit = gb["hit"]
    out = np.zeros((len(hit), 3))
    v, n, nov, (base, metallic, _, rough, f0) = surface(gb, arrays)
    p = gb["pos"][hit]
    origin = ray_offset(p, n, gb["dir"][hit], gb["t"][hit])
    sid = np.flatnonzero(hit)              # each G-buffer sample's random stream (one tile)
    seed = effects["reference"]["seed"]
    color = np.zeros((len(p), 3))
    shade = lambda l: light_brdf_cos(base, metallic, rough, f0, n, v, nov, l, diffuse, specular)   # noqa: E731
    for j, r in enumerate(records.astype(np.float64)):
        kind, e = int(r[0, 3]), np.broadcast_to(r[1, :3], (len(p), 3)).copy()
        if kind == 0:
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
        omc = sin_max ** 2 / (1 + np.sqrt(np.maximum(0, 1 - sin_max ** 2)))
        ls = int(np.uint32(seed) ^ sampling.pcg_hash(j + 1))
        ns = effects["reference"]["max_samples"] if exact else int(r[3, 3])
        mode = int(r[1, 3])

        if exact and (sin_max > 0).any():
            le = e / (np.pi * sin_max ** 2)[:, None]
            acc = np.zeros((len(p), 3))
            for k in range(ns):
                l = _cone_direction(wc, omc, _qmc2(ls, sid, k))
                ok = ~occluded(origin, l, arrays, dist) if visibility else np.ones(len(p), bool)
                acc += np.where(ok[:, None], shade(l), 0.0)
            color += le * (2 * np.pi * omc)[:, None] * acc / ns
            continue
        if exact:
            vis = (~occluded(origin, wc, arrays, dist)).astype(float) if visibility else np.ones(len(p))
        elif mode == 1 or (mode == 2 and (sin_max <= 0).all()):
            vis = (~occluded(origin, wc, arrays, dist)).astype(float)
        elif mode == 2:             # soft: the share of ns rays over the disk or sphere that arrive
            vis = sum(~occluded(origin, _cone_direction(wc, omc, _qmc2(ls, sid, k)), arrays, dist)
                      for k in range(ns)) / ns
        else:
            vis = np.ones(len(p))
        color += vis[:, None] * e * light_brdf_cos(base, metallic, rough, f0, n, v, nov, wc, diffuse, specular,
                                                   sin_max if representative and not exact else None)
    out[hit] = color
    return out


DELTA_ALPHA = 1e-4   # kernels/reference.cl: narrower GGX lobes are mirrors in the reference


def exact(gb, arrays, effects: dict, env: dict, image, sub: int = 2, chunk: int = 256):
    """What the `reference` pass converges to, by quadrature over the panorama's texels."""
    hit = gb["hit"]
    out = np.zeros((len(hit), 3))
    v, n, nov, (base, metallic, emissive, rough, f0) = surface(gb, arrays)
    alpha = rough ** 2
    hgt, wid = image.shape[:2]
    dirs, omega = prefilter.texel_subsamples(wid, hgt, sub)
    dirs = conventions.rotate_y(dirs.reshape(-1, 3), env["rotation_y"])     # panorama -> world
    omega = omega.reshape(-1)
    radiance = np.repeat(image.reshape(-1, 3).astype(np.float64), sub * sub, axis=0) * env["intensity"]
    res = np.zeros((len(n), 3))
    kd = diffuse_weight(base, metallic, rough, f0, nov)
    delta = alpha < DELTA_ALPHA
    visibility = effects["reference"]["visibility"]
    if visibility:
        origin = ray_offset(gb["pos"][hit], n, gb["dir"][hit], gb["t"][hit])
    for i0 in range(0, len(n), chunk):
        sl = slice(i0, i0 + chunk)
        nol = n[sl] @ dirs.T                                            # (c, dirs)
        w = np.where(nol > 0, nol, 0.0) * omega
        if visibility:
            w = np.where(occluded(origin[sl, None, :], dirs[None], arrays), 0.0, w)
        if effects["diffuse"] == "reference":
            res[sl] += kd[sl] * (w @ radiance)
        if effects["specular"] == "reference" and not delta[sl].all():
            hv = v[sl, None, :] + dirs[None]
            hv /= np.linalg.norm(hv, axis=2, keepdims=True)
            noh = (hv * n[sl, None, :]).sum(2)
            voh = (hv * v[sl, None, :]).sum(2)
            dv = brdf.d_ggx(noh, alpha[sl, None]) * brdf.v_smith_ggx_correlated(nov[sl, None], nol, alpha[sl, None])
            fw = (1 - np.clip(voh, 0, 1)) ** 5                          # Schlick: F0 + (1 - F0) fw
            a = (dv * w) @ radiance
            bsum = (dv * w * fw) @ radiance
            res[sl] += np.where(delta[sl, None], 0.0, f0[sl] * a + (1 - f0[sl]) * bsum)
    if effects["specular"] == "reference" and delta.any():
        # a lobe narrower than float32 resolves (the kernel's DELTA_ALPHA) is a mirror: F(NoV) L(R),
        # L read as the kernel reads it (nearest texel)
        r = 2 * nov[delta, None] * n[delta] - v[delta]
        seen = ~occluded(origin[delta], r, arrays) if visibility else np.ones(len(r), bool)
        u, w = conventions.equirect_uv_from_dir(to_env(r, env["rotation_y"]))
        i = np.minimum((u * wid).astype(np.int64), wid - 1)
        j = np.minimum((w * hgt).astype(np.int64), hgt - 1)
        res[delta] += (image[j, i].astype(np.float64) * env["intensity"]
                       * brdf.f_schlick(nov[delta, None], f0[delta])) * seen[:, None]
    out[hit] = res * material_occlusion(gb)[:, None]      # the occlusion map: image-based light only
    return out
