"""Local reflection probes (kernels/reflection_probes.h): each probe's fade, the parallax-corrected
direction, the sky it saw and the blend with the distant chain. numpy twin, float64."""

from __future__ import annotations

import numpy as np

from iblbake.bake import radiance
from iblbake.core import brdf, conventions, sampling


def weight(st: dict, p):
    """Twin of rprobe_weight for points p (m, 3) and one probe's settings."""
    if st["shape"] == "box":
        lo, hi = np.asarray(st["min"], np.float64), np.asarray(st["max"], np.float64)
        half = 0.5 * (hi - lo)
        over = ((np.abs(p - 0.5 * (lo + hi)) - half) / half).max(-1)
    else:
        over = np.linalg.norm(p - np.asarray(st["position"]), axis=-1) / st["radius"] - 1
    fade = np.maximum(1 - over / st["blend"], 0.0) if st["blend"] > 0 else np.zeros_like(over)
    return np.where(over <= 0, 1.0, fade)


def exit_point(st: dict, p, r):
    """Twin of rprobe_exit: where p + t r leaves the probe's box or sphere."""
    pos = np.asarray(st["position"], np.float64)
    if st["shape"] == "box":
        lo, hi = np.asarray(st["min"], np.float64), np.asarray(st["max"], np.float64)
        far = np.where(r > 0, hi, lo)
        with np.errstate(divide="ignore", invalid="ignore"):
            tt = np.where(r != 0, (far - p) / np.where(r != 0, r, 1), np.inf)
        t = tt.min(-1)
    else:
        o = p - pos
        b = (o * r).sum(-1)
        c = (o * o).sum(-1) - st["radius"] ** 2
        t = -b + np.sqrt(np.maximum(b * b - c, 0.0))
    return p + np.maximum(t, 0.0)[:, None] * r


MARCH, REFINE, BEHIND = 16, 4, 0.005  # kernels/reflection_probes.h RPROBE_MARCH, RPROBE_REFINE, RPROBE_BEHIND


def depth(c: dict, o, q):
    """Twin of rprobe_depth: the distance from the probe at o to what capture c saw towards q (its
    distance chain, the ratio to the proxy's distance, times that distance)."""
    d = q - o
    length = np.linalg.norm(d, axis=-1, keepdims=True)
    d = d / np.maximum(length, 1e-300)
    ratio = radiance.chain_lookup_twin(c["depth"][:1], d, 0.0)[:, 0]
    proxy = np.linalg.norm(exit_point(c["settings"], np.broadcast_to(o, d.shape), d) - o, axis=-1)
    return np.where(length[:, 0] < 1e-6, 0.0, ratio * proxy)


def marches(c: dict) -> bool:
    """Whether capture c's reads march its distance chain (rp_info's fourth w): it has one, and it
    sees something in front of its proxy. Where every texel's ratio is 1 / (1 + BEHIND) or more
    no step inside the proxy goes behind the captured surface by BEHIND of its distance: the march
    would end at the proxy's exit (a closed room, the object at the probe excluded)."""
    return c.get("depth") is not None and float(np.min(c["depth"][0])) < 1.0 / (1.0 + BEHIND)


def hit(c: dict, p, r):
    """Twin of rprobe_hit: where p + t r meets the surface capture c saw (its distance chain marched
    in MARCH even steps to the proxy's exit, the first step behind it by BEHIND of the distance
    refined by REFINE secant steps), the proxy's exit where it does not march or no step goes
    behind."""
    x = exit_point(c["settings"], p, r)
    return march(c, p, r, x) if marches(c) else x


def march(c: dict, p, r, x):
    """rprobe_hit's march from p along r to the proxy's exit x."""
    o = np.asarray(c["settings"]["position"], np.float64)
    far = np.linalg.norm(x - p, axis=-1)
    t0, f0 = np.zeros(len(p)), np.linalg.norm(p - o, axis=-1) - depth(c, o, p)
    out, done = x.copy(), np.zeros(len(p), bool)
    for i in range(1, MARCH + 1):
        t1 = far * i / MARCH
        q = p + t1[:, None] * r
        dq = depth(c, o, q)
        f1 = np.linalg.norm(q - o, axis=-1) - dq
        cross = ~done & (f0 <= 0) & (f1 > BEHIND * dq)
        if cross.any():
            out[cross] = _secant(c, o, p[cross], r[cross], t0[cross], f0[cross], t1[cross], f1[cross])
            done |= cross
        t0, f0 = t1, f1
    return out


def _secant(c: dict, o, p, r, lo, flo, hi, fhi):
    """REFINE secant steps of rprobe_hit within [lo, hi] (in front at lo, behind at hi)."""
    def root(lo, flo, hi, fhi):
        return lo + (hi - lo) * flo / np.minimum(flo - fhi, -1e-12)
    for _ in range(REFINE):
        t = root(lo, flo, hi, fhi)
        m = p + t[:, None] * r
        fm = np.linalg.norm(m - o, axis=-1) - depth(c, o, m)
        behind = fm > 0
        hi, fhi = np.where(behind, t, hi), np.where(behind, fm, fhi)
        lo, flo = np.where(behind, lo, t), np.where(behind, flo, fm)
    return p + root(lo, flo, hi, fhi)[:, None] * r


NEAR, FAR, FINEST = 0.1, 0.4, 2.0      # kernels/reflection_probes.h RPROBE_NEAR, RPROBE_FAR, RPROBE_FINEST


SKY_SEEN = 0.05       # kernels/reflection_probes.h RPROBE_SKY_SEEN
EDGE = 0.02           # kernels/reflection_probes.h RPROBE_TAP_EDGE
TAP_SEED = 0x7A95     # kernels/reflection_probes.h RPROBE_TAP_SEED


def open_sky(c: dict, r, lod, distant):
    """Twin of rprobe_open_sky: the sky capture c saw through its openings about r per unit of open
    share, at the finest of the lobe's level and three wider ones where it saw SKY_SEEN open;
    `distant` where it saw none."""
    top = len(c["coverage"]) - 1
    out, done = distant.copy(), np.zeros(len(r), bool)
    for widen in (0.0, 0.25, 0.5, 1.0):
        level = np.minimum(lod + widen * top, top)
        seen = 1 - radiance.chain_lookup_twin(c["coverage"], r, level)[:, 0]
        take = ~done & (seen > SKY_SEEN)
        out[take] = (radiance.chain_lookup_twin(c["sky"], r, level) / np.maximum(seen, 1e-30)[:, None])[take]
        done |= take
    return out


def near(c: dict, shift, lod):
    """Twin of rprobe_near: 1 while the opening's shift as p sees it is within the lobe's width
    (2 alpha), 0 at twice it."""
    rough = lod / max(len(c["coverage"]) - 1, 1)
    return np.clip(2 - shift / np.maximum(2 * rough * rough, 1e-6), 0.0, 1.0)


def sky(c: dict, r, lod, open_, off, shift, distant):
    """Twin of rprobe_sky: the sky capture c saw about r, times the share `open_` of the lobe p sees
    open over the share the probe saw, where that is less; `off` of the rest is filled with the sky
    the probe saw through its openings (open_sky) while the opening's shift as p sees it is within
    the lobe's width, the distant chain once it is twice that."""
    seen = np.maximum(1 - radiance.chain_lookup_twin(c["coverage"], r, lod)[:, :1], 0.0)
    got = radiance.chain_lookup_twin(c["sky"], r, lod)
    held = near(c, shift, lod)[:, None]
    fill = off * np.maximum(open_ - seen, 0.0)
    through = open_sky(c, r, lod, distant) if (held > 0).any() and (fill > 0).any() else distant
    return got * (np.minimum(open_, seen) / np.maximum(seen, 1e-6)) + fill * (held * through + (1 - held) * distant)


TAP_SPREAD = 0.5     # kernels/reflection_probes.h RPROBE_TAP_SPREAD


TAP_HORIZON = 0.05    # kernels/reflection_probes.h RPROBE_TAP_HORIZON


def tap_rough(pdf, nol, alpha, count: int):
    """Twin of rprobe_tap_rough: the roughness whose prefiltered lobe (about 4 pi alpha^2
    steradians) spans TAP_SPREAD of the solid angle 1 / (count pdf) a tap of pdf `pdf` (over
    directions) stands for (filtered importance sampling), no wider than the lobe's, its alpha
    within TAP_HORIZON NoL (above the surface)."""
    omega = TAP_SPREAD / np.maximum(count * pdf, 1e-20)
    a = np.minimum(np.sqrt(omega / (4 * np.pi)), TAP_HORIZON * nol)
    return np.minimum(np.sqrt(a), np.sqrt(alpha))


def tap_sky(c: dict, l, d, rough_t, env):
    """Twin of rprobe_tap_sky: the sky a tap along l (roughness rough_t) meets through capture c's
    openings per unit of the share p sees open: the capture's sky about l over its open share seen
    (the distant chain's where seen <= SKY_SEEN) on the part the probe saw too; the part p sees
    open beyond it (open: the coverage along d at the tap's level) the distant chain about l at
    rough_t times the square root of that part's share. Where an opening's edge crosses the tap's
    footprint (EDGE < seen < 1 - EDGE) the part the probe saw reads its sky along l at the capture's
    own level (the panorama's at level 0 where it saw none of l open). env: the distant chain, its
    rotation, its intensity."""
    chain, rot, scale = env
    tap = rough_t * max(len(c["levels"]) - 1, 1)
    seen = np.maximum(1 - radiance.chain_lookup_twin(c["coverage"], l, tap)[:, :1], 0.0)
    open_ = np.maximum(1 - radiance.chain_lookup_twin(c["coverage"], d, tap)[:, :1], 0.0)

    def distant(rough):
        return scale * radiance.chain_lookup_twin(chain, conventions.rotate_y(l, -rot), rough * (len(chain) - 1))

    def through_at(level, s, rough):          # the sky at `level` per unit of its open share s seen there
        return np.where(s > SKY_SEEN, radiance.chain_lookup_twin(c["sky"], l, level) / np.maximum(s, 1e-30),
                        distant(rough))
    edge = (seen > EDGE) & (seen < 1 - EDGE)
    through = through_at(tap, seen, rough_t)
    if edge.any():
        sharp = np.maximum(1 - radiance.chain_lookup_twin(c["coverage"], l, 0.0)[:, :1], 0.0)
        through = np.where(edge, through_at(0.0, sharp, 0.0), through)
    beyond = np.maximum(open_ - seen, 0.0)
    known = np.where(beyond > 0, seen / np.maximum(open_, 1e-30), 1.0)
    return known * through + (1 - known) * distant(rough_t * np.sqrt(beyond[:, 0]))


def tap_turn(sample):
    """Twin of rprobe_tap_turn: G-buffer sample number `sample`'s turn of its taps about the normal
    (a share of a whole turn)."""
    h = sampling.pcg_hash(np.uint32(TAP_SEED) ^ sampling.pcg_hash(np.asarray(sample, np.uint64).astype(np.uint32)))
    return (h >> 8).astype(np.float64) * (1.0 / 16777216.0)


def taps(c: dict, p, n, v, lod, env, count: int, sample):
    """Twin of rprobe_taps: the GGX lobe of normal n and view v (alpha rough^2, rough lod over the
    chain's last level) read in `count` directions l of its visible normals (Heitz 2018) at the
    Hammersley points turned about n by each point's G-buffer sample (tap_turn), each weighted as the BRDF
    over its pdf without Fresnel (V 4 NoV NoL / G1(NoV), none below the surface): the scene where
    l leaves the proxy, seen from the probe at the tap's own level (not floored at FINEST), and
    the sky along l itself (tap_sky; env: the distant chain, its rotation, its intensity), times
    whether p sees that direction open (the coverage at the capture's own level along the
    parallax-corrected direction); each tap at its own roughness (tap_rough)."""
    st, nlev = c["settings"], len(c["levels"])
    pos = np.asarray(st["position"], np.float64)
    top = max(nlev - 1, 1)
    alpha = (lod / top) ** 2
    nov = np.maximum((n * v).sum(1), 1e-4)
    t, b = conventions.tangent_frame(n)
    g1 = sampling.g1_smith(nov, alpha)
    turn = tap_turn(sample)
    acc, wsum = np.zeros((len(p), 3)), np.zeros((len(p), 1))
    for u in sampling.hammersley(count):
        hz, voh, l, nol = sampling.reflect_ggx_vndf(np.stack([np.full(len(p), u[0]), (u[1] + turn) % 1.0], -1),
                                                    t, b, n, v, nov, alpha)
        noh = np.maximum(hz, 1e-7)
        ok = (nol > 0) & (voh > 0)
        w = np.where(ok, brdf.v_smith_ggx_correlated(nov, nol, alpha) * 4 * nov * nol / g1, 0.0)[:, None]
        pdf = g1 * brdf.d_ggx(noh, alpha) / (4 * nov)
        rough_t = tap_rough(pdf, np.maximum(nol, 0.0), alpha, count)
        tap = rough_t * top
        x = hit(c, p, l)
        d = (x - pos) / np.maximum(np.linalg.norm(x - pos, axis=-1, keepdims=True), 1e-6)
        open_ = np.maximum(1 - radiance.chain_lookup_twin(c["coverage"], d, 0.0)[:, :1], 0.0)
        acc += w * (radiance.chain_lookup_twin(c["levels"], d, tap) + open_ * tap_sky(c, l, d, rough_t, env))
        wsum += w
    return acc / np.maximum(wsum, 1e-9)


def read(c: dict, p, r, lod, distant):
    """Twin of rprobe_read: capture c's one read at p along r (the scene along the direction
    corrected to where p's ray meets the capture, at the distance-narrowed level; the sky)."""
    st = c["settings"]
    d, near_lod, off, shift = r, lod, np.zeros((len(p), 1)), np.zeros(len(p))
    if st["parallax"]:
        pos = np.asarray(st["position"], np.float64)
        x = hit(c, p, r)
        from_probe = np.maximum(np.linalg.norm(x - pos, axis=-1), 1e-6)
        d = (x - pos) / from_probe[:, None]
        near_lod = np.maximum(lod * np.clip(np.linalg.norm(x - p, axis=-1) / from_probe, 0.0, 1.0),
                              np.minimum(lod, FINEST))
        shift = np.linalg.norm(p - pos, axis=-1) / from_probe
        off = np.clip((shift - NEAR) / (FAR - NEAR), 0.0, 1.0)[:, None]
    open_ = 1 - radiance.chain_lookup_twin(c["coverage"], d, near_lod)[:, :1]
    return radiance.chain_lookup_twin(c["levels"], d, near_lod) + sky(c, r, lod, open_, off, shift, distant)


GRAZING_LO, GRAZING_HI = 0.4, 0.8     # kernels/reflection_probes.h RPROBE_GRAZING_LO, RPROBE_GRAZING_HI


def grazing(st: dict, nov):
    """Twin of rprobe_grazing: the share of a parallax probe's reading taken in taps (all of it
    with `taps`, else by NoV where `grazing_taps` is set, none without either)."""
    if not st["parallax"] or not (st.get("taps") or st.get("grazing_taps")):
        return np.zeros(len(nov))
    if st.get("taps"):
        return np.ones(len(nov))
    return np.clip((GRAZING_HI - nov) / (GRAZING_HI - GRAZING_LO), 0.0, 1.0)


STRADDLE_LO, STRADDLE_HI, STRADDLE_RISE = 0.005, 0.02, 0.05   # kernels/reflection_probes.h RPROBE_STRADDLE_*


def straddle(c: dict, p, r, lod):
    """Twin of rprobe_straddle: the share of a parallax probe's reading taken in taps where its lobe
    about r straddles an opening's edge (the probe's open share seen = 1 - coverage(r, lod) from
    STRADDLE_LO to STRADDLE_HI of the way to either end), p is off the probe (its distance from the
    probe over the probe's from where r leaves the proxy, from NEAR to NEAR + STRADDLE_RISE) and
    that shift is within the lobe's width (near)."""
    st = c["settings"]
    pos = np.asarray(st["position"], np.float64)
    seen = 1 - radiance.chain_lookup_twin(c["coverage"], r, lod)[:, 0]
    edge = np.clip((np.minimum(seen, 1 - seen) - STRADDLE_LO) / (STRADDLE_HI - STRADDLE_LO), 0.0, 1.0)
    shift = np.linalg.norm(p - pos, axis=-1) / np.maximum(np.linalg.norm(exit_point(st, p, r) - pos, axis=-1), 1e-6)
    return edge * np.clip((shift - NEAR) / STRADDLE_RISE, 0.0, 1.0) * near(c, shift, lod)


OWN_MAX = 32      # kernels/reflection_probes.h RPROBE_OWN_MAX


def own_masks(captured: list, nobj: int) -> np.ndarray:
    """rp_excl (kernels/reflection_probes.h): per object, bit k where probe k < OWN_MAX excludes it
    (capture k's `excluded`: render/reflection_probes.py excluded); later probes are not kept."""
    masks = np.zeros(max(nobj, 1), np.uint32)
    for k, c in enumerate(captured[:OWN_MAX]):
        for i in c.get("excluded") or ():
            if i < len(masks):
                masks[i] |= np.uint32(1 << k)
    return masks


def own(captured: list, p, masks):
    """Twin of rprobe_own: each point's mask where a probe in it holds the point, else 0."""
    held = np.zeros(len(p), bool)
    for k, c in enumerate(captured[:OWN_MAX]):
        held |= ((masks >> np.uint32(k)) & 1).astype(bool) & (weight(c["settings"], p) > 0)
    return np.where(held, masks, np.uint32(0)).astype(np.uint32)


def masks_of(captured: list, obj) -> np.ndarray:
    """Each point's rp_excl, its object's (own_masks) by object index obj (-1: none, 0)."""
    obj = np.asarray(obj)
    if not len(obj):
        return np.zeros(0, np.uint32)
    masks = own_masks(captured, int(obj.max()) + 1)
    return np.where(obj >= 0, masks[np.maximum(obj, 0)], 0).astype(np.uint32)


def kept(mine, k: int):
    """Twin of rprobe_kept: whether probe k counts for points whose own probes are mine (own): all
    where 0."""
    return (mine == 0) | (((mine >> np.uint32(min(k, OWN_MAX - 1))) & 1).astype(bool) & (k < OWN_MAX))


def blend(captured: list, p, r, lod, distant, env, lobe, masks=None):
    """Twin of reflection_probes: captured [{settings, levels, coverage, sky, depth (optional: the
    distance chain, rprobe_hit)}], distant the scaled distant chain's radiance at (p, r) (m, 3),
    which takes the share no probe's influence holds; env (the distant chain, its rotation, its
    intensity) and lobe (n, v[, sample]: each point's G-buffer sample number in the frame, which
    turns its taps, tap_turn; 0 where not given) for a probe read in taps (everywhere, or at
    grazing views and on lobes straddling an opening's edge: grazing, straddle). masks: each point's rp_excl of its
    object (own_masks; None: 0): a point reads only the probes excluding its object where any of
    them holds it (own)."""
    acc = np.zeros_like(distant)
    wsum = np.zeros(len(p))
    lod = np.broadcast_to(np.asarray(lod, np.float64), (len(p),))
    nov = (lobe[0] * lobe[1]).sum(-1) if lobe is not None else np.ones(len(p))     # no lobe: no taps
    mine = own(captured, p, np.asarray(masks, np.uint32)) if masks is not None else np.zeros(len(p), np.uint32)
    sample = np.broadcast_to(lobe[2] if lobe is not None and len(lobe) > 2 else 0, (len(p),))
    for k, c in enumerate(captured):
        st = c["settings"]
        w = np.where(kept(mine, k), weight(st, p), 0.0)
        wsum += w
        g = grazing(st, nov)
        if lobe is not None and st["parallax"] and not st.get("taps") and st.get("grazing_taps"):
            g = np.maximum(g, straddle(c, p, r, lod))
        got = np.zeros_like(distant)
        tapped = (w > 0) & (g > 0)
        if tapped.any():
            count = st.get("taps") or st["grazing_taps"]
            got[tapped] = g[tapped, None] * taps(c, p[tapped], lobe[0][tapped], lobe[1][tapped], lod[tapped], env,
                                                 count, sample[tapped])
        one = (w > 0) & (g < 1)
        if one.any():
            got[one] += (1 - g[one, None]) * read(c, p[one], r[one], lod[one], distant[one])
        acc += w[:, None] * got
    over = wsum > 1
    out = acc + (1 - wsum)[:, None] * distant
    return np.where(over[:, None], acc / np.where(over, wsum, 1)[:, None], out)
