/* Local reflection probes (Lagarde and Zanuttini 2012): prefiltered captures read inside each
 * probe's influence along the reflected ray corrected to where it leaves the probe's proxy (its
 * box or sphere), blended by each influence's fade, the distant chain taking what is left.
 * rp_info, 4 float4 per probe: (position, shape: 0 box, 1 sphere), (min, blend), (max, radius),
 * (parallax, the capture's texel in radians, 0, 0). Each probe has two chains, its capture's radiance of the scene (chain 2k)
 * and the coverage of its texels by the scene (chain 2k + 1, grey): the sky past the scene is the
 * distant chain's, read along the reflected ray itself (infinitely far: no parallax moves it).
 * The chains lie back to back in rp_chain, level l of chain c at rp_off[c rp_nlev + l] texels,
 * every level rp_lw x rp_lh.
 * numpy twin: iblbake/render/twin/reflection_probes.py. */
#ifndef IBLBAKE_REFLECTION_PROBES_H
#define IBLBAKE_REFLECTION_PROBES_H
#include "common.h"

#define RPROBE_PARAMS __global const float *rp_chain, __global const int *rp_off, __global const int *rp_lw, \
                      __global const int *rp_lh, const int rp_nlev, const int rp_count, __global const float4 *rp_info
#define RPROBE_ARGS rp_chain, rp_off, rp_lw, rp_lh, rp_nlev, rp_count, rp_info

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

/* The capture's direction for the ray p + t r: towards its exit, seen from the probe's position. */
IBL_INLINE float3 rprobe_direction(float3 p, float3 r, float4 a, float4 b, float4 c)
{
    return normalize(rprobe_exit(p, r, a, b, c) - a.xyz);
}

/* How much of the reflection along p + t r that meets the scene at x the probes at p already hold,
 * for a lobe of GGX alpha: the influence-weighted share of parallax probes whose proxy the ray
 * leaves within 3% of its travel from x (a wall or floor on the proxy: the capture, read with
 * parallax, shows that very point), to the capture's resolution (a lobe narrower than its texel,
 * a mirror's, sees more of the frame than of it). Screen-space reflections defer to them there and
 * add what lies off every proxy. */
IBL_INLINE float reflection_probes_hold(float3 p, float3 r, float3 x, float alpha, __global const float4 *rp_info,
                                    const int rp_count)
{
    float held = 0.0f, wsum = 0.0f;
    const float travel = distance(p, x);
    for (int k = 0; k < rp_count; ++k) {
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

/* The prefiltered radiance at point p along r (world frame) at chain level lod: the probes whose
 * influence holds p, weighted (their weights normalised where they sum past 1), and `distant`
 * (the panorama's chain, scaled) for the rest. Captures hold the panorama's intensity and frame. */
IBL_INLINE float3 reflection_probes(float3 p, float3 r, float lod, float3 distant, RPROBE_PARAMS)
{
    float3 acc = (float3)(0.0f);
    float wsum = 0.0f;
    for (int k = 0; k < rp_count; ++k) {
        const float4 a = rp_info[4 * k], b = rp_info[4 * k + 1], c = rp_info[4 * k + 2], e = rp_info[4 * k + 3];
        const float w = rprobe_weight(p, a, b, c);
        if (w <= 0.0f) continue;
        const float3 d = e.x > 0.5f ? rprobe_direction(p, r, a, b, c) : r;
        const float cover = rprobe_lookup(RPROBE_ARGS, 2 * k + 1, d, lod).x;
        acc += w * (rprobe_lookup(RPROBE_ARGS, 2 * k, d, lod) + (1.0f - cover) * distant);
        wsum += w;
    }
    if (wsum > 1.0f) return acc / wsum;
    return acc + (1.0f - wsum) * distant;
}

#endif
