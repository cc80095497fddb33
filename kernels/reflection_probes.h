/* Local reflection probes (Lagarde and Zanuttini 2012): prefiltered captures read inside each
 * probe's influence along the reflected ray corrected to where it leaves the probe's proxy (its
 * box or sphere), blended by each influence's fade, the distant chain taking what is left.
 * rp_info, 4 float4 per probe: (position, shape: 0 box, 1 sphere), (min, blend), (max, radius),
 * (parallax, the capture's texel in radians, taps, distance). Each probe has four chains: its
 * capture's radiance of the scene (chain 4k), the coverage of its texels by the scene (chain 4k + 1,
 * grey), the sky its escaping rays saw (chain 4k + 2: the panorama through the scene's openings, 0
 * where covered) and the distance from the probe to the scene (chain 4k + 3, grey, level 0 read;
 * an opening's texels the proxy's). The sky is infinitely far: no parallax moves it (rprobe_sky).
 * rp_info's fourth z: the probe's taps (reflection_probes.N.taps), -N: N taps at grazing views and
 * on lobes straddling an opening's edge (reflection_probes.N.grazing_taps, rprobe_grazing,
 * rprobe_straddle), 0: one read a lobe; w: 1 where
 * the probe has its distance chain (rprobe_hit marches against it), 0: the proxy alone.
 * The chains lie back to back in rp_chain, level l of chain c at rp_off[c rp_nlev + l] texels,
 * every level rp_lw x rp_lh. rp_excl, a uint per object: bit k set where probe k < RPROBE_OWN_MAX
 * excludes it (reflection_probes.N.exclude, or objects.N.reflection_captures: false).
 * numpy twin: iblbake/render/twin/reflection_probes.py. */
#ifndef IBLBAKE_REFLECTION_PROBES_H
#define IBLBAKE_REFLECTION_PROBES_H
#include "common.h"
#include "ggx.h"
#include "sampler.h"
#include "split_sum.h"

#define RPROBE_PARAMS __global const float *rp_chain, __global const int *rp_off, __global const int *rp_lw, \
                      __global const int *rp_lh, const int rp_nlev, const int rp_count, __global const float4 *rp_info, \
                      __global const uint *rp_excl
#define RPROBE_ARGS rp_chain, rp_off, rp_lw, rp_lh, rp_nlev, rp_count, rp_info, rp_excl

/* How much of probe k's capture a point takes: 1 inside its box or sphere (a room-sized box
 * covers the room's own walls and floor), falling to 0 over `blend` of each half extent (a box)
 * or of the radius (a sphere) beyond it; blend 0: 1 inside, 0 outside. */
IBL_INLINE float rprobe_weight(float3 p, float4 a, float4 b, float4 c)
{
    float over;
    if (a.w < 0.5f) {
        const float3 half_extent = 0.5f * (c.xyz - b.xyz);
        const float3 rel = (fabs(p - 0.5f * (b.xyz + c.xyz)) - half_extent) / half_extent;
        over = fmax(rel.x, fmax(rel.y, rel.z));       /* <= 0 inside; 1 a half extent out */
    } else {
        over = length(p - a.xyz) / c.w - 1.0f;
    }
    if (over <= 0.0f) return 1.0f;
    return b.w > 0.0f ? fmax(1.0f - over / b.w, 0.0f) : 0.0f;
}

/* Where the ray p + t r (p inside the proxy) leaves the box (the slabs' nearest exit) or the
 * sphere (the far root). */
IBL_INLINE float3 rprobe_exit(float3 p, float3 r, float4 a, float4 b, float4 c)
{
    float t;
    if (a.w < 0.5f) {
        const float3 far = select(b.xyz, c.xyz, isgreater(r, (float3)(0.0f)));
        const float3 tt = (far - p) / r;               /* +inf along an axis r does not move on */
        t = fmin(tt.x, fmin(tt.y, tt.z));
    } else {
        const float3 o = p - a.xyz;
        const float bb = dot(o, r), cc = dot(o, o) - c.w * c.w;
        t = -bb + sqrt(fmax(bb * bb - cc, 0.0f));
    }
    return p + fmax(t, 0.0f) * r;
}

/* The distance from probe k (at a.xyz) to what it captured in the direction of q: chain 4k + 3
 * (level 0, bilinear) holds that distance over the proxy's in the texel's direction (1 on the
 * proxy, below it in front), times the proxy's distance along q's own direction: on the proxy the
 * ratio reads 1 between texels too, where a box's distance bends at its edges. */
IBL_INLINE float rprobe_depth(RPROBE_PARAMS, int k, float3 q)
{
    const float4 a = rp_info[4 * k], b = rp_info[4 * k + 1], c = rp_info[4 * k + 2];
    const float len = distance(q, a.xyz);
    if (len < 1e-6f) return 0.0f;
    const float3 d = (q - a.xyz) / len;
    const float ratio = bilinear_equirect(rp_chain + 3 * (size_t)rp_off[(4 * k + 3) * rp_nlev], rp_lw[0], rp_lh[0],
                                          equirect_uv_from_dir(d)).x;
    return ratio * distance(rprobe_exit(a.xyz, d, a, b, c), a.xyz);
}

/* Where p + t r meets the surface probe k captured, a distance impostor (Szirmay-Kalos, Szecsi and
 * Sbert 2005, "Approximate ray-tracing on the GPU with distance impostors"): the ray marched in
 * RPROBE_MARCH even steps from p to where it leaves the proxy (rprobe_exit), each point q behind
 * the captured surface where |q - probe| exceeds the capture's distance towards q by
 * RPROBE_BEHIND of it; the first step that goes behind is refined by RPROBE_REFINE secant steps.
 * No step behind (the room's walls on the proxy, an opening: its texels hold the proxy's distance):
 * the exit itself, the box projection exactly. An object off the proxy (a sphere in the room) is
 * met where it stands, not pinned on the wall behind it (window_room's chrome sphere mirroring the
 * clay sphere: x1.21 on that half with the box alone). RPROBE_BEHIND, the least that counts as
 * behind: a grazing ray goes little behind a sphere between two steps (that half in 64 taps: 5.1%
 * at 0.005, 11.3% at 0.02, 15.7% at 0.05); a capture's texel means lie within 0.06% of a wall's
 * distance (window_room's, 99th percentile). A probe that does not march (rp_info's fourth w 0:
 * no distance chain, or nothing in front of its proxy): the exit. */
#define RPROBE_MARCH 16
#define RPROBE_REFINE 4
#define RPROBE_BEHIND 0.005f
IBL_INLINE float3 rprobe_hit(RPROBE_PARAMS, int k, float3 p, float3 r)
{
    const float4 a = rp_info[4 * k], b = rp_info[4 * k + 1], c = rp_info[4 * k + 2], e = rp_info[4 * k + 3];
    const float3 x = rprobe_exit(p, r, a, b, c);
    if (e.w < 0.5f) return x;
    const float far = distance(p, x);
    float t0 = 0.0f, f0 = distance(p, a.xyz) - rprobe_depth(RPROBE_ARGS, k, p);
    for (int i = 1; i <= RPROBE_MARCH; ++i) {
        const float t1 = far * (float)i / (float)RPROBE_MARCH;
        const float3 q = p + t1 * r;
        const float depth = rprobe_depth(RPROBE_ARGS, k, q), f1 = distance(q, a.xyz) - depth;
        if (f0 <= 0.0f && f1 > RPROBE_BEHIND * depth) {
            float lo = t0, flo = f0, hi = t1, fhi = f1;
            for (int j = 0; j < RPROBE_REFINE; ++j) {          /* secant within [lo, hi] */
                const float t = lo + (hi - lo) * flo / fmin(flo - fhi, -1e-12f);
                const float3 m = p + t * r;
                const float fm = distance(m, a.xyz) - rprobe_depth(RPROBE_ARGS, k, m);
                if (fm > 0.0f) { hi = t; fhi = fm; } else { lo = t; flo = fm; }
            }
            return p + (lo + (hi - lo) * flo / fmin(flo - fhi, -1e-12f)) * r;
        }
        t0 = t1;
        f0 = f1;
    }
    return x;
}

/* The probes a point reads among those excluding its object (own: rp_excl's bits): own where
 * any of them holds p in its influence, else 0 (every probe, the usual blend). */
#define RPROBE_OWN_MAX 32
IBL_INLINE uint rprobe_own(float3 p, uint own, __global const float4 *rp_info, const int rp_count)
{
    for (int k = 0; k < min(rp_count, RPROBE_OWN_MAX); ++k)
        if (((own >> k) & 1u) && rprobe_weight(p, rp_info[4 * k], rp_info[4 * k + 1], rp_info[4 * k + 2]) > 0.0f)
            return own;
    return 0u;
}

/* Whether probe k counts for a point whose own probes are own (rprobe_own): every probe where 0 */
IBL_INLINE int rprobe_kept(uint own, int k)
{
    return own == 0u || (k < RPROBE_OWN_MAX && ((own >> k) & 1u));
}

/* How much of the reflection along p + t r that meets the scene at x the probes at p already hold,
 * for a lobe of GGX alpha: the influence-weighted share of parallax probes whose proxy the ray
 * leaves within 3% of its travel from x (a wall or floor on the proxy: the capture, read with
 * parallax, shows that very point), to the capture's resolution (a lobe narrower than its texel,
 * a mirror's, sees more of the frame than of it). Screen-space reflections defer to them there and
 * add what lies off every proxy. own (rprobe_own): the probes the point reads, as reflection_probes
 * reads them (an object that some probes exclude: only those). */
IBL_INLINE float reflection_probes_hold(float3 p, float3 r, float3 x, float alpha, uint own,
                                    __global const float4 *rp_info, const int rp_count)
{
    float held = 0.0f, wsum = 0.0f;
    const float travel = distance(p, x);
    for (int k = 0; k < rp_count; ++k) {
        if (!rprobe_kept(own, k)) continue;                 /* not its own probe */
        const float4 a = rp_info[4 * k], b = rp_info[4 * k + 1], c = rp_info[4 * k + 2], e = rp_info[4 * k + 3];
        const float w = rprobe_weight(p, a, b, c);
        if (w <= 0.0f) continue;
        wsum += w;
        if (e.x > 0.5f)
            held += w * clamp(1.0f - distance(rprobe_exit(p, r, a, b, c), x) / (0.03f * travel), 0.0f, 1.0f)
                    * clamp(alpha / e.y, 0.0f, 1.0f);
    }
    return wsum > 1.0f ? held / wsum : held;
}

/* Trilinear read of chain c (chain_lookup's, on the probes' tables) */
IBL_INLINE float3 rprobe_lookup(RPROBE_PARAMS, int c, float3 d, float lod)
{
    const float2 uv = equirect_uv_from_dir(d);
    lod = isnan(lod) ? 0.0f : clamp(lod, 0.0f, (float)(rp_nlev - 1));
    const int l0 = (int)lod, l1 = min(l0 + 1, rp_nlev - 1);
    const float f = lod - (float)l0;
    const float3 x = bilinear_equirect(rp_chain + 3 * (size_t)rp_off[c * rp_nlev + l0], rp_lw[l0], rp_lh[l0], uv);
    if (f <= 0.0f) return x;
    return mix(x, bilinear_equirect(rp_chain + 3 * (size_t)rp_off[c * rp_nlev + l1], rp_lw[l1], rp_lh[l1], uv), f);
}

/* The sky radiance behind the openings probe k saw about r, per unit of open share: its sky over
 * its open share at the finest of the lobe's level and three wider ones (a quarter, half and all of
 * the chain further) where it saw RPROBE_SKY_SEEN of the lobe open; `distant` where it saw none. */
#define RPROBE_SKY_SEEN 0.05f
IBL_INLINE float3 rprobe_open_sky(RPROBE_PARAMS, int k, float3 r, float lod, float3 distant)
{
    const float top = (float)(rp_nlev - 1);
    const float widen[4] = {0.0f, 0.25f, 0.5f, 1.0f};
    for (int i = 0; i < 4; ++i) {
        const float l = fmin(lod + widen[i] * top, top);
        const float seen = 1.0f - rprobe_lookup(RPROBE_ARGS, 4 * k + 1, r, l).x;
        if (seen > RPROBE_SKY_SEEN) return rprobe_lookup(RPROBE_ARGS, 4 * k + 2, r, l) / seen;
    }
    return distant;
}

/* The sky behind probe k's openings as the point p sees them, for the lobe about r at lod: the sky
 * its escaping rays saw (chain 3k + 2) read along r itself (the sky is at infinity: the panorama's
 * directions that the lobe meets through a window, not all of them), times the share of the lobe
 * left open as p sees it (`open`, the coverage read with parallax) over that the probe saw about r,
 * where p sees less of the opening. Where p sees more (an opening's edge the probe does not see
 * about r), that share is filled in proportion to `off` (how far p is off the probe: near it the
 * probe's own view holds, the capture's lobe being wider than p's) with the sky the probe saw
 * through its openings about r (rprobe_open_sky) while the opening's shift as p sees it (`shift`,
 * |p - probe| / |x - probe| radians) is within the lobe's width (2 alpha), the distant chain's
 * lobe once it is twice that: a studio's key light behind the wall beside a window is in the
 * distant chain's lobe but not in what p sees through the window (quad_room under studio: the
 * window half x1.25 with the distant chain alone, x0.98 now). rprobe_near: that share of the
 * probe's sky, 1 within the lobe's width (2 alpha, alpha = (lod / the chain's last level)^2), 0 at
 * twice it. */
IBL_INLINE float rprobe_near(float shift, float lod, int nlev)
{
    const float rough = lod / fmax((float)(nlev - 1), 1.0f);
    return clamp(2.0f - shift / fmax(2.0f * rough * rough, 1e-6f), 0.0f, 1.0f);
}
IBL_INLINE float3 rprobe_sky(RPROBE_PARAMS, int k, float3 r, float lod, float open, float off, float shift,
                             float3 distant)
{
    const float seen = fmax(1.0f - rprobe_lookup(RPROBE_ARGS, 4 * k + 1, r, lod).x, 0.0f);
    const float3 sky = rprobe_lookup(RPROBE_ARGS, 4 * k + 2, r, lod);
    const float fill = off * fmax(open - seen, 0.0f);
    if (fill <= 0.0f) return sky * (fmin(open, seen) / fmax(seen, 1e-6f));
    const float near = rprobe_near(shift, lod, rp_nlev);
    const float3 through = near > 0.0f ? rprobe_open_sky(RPROBE_ARGS, k, r, lod, distant) : distant;
    return sky * (fmin(open, seen) / fmax(seen, 1e-6f)) + fill * mix(distant, through, near);
}

/* How far p is off the probe, as a share of the way from the probe to x (where p's ray leaves the
 * proxy), mapped to the share of an opening only p sees that the distant chain fills: none below
 * RPROBE_NEAR, all past RPROBE_FAR (measured on the window rooms and the resting sphere,
 * docs/benchmarks.md "Reflection probes at the truth"). */
#define RPROBE_NEAR 0.1f
#define RPROBE_FAR 0.4f
/* The finest level a lobe narrowed by distance reads: below it the capture's own noise shows (its
 * paths, `samples` a texel; the resting sphere's lower half: pixel noise 0.23 at level 0, 0.065 at
 * 2, the reference's 0.105 at 2048 samples a pixel) */
#define RPROBE_FINEST 2.0f

/* The roughness a tap reads (reflection_probes.N.taps: how many): filtered importance sampling
 * (Krivanek and Colbert 2008, GPU Gems 3 ch. 20): each tap stands for the solid angle 1 / (N pdf)
 * of the lobe about it and reads the level whose prefiltered lobe (a GGX lobe of alpha a spans
 * about 4 pi a^2 steradians) spans RPROBE_TAP_SPREAD of that, no wider than the lobe itself and
 * its alpha within RPROBE_TAP_HORIZON NoL (a tap near the horizon does not read under the
 * surface). Taps at a fixed share of the lobe's level aliased on a compact key light (a studio's
 * lamps, a city's sun: which taps met it decided a half's mean: resting under city 54% off with
 * 64 taps, 2% now); wider taps leak a lamp behind a window's edge (quad_room under studio: x1.40
 * on the window half at 4x the tap's solid angle, x1.06 at half). */
#define RPROBE_TAP_SPREAD 0.5f
#define RPROBE_TAP_HORIZON 0.05f
IBL_INLINE float rprobe_tap_rough(float pdf, float nol, float alpha, int count)
{
    const float omega = RPROBE_TAP_SPREAD / fmax((float)count * pdf, 1e-20f);
    const float a = fmin(sqrt(omega / (4.0f * 3.14159265358979323846f)), RPROBE_TAP_HORIZON * nol);
    return fmin(sqrt(a), sqrt(alpha));
}

/* An opening's edge crosses the tap's footprint (the probe saw between RPROBE_TAP_EDGE and 1 -
 * RPROBE_TAP_EDGE of it open): its filtered sky per unit of open share spreads a lamp the probe saw
 * just inside the edge over the part p sees open, where p may see that lamp behind the wall (a new
 * user's window room under studio, a key light 4 cm inside the window's edge as the probe sees it,
 * 0.4 m behind it from the gold sphere's +z side: its +x half x1.49 with 64 taps, x1.10 now). There
 * the share the probe saw reads the sky along l at the capture's own level (the panorama's where the
 * probe saw none of it open): p sees l open (rprobe_taps), and the sky is at infinity. */
#define RPROBE_TAP_EDGE 0.02f
/* Each G-buffer sample turns its taps about the normal by its own angle (its number in the frame
 * hashed): one set in every pixel of a flat face read the same directions there, so its quadrature
 * error did not average over the face (metal_box's cube under city, its -x face x0.89 in 32 taps
 * over the visible normals, x0.94 in 256; x0.93 turned). */
#define RPROBE_TAP_SEED 0x7A95u
IBL_INLINE float rprobe_tap_turn(uint sample)
{
    return (float)(pcg_hash(RPROBE_TAP_SEED ^ pcg_hash(sample)) >> 8) * (1.0f / 16777216.0f);
}
/* The sky a tap along l (at roughness tap_rough, chain level tap_rough top) meets through probe k's
 * openings, per unit of the share of its footprint p sees open: where the probe saw that share
 * too, the capture's own sky about l per unit of its open share seen = 1 - coverage(l) (a lamp
 * behind the wall beside a window is not in it, where the distant chain's filtered tap spread it
 * through the edge: quad_room under studio x1.28 on the window half with it; the distant chain's
 * where the probe saw less than RPROBE_SKY_SEEN of it open); the share p sees open beyond the
 * probe's (open = 1 - coverage(d) at the tap's level, d towards where l meets the capture: an
 * opening nearer p than the probe) holds the panorama about l itself (at infinity), read at the
 * tap's roughness times the square root of that share (it lies along the opening's edge). The
 * probe's sky there (before) spread a lamp it saw in a sliver of the opening over all p sees of
 * it: metal_box's cube under studio, the face that mirrors the box's open corner x1.19 in red and
 * blue (11.4%), 3.0% now; at the share's own solid angle (its fourth root) the lamp behind
 * quad_room's window wall came back through the edge (9.9%, 6.5% now). */
IBL_INLINE float3 rprobe_tap_sky(RPROBE_PARAMS, int k, float3 l, float3 d, float tap_rough, CHAIN_PARAMS,
                                 float2 env_rot, float env_scale)
{
    const float tap = tap_rough * fmax((float)(rp_nlev - 1), 1.0f);
    const float seen = fmax(1.0f - rprobe_lookup(RPROBE_ARGS, 4 * k + 1, l, tap).x, 0.0f);
    const int edge = seen > RPROBE_TAP_EDGE && seen < 1.0f - RPROBE_TAP_EDGE;
    const float sharp = edge ? 0.0f : tap_rough;        /* the sky's roughness along l */
    const float seen_l = edge ? fmax(1.0f - rprobe_lookup(RPROBE_ARGS, 4 * k + 1, l, 0.0f).x, 0.0f) : seen;
    const float open = fmax(1.0f - rprobe_lookup(RPROBE_ARGS, 4 * k + 1, d, tap).x, 0.0f);
    const float3 through = seen_l > RPROBE_SKY_SEEN
                           ? rprobe_lookup(RPROBE_ARGS, 4 * k + 2, l, edge ? 0.0f : tap) / seen_l
                           : env_scale * split_sum_radiance(CHAIN_ARGS, l, env_rot, sharp);
    if (open <= seen) return through;
    const float known = seen / open;
    return known * through
           + (1.0f - known) * env_scale * split_sum_radiance(CHAIN_ARGS, l, env_rot, tap_rough * sqrt(open - seen));
}

/* Probe k's reading at p of the GGX lobe of normal n and view v (alpha rough^2, rough = lod over
 * the chain's last level) in `count` directions l of its visible normals (Heitz 2018) at the
 * Hammersley points turned about n by G-buffer sample `sample`'s angle (rprobe_tap_turn), each
 * weighted as the BRDF over its pdf without Fresnel (V 4 NoV NoL / G1(NoV) = G2 / G1, about 1 for
 * every tap; none below the surface; the split sum's albedo scales the mean). Drawn from the normal
 * distribution (before), a tap near the normal at a grazing view weighed V 4 NoL VoH / NoH, 9 or
 * more against the others' 1: one such tap meeting a window's sky made a silhouette pixel of a new
 * user's gold sphere 5x too bright, its half 13% (docs/conventions.md "Taps"). Each tap at its own
 * roughness (rprobe_tap_rough): the scene where l leaves the proxy (x), read from the probe along d
 * = x - probe (at the tap's level, not floored at RPROBE_FINEST: the taps average the capture's
 * noise, and a floored read bled the black floor under a probe's excluded cube into the lit floor
 * beside it: metal_box under city, the -x face x0.88 at level 2, x0.93 at the tap's), and the sky
 * along l itself (at infinity: no parallax) where p sees that direction open (the coverage along d
 * at the capture's own level: a window's edge as sharp as the capture holds it), rprobe_tap_sky. */
IBL_INLINE float3 rprobe_taps(RPROBE_PARAMS, int k, float3 p, float3 n, float3 v, float lod, int count, uint sample,
                              CHAIN_PARAMS, float2 env_rot, float env_scale)
{
    const float4 a = rp_info[4 * k];
    const float top = fmax((float)(rp_nlev - 1), 1.0f);
    const float rough = lod / top, alpha = rough * rough;
    const float nov = fmax(dot(n, v), 1e-4f);
    float3 t, bt, acc = (float3)(0.0f);
    float wsum = 0.0f;
    tangent_frame(n, &t, &bt);
    const float3 vl = (float3)(dot(v, t), dot(v, bt), nov);
    const float g1 = g1_smith(nov, alpha), turn = rprobe_tap_turn(sample);
    for (int i = 0; i < count; ++i) {
        const float2 u = hammersley((uint)i, (uint)count);
        float3 h;
        float hz;
        const float3 l = reflect_ggx_vndf((float2)(u.x, fmod(u.y + turn, 1.0f)), t, bt, n, v, vl, alpha, &h, &hz);
        const float voh = dot(v, h);
        const float nol = dot(n, l);
        if (nol <= 0.0f || voh <= 0.0f) continue;
        const float noh = fmax(hz, 1e-7f);
        const float w = v_smith_ggx_correlated(nov, nol, alpha) * 4.0f * nov * nol / g1;
        const float tap_rough = rprobe_tap_rough(pdf_ggx_vndf_reflected(nov, noh, alpha), nol, alpha, count);
        const float tap = tap_rough * top;
        const float3 x = rprobe_hit(RPROBE_ARGS, k, p, l);
        const float3 d = (x - a.xyz) / fmax(distance(x, a.xyz), 1e-6f);
        const float open = fmax(1.0f - rprobe_lookup(RPROBE_ARGS, 4 * k + 1, d, 0.0f).x, 0.0f);
        const float3 through = rprobe_tap_sky(RPROBE_ARGS, k, l, d, tap_rough, CHAIN_ARGS, env_rot, env_scale);
        acc += w * (rprobe_lookup(RPROBE_ARGS, 4 * k, d, tap) + open * through);
        wsum += w;
    }
    return acc / fmax(wsum, 1e-9f);
}

/* Probe k's one read at p along r (the split sum's direction) at chain level lod: its scene along
 * the direction corrected to where p's ray meets the capture (a parallax probe: rprobe_hit), at a
 * level narrowed by p's distance to that point over the probe's (Lagarde and Zanuttini 2012's
 * distance-based roughness: the lobe's footprint there, seen from the probe), down to
 * RPROBE_FINEST; the sky it saw fills the rest (rprobe_sky). */
IBL_INLINE float3 rprobe_read(RPROBE_PARAMS, int k, float3 p, float3 r, float lod, float3 distant)
{
    const float4 a = rp_info[4 * k], e = rp_info[4 * k + 3];
    float3 d = r;
    float near_lod = lod, off = 0.0f, shift = 0.0f;
    if (e.x > 0.5f) {
        const float3 x = rprobe_hit(RPROBE_ARGS, k, p, r);
        const float from_probe = fmax(distance(x, a.xyz), 1e-6f);
        d = (x - a.xyz) / from_probe;
        near_lod = fmax(lod * clamp(distance(x, p) / from_probe, 0.0f, 1.0f), fmin(lod, RPROBE_FINEST));
        shift = distance(p, a.xyz) / from_probe;
        off = clamp((shift - RPROBE_NEAR) / (RPROBE_FAR - RPROBE_NEAR), 0.0f, 1.0f);
    }
    const float open = 1.0f - rprobe_lookup(RPROBE_ARGS, 4 * k + 1, d, near_lod).x;
    return rprobe_lookup(RPROBE_ARGS, 4 * k, d, near_lod) + rprobe_sky(RPROBE_ARGS, k, r, lod, open, off, shift, distant);
}

/* The share of a parallax probe's reading taken in taps where its taps are left to the view's
 * angle (rp_info's fourth z -N: reflection_probes.N.grazing_taps): all of it below
 * RPROBE_GRAZING_LO NoV, none above RPROBE_GRAZING_HI, linear between (no seam where the reading
 * changes). There the split sum's lobe about r misses the material's: the lobe is stretched and
 * cut by the horizon, and its read along the dominant direction (Lagarde and de Rousiers 2014's
 * fit, view-independent) is 13-29% off on the halves of a rough gold sphere seen edge-on
 * (docs/conventions.md "Grazing"). */
#define RPROBE_GRAZING_LO 0.4f
#define RPROBE_GRAZING_HI 0.8f
IBL_INLINE float rprobe_grazing(float z, float nov)
{
    if (z > 0.5f) return 1.0f;
    if (z > -0.5f) return 0.0f;
    return clamp((RPROBE_GRAZING_HI - nov) / (RPROBE_GRAZING_HI - RPROBE_GRAZING_LO), 0.0f, 1.0f);
}

/* The share of a parallax probe's reading taken in taps where its lobe about r straddles an
 * opening's edge and p is off the probe (rp_info's fourth z -N, as grazing views): one read
 * spreads the sky the probe saw in the lobe over all of it that p sees open, where p may see a
 * lamp just inside the edge behind the wall (a new user's window room under studio, a rough gold
 * sphere at the probe: its window half 3.2x with one read), and no one-read estimator can tell
 * which part of the lobe is open. The weight is a product of ramps, no seam where the reading
 * changes: the probe's open share seen = 1 - coverage(r, lod) (that of rprobe_sky) from
 * RPROBE_STRADDLE_LO to RPROBE_STRADDLE_HI of the way to either end (an open or closed lobe reads
 * once: the coverage chain's rounding never pays the taps); the opening's shift as p sees it (p's
 * distance from the probe over the probe's from where r leaves the proxy: the opening lies on it,
 * no march) from RPROBE_NEAR (rprobe_read's `off` 0) to RPROBE_NEAR + RPROBE_STRADDLE_RISE (that
 * gold sphere's window half +27.0% in 16 taps; +26.6% with a ramp of 0.03, +33% of 0.1); and
 * rprobe_sky's `near`, 1 while that shift is within the lobe's width, 0 at twice it: there one
 * read fills with the distant chain, not the probe's sky per unit of open share that spreads the
 * lamp, and a narrower lobe's taps miss the sliver of an opening (metal_box's cube under studio,
 * 0.3 roughness: +x x0.90 in taps, x0.97 with `near`, x0.99 in one read). */
#define RPROBE_STRADDLE_LO 0.005f
#define RPROBE_STRADDLE_HI 0.02f
#define RPROBE_STRADDLE_RISE 0.05f
IBL_INLINE float rprobe_straddle(RPROBE_PARAMS, int k, float3 p, float3 r, float lod)
{
    const float4 a = rp_info[4 * k], b = rp_info[4 * k + 1], c = rp_info[4 * k + 2];
    const float seen = 1.0f - rprobe_lookup(RPROBE_ARGS, 4 * k + 1, r, lod).x;
    const float edge = clamp((fmin(seen, 1.0f - seen) - RPROBE_STRADDLE_LO) / (RPROBE_STRADDLE_HI - RPROBE_STRADDLE_LO),
                             0.0f, 1.0f);
    if (edge <= 0.0f) return 0.0f;
    const float shift = distance(p, a.xyz) / fmax(distance(rprobe_exit(p, r, a, b, c), a.xyz), 1e-6f);
    return edge * clamp((shift - RPROBE_NEAR) / RPROBE_STRADDLE_RISE, 0.0f, 1.0f) * rprobe_near(shift, lod, rp_nlev);
}

/* The prefiltered radiance at point p (normal n, view v) along r (world frame) at chain level lod:
 * the probes whose influence holds p, weighted (their weights normalised where they sum past 1),
 * and `distant` (the panorama's chain, scaled) for the rest. A parallax probe with taps (rp_info's
 * fourth z: N everywhere, -N at grazing views and on lobes straddling an opening's edge,
 * rprobe_grazing and rprobe_straddle) is read in that many taps over the lobe (rprobe_taps),
 * elsewhere in one read (rprobe_read). Captures hold the panorama's intensity
 * and frame. A point on object obj that some probes exclude (rp_excl[obj], rprobe_own) reads,
 * among the probes whose influence holds it, only those: each of them was captured for that object
 * (the object is not in it), where any other shows it from outside (a new user's window room with a
 * probe per sphere, both influences the room: the gold sphere read half the chrome's probe, in which
 * it stands, x1.47 on its +x half). None of them holding p, or obj -1 (no object): every probe. Only
 * probes k < RPROBE_OWN_MAX are kept in the mask: a later probe never counts as an object's own. */
IBL_INLINE float3 reflection_probes(float3 p, float3 n, float3 v, float3 r, float lod, float3 distant, int obj,
                                    uint sample, RPROBE_PARAMS, CHAIN_PARAMS, float2 env_rot, float env_scale)
{
    float3 acc = (float3)(0.0f);
    float wsum = 0.0f;
    const uint own = obj >= 0 ? rprobe_own(p, rp_excl[obj], rp_info, rp_count) : 0u;
    for (int k = 0; k < rp_count; ++k) {
        if (!rprobe_kept(own, k)) continue;                 /* not its own probe */
        const float4 a = rp_info[4 * k], b = rp_info[4 * k + 1], c = rp_info[4 * k + 2], e = rp_info[4 * k + 3];
        const float w = rprobe_weight(p, a, b, c);
        if (w <= 0.0f) continue;
        wsum += w;
        float g = e.x > 0.5f ? rprobe_grazing(e.z, dot(n, v)) : 0.0f;
        if (e.x > 0.5f && e.z < -0.5f && g < 1.0f) g = fmax(g, rprobe_straddle(RPROBE_ARGS, k, p, r, lod));
        if (g > 0.0f)
            acc += w * g * rprobe_taps(RPROBE_ARGS, k, p, n, v, lod, (int)fabs(e.z), sample, CHAIN_ARGS, env_rot,
                                       env_scale);
        if (g < 1.0f)
            acc += w * (1.0f - g) * rprobe_read(RPROBE_ARGS, k, p, r, lod, distant);
    }
    if (wsum > 1.0f) return acc / wsum;
    return acc + (1.0f - wsum) * distant;
}

#endif
