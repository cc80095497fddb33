/* Shade pass: the approximate lighting terms the scene asks for, added into the radiance buffer.
 *   DIFFUSE_MODE  DIFFUSE_SH (SH_BANDS bands), DIFFUSE_PROBES (the irradiance probes around the point,
 *                 kernels/probes.h; probe_stats counts the samples that fell back) or off
 *   SPECULAR_MODE SPECULAR_IMPORTANCE (the importance pass's sums, kernels/importance.cl,
 *                 combined here with f0) or SPECULAR_PREFILTERED
 *                 (DOMINANT_DIRECTION; HAS_REFLECTION_PROBES: the local probes' captures where they
 *                 reach, kernels/reflection_probes.h) or SPECULAR_LOBE or off
 *   HAS_SSR       (prefiltered) the reflected environment, its weight and radiance, into ssr_env, which
 *                 the ssr pass replaces where its rays meet the frame (kernels/ssr.cl)
 *   HAS_EMISSIVE  emission
 *   HAS_OCCLUSION_MAP  the material's occlusion (its map) on the image-based terms
 *   HAS_AO        ambient occlusion (the ao or gtao pass's ao_buf) on the diffuse term (AO_MULTIBOUNCE:
 *                 through the multi-bounce fit), Lagarde's specular occlusion on the specular term
 * numpy twin: iblbake/render/twin/shade.py shade(). */
#include "common.h"
#include "brdf.h"
#include "sampling.h"
#include "envmap.h"
#include "sh.h"
#include "probes.h"
#include "reflection_probes.h"
#include "scene.h"
#include "surface.h"

#if DIFFUSE_MODE == DIFFUSE_SH || DIFFUSE_MODE == DIFFUSE_PROBES
inline float3 sh_irradiance(__constant float4 *coeffs, float3 n)
{
    float Y[SH_COEFFS];
    sh_eval(n, Y);
    float3 e = (float3)(0.0f);
    for (int k = 0; k < SH_COEFFS; ++k) e += coeffs[k].xyz * Y[k];
    return fmax(e, (float3)(0.0f));
}
#endif

#if SPECULAR_MODE == SPECULAR_PREFILTERED || SPECULAR_MODE == SPECULAR_LOBE
/* The DFG table (x: NoV, y: roughness, texel centres at the ends): bilinear. */
inline float2 dfg_lookup(__global const float2 *dfg, const int dfg_size, float nov, float roughness)
{
    const float x = clamp(nov, 0.0f, 1.0f) * (dfg_size - 1), y = roughness * (dfg_size - 1);
    const int x0 = min((int)x, dfg_size - 2), y0 = min((int)y, dfg_size - 2);
    const float fx = x - x0, fy = y - y0;
    return mix(mix(dfg[y0 * dfg_size + x0], dfg[y0 * dfg_size + x0 + 1], fx),
               mix(dfg[(y0 + 1) * dfg_size + x0], dfg[(y0 + 1) * dfg_size + x0 + 1], fx), fy);
}
#endif

/* Specular occlusion from ambient occlusion (Lagarde and de Rousiers 2014, "Moving Frostbite to
 * PBR", computeSpecOcclusion): saturate((NoV + ao)^(2^(-16 r - 1)) - 1 + ao). */
inline float specular_occlusion(float nov, float ao, float roughness)
{
    return clamp(pow_fast(nov + ao, exp2(-16.0f * roughness - 1.0f)) - 1.0f + ao, 0.0f, 1.0f);
}

/* Multi-bounce AO (Jimenez et al. 2016, "Practical Real-Time Strategies for Accurate Indirect
 * Occlusion", eq. 10): a cubic in the visibility fitted per albedo to ray-traced interreflection. */
inline float3 ao_multibounce(float ao, float3 albedo)
{
    const float3 a = 2.0404f * albedo - 0.3324f, b = -4.7951f * albedo + 0.6417f, c = 2.7552f * albedo + 0.6903f;
    return fmax((float3)(ao), ((ao * a + b) * ao + c) * ao);
}

/* Where a rough lobe really points: between N and R (Lagarde and de Rousiers 2014, Frostbite,
 * getSpecularDominantDir with their alpha). The split sum reads its prefiltered chain there. */
inline float3 dominant_direction(float3 n, float3 r, float a)
{
    const float s = clamp(1.0f - a, 0.0f, 1.0f);
    return normalize(mix(n, r, s * (sqrt(s) + a)));
}

__kernel void shade(__global const float4 *gb_pos, SURFACE_PARAMS,
                    const int n, const float2 env_rot, const float env_scale,
                    __constant float4 *sh_coeffs,
                    CHAIN_PARAMS,
                    __global const float4 *hammersley_pts, const int nsamples, const float mip_bias, const float lobe_spread,
                    __global const float2 *dfg, const int dfg_size, __global const float *ao_buf,
                    __global const float4 *spec_sums, PROBE_PARAMS, RPROBE_PARAMS, __global float4 *ssr_env,
                    __global int *probe_stats, __global float4 *radiance)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    if (gb_pos[gid].w == MISS_T) return;
    Material mt;
    float3 v, nrm;
    const float nov = surface_at(SURFACE_ARGS, gid, &mt, &v, &nrm);
    float3 color = (float3)(0.0f);
#ifdef HAS_SSR
    float3 ssr_w = (float3)(0.0f), ssr_li = (float3)(0.0f);
#endif
#ifdef HAS_AO
    const float spec_occ = specular_occlusion(nov, ao_buf[gid], mt.roughness);
#ifdef AO_MULTIBOUNCE
    const float3 diff_occ = ao_multibounce(ao_buf[gid], mt.base * (1.0f - mt.metallic));
#else
    const float diff_occ = ao_buf[gid];
#endif
#else
    const float diff_occ = 1.0f, spec_occ = 1.0f;
#endif
#if DIFFUSE_MODE == DIFFUSE_SH
    color += diff_occ * diffuse_weight(mt, nov) * env_scale * sh_irradiance(sh_coeffs, to_env(nrm, env_rot));
#elif DIFFUSE_MODE == DIFFUSE_PROBES
    {
        /* the probes' irradiance holds the panorama's intensity already (their rays read it
         * scaled); outside the volume, and where no active probe is near (counted in probe_stats:
         * [0] the nearest active probes stood in for the cell's, [1] none did), the panorama's SH */
        const float3 p = gb_pos[gid].xyz;
        const float wv = probe_volume_weight(p, probe_origin, probe_spacing, probe_nx, probe_ny, probe_nz);
        float3 sky = (float3)(0.0f);
        if (wv < 1.0f) sky = env_scale * sh_irradiance(sh_coeffs, to_env(nrm, env_rot));
        float3 e = (1.0f - wv) * sky;
        if (wv > 0.0f) {
            float4 pe = probe_irradiance(p, nrm, v, PROBE_ARGS);
            if (pe.w == PROBE_SOURCE_NEAREST) atomic_inc(&probe_stats[0]);
            if (pe.w == PROBE_SOURCE_NONE) {
                atomic_inc(&probe_stats[1]);
                pe.xyz = env_scale * sh_irradiance(sh_coeffs, to_env(nrm, env_rot));
            }
            e += wv * pe.xyz;
        }
        color += diff_occ * diffuse_weight(mt, nov) * e;
    }
#endif
#if SPECULAR_MODE == SPECULAR_IMPORTANCE
    {
        /* the importance pass's two sums: F = f0 (1 - c) + f90 c */
        color += spec_occ * env_scale * (mt.f0 * spec_sums[2 * gid].xyz + mt.f90 * spec_sums[2 * gid + 1].xyz);
    }
#elif SPECULAR_MODE == SPECULAR_PREFILTERED
    {
        /* split sum: prefiltered chain at R (level = roughness (K-1)) x (F0 A + B) */
#ifdef DOMINANT_DIRECTION
        const float3 r = dominant_direction(nrm, 2.0f * dot(nrm, v) * nrm - v, mt.alpha);
#else
        const float3 r = 2.0f * dot(nrm, v) * nrm - v;
#endif
        const float3 pre = chain_lookup(CHAIN_ARGS, to_env(r, env_rot),
                                        mt.roughness * (float)(nlev - 1));
        const float2 ab = dfg_lookup(dfg, dfg_size, nov, mt.roughness);
#ifdef HAS_REFLECTION_PROBES
        /* the local captures (world frame, the panorama's intensity in them) where they reach */
        const float3 li = reflection_probes(gb_pos[gid].xyz, r, mt.roughness * (float)(rp_nlev - 1), env_scale * pre,
                                            RPROBE_ARGS);
        color += spec_occ * li * (mt.f0 * ab.x + mt.f90 * ab.y);
#else
        color += spec_occ * env_scale * pre * (mt.f0 * ab.x + mt.f90 * ab.y);
#ifdef HAS_SSR
        const float3 li = env_scale * pre;
#endif
#endif
#ifdef HAS_SSR
        ssr_w = spec_occ * (mt.f0 * ab.x + mt.f90 * ab.y);
        ssr_li = li;
#endif
    }
#elif SPECULAR_MODE == SPECULAR_LOBE
    {
        /* The split sum's chain and DFG table, read along the real lobe: K visible-normal samples
         * l_i of the view-dependent GGX lobe (Heitz 2018), each reading the prefiltered chain at
         * the roughness whose lobe covers the sample's share 1 / (K pdf(l_i)) of the solid angle
         * (a level-k lobe at N = V = R has peak pdf 1 / (4 pi alpha_k^2): FIS's rule applied to
         * the prefiltered chain), capped at the material's own. Weights are the exact estimator's,
         * f NoL / pdf = 4 F V NoV NoL / G1(NoV); their ratio times the DFG table's albedo
         * F0 A + B keeps the white furnace exact. K = 1: the split sum, read at one sample's
         * direction and level. No sample above the horizon: the split sum at R. */
        float3 t, b;
        tangent_frame(nrm, &t, &b);
        const float3 vl = (float3)(dot(v, t), dot(v, b), nov);
        const float g1 = g1_smith(nov, mt.alpha);
        float3 num = (float3)(0.0f), den = (float3)(0.0f);
        for (int i = 0; i < nsamples; ++i) {
            const float3 hl = sample_ggx_vndf(vl, mt.alpha, hammersley_pts[i].xy);
            const float3 h = t * hl.x + b * hl.y + nrm * hl.z;
            const float voh = dot(v, h);
            const float3 l = 2.0f * voh * h - v;
            const float nol = dot(nrm, l);
            if (nol <= 0.0f || voh <= 0.0f) continue;
            const float pdf = g1 * d_ggx(hl.z, mt.alpha) / (4.0f * nov);
            const float a = fmin(sqrt(lobe_spread / (4.0f * IBL_PI * (float)nsamples * pdf)), mt.alpha);
            const float3 w = f_schlick(voh, mt.f0, mt.f90) * (v_smith_ggx_correlated(nov, nol, mt.alpha) * 4.0f * nov * nol / g1);
            num += w * chain_lookup(CHAIN_ARGS, to_env(l, env_rot), sqrt(a) * (float)(nlev - 1));
            den += w;
        }
        const float2 ab = dfg_lookup(dfg, dfg_size, nov, mt.roughness);
        const float3 li = den.x > 0.0f ? num / den
            : chain_lookup(CHAIN_ARGS, to_env(2.0f * nov * nrm - v, env_rot), mt.roughness * (float)(nlev - 1));
        color += spec_occ * env_scale * li * (mt.f0 * ab.x + mt.f90 * ab.y);
    }
#endif
#ifdef HAS_OCCLUSION_MAP
    color *= mt.occlusion;             /* the material's occlusion map: image-based light only */
#ifdef HAS_SSR
    ssr_w *= mt.occlusion;
#endif
#endif
#ifdef HAS_SSR
    ssr_env[2 * gid] = (float4)(ssr_w, 0.0f);
    ssr_env[2 * gid + 1] = (float4)(ssr_li, 0.0f);
#endif
#ifdef HAS_EMISSIVE
    color += mt.emissive;
#endif
    radiance[gid] += (float4)(color, 0.0f);   /* lighting passes add */
}
