/* Shade pass: the approximate lighting terms the scene asks for, added into the radiance buffer.
 *   DIFFUSE_MODE  DIFFUSE_SH (SH_BANDS bands), DIFFUSE_BASIS (the directional basis BASIS_<NAME>
 *                 selects, kernels/bases.h), DIFFUSE_PROBES (the irradiance probes around the point,
 *                 kernels/probes.h; probe_stats counts the samples that fell back), DIFFUSE_LIGHTMAP
 *                 (the lightmap's atlas at the G-buffer's UV1, kernels/lightmap.h; a sample without
 *                 one reads the probes with LIGHTMAP_FALLBACK_PROBES, else the panorama's SH; lm_stats
 *                 counts both) or off
 *   SPECULAR_MODE SPECULAR_IMPORTANCE (the importance pass's sums, kernels/importance.cl,
 *                 combined here with f0) or SPECULAR_PREFILTERED
 *                 (DOMINANT_DIRECTION; HAS_REFLECTION_PROBES: the local probes' captures where they
 *                 reach, kernels/reflection_probes.h) or SPECULAR_LOBE or SPECULAR_BASIS (the split sum
 *                 with the frame's basis's basis_specular_radiance, kernels/bases.h) or SPECULAR_PROBES
 *                 (the same from the irradiance probes' basis, kernels/probes.h probes_specular) or
 *                 SPECULAR_LIGHTMAP (the same from the lightmap's second set, kernels/lightmap.h
 *                 lightmap_specular; the distant chain on what has none; lm_stats[2], [3]) or off
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
#include "bases.h"
#include "probes.h"
#include "lightmap.h"
#include "importance.h"
#include "split_sum.h"
#include "lobe.h"
#include "reflection_probes.h"
#include "ssr_split.h"
#include "scene.h"
#include "surface.h"

/* Specular occlusion from ambient occlusion (Lagarde and de Rousiers 2014, "Moving Frostbite to
 * PBR", computeSpecOcclusion): saturate((NoV + ao)^(2^(-16 r - 1)) - 1 + ao). */
IBL_INLINE float specular_occlusion(float nov, float ao, float roughness)
{
    return clamp(pow_fast(nov + ao, exp2(-16.0f * roughness - 1.0f)) - 1.0f + ao, 0.0f, 1.0f);
}

/* Multi-bounce AO (Jimenez et al. 2016, "Practical Real-Time Strategies for Accurate Indirect
 * Occlusion", eq. 10): a cubic in the visibility fitted per albedo to ray-traced interreflection. */
IBL_INLINE float3 ao_multibounce(float ao, float3 albedo)
{
    const float3 a = 2.0404f * albedo - 0.3324f, b = -4.7951f * albedo + 0.6417f, c = 2.7552f * albedo + 0.6903f;
    return fmax((float3)(ao), ((ao * a + b) * ao + c) * ao);
}

/* Every source's function lives in its header (render/sources/ declares its defines, bakes and
 * arguments); this kernel only dispatches to them and applies occlusion. */
__kernel void shade(__global const float4 *gb_pos, SURFACE_PARAMS,
                    const int n, const int pixel0, const int spp, const float2 env_rot, const float env_scale,
                    __constant float4 *sh_coeffs, __constant float4 *basis_coeffs, __global const float *basis_table,
                    CHAIN_PARAMS, __global const float2 *dfg, const int dfg_size,
                    LOBE_PARAMS, __global const float *ao_buf, __global const float4 *spec_sums, PROBE_PARAMS,
                    RPROBE_PARAMS, __global float4 *ssr_env, __global int *probe_stats,
                    __global const float4 *gb_lm, LIGHTMAP_PARAMS, __global const float4 *lm_spec,
                    __global int *lm_stats, __global float4 *radiance)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    if (gb_pos[gid].w == MISS_T) return;
    Material mt;
    float3 v, nrm;
    const float nov = surface_at(SURFACE_ARGS, gid, &mt, &v, &nrm);
    float3 color = (float3)(0.0f);
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
#elif DIFFUSE_MODE == DIFFUSE_BASIS
    color += diff_occ * diffuse_weight(mt, nov) * env_scale * basis_irradiance(basis_coeffs, to_env(nrm, env_rot));
#elif DIFFUSE_MODE == DIFFUSE_PROBES
    atomic_inc(&probe_stats[5]);         /* the samples on geometry: what the fallbacks' shares are of */
    color += diff_occ * diffuse_weight(mt, nov)
             * probes_diffuse(gb_pos[gid].xyz, nrm, v, env_scale * sh_irradiance(sh_coeffs, to_env(nrm, env_rot)),
                              PROBE_ARGS, probe_stats);
#elif DIFFUSE_MODE == DIFFUSE_LIGHTMAP
    {
        /* the lightmap's irradiance holds the panorama's intensity already (its paths read it scaled) */
        const float4 lm = gb_lm[gid];
        float3 e;
        if (lm.z > 0.0f) {
            e = lightmap_irradiance(lm.xy, nrm, LIGHTMAP_ARGS);
            atomic_inc(&lm_stats[0]);
        } else {
            const float3 sky = env_scale * sh_irradiance(sh_coeffs, to_env(nrm, env_rot));
#ifdef LIGHTMAP_FALLBACK_PROBES
            e = probes_diffuse(gb_pos[gid].xyz, nrm, v, sky, PROBE_ARGS, probe_stats);
#else
            e = sky;
#endif
            atomic_inc(&lm_stats[1]);
        }
        color += diff_occ * diffuse_weight(mt, nov) * e;
    }
#endif
#if SPECULAR_MODE == SPECULAR_IMPORTANCE
    color += spec_occ * env_scale * importance_specular(spec_sums, gid, mt);
#elif SPECULAR_MODE == SPECULAR_PREFILTERED
    {
        const float3 r = split_sum_direction(nrm, v, mt.alpha);
        float3 li = env_scale * split_sum_radiance(CHAIN_ARGS, r, env_rot, mt.roughness);
        const float3 w = spec_occ * split_sum_albedo(dfg, dfg_size, mt, nov);
#ifdef HAS_REFLECTION_PROBES
        /* the local captures (world frame, the panorama's intensity in them) where they reach and
         * the lobe reflects anything (a Lambert wall of specular 0 pays no taps at grazing views) */
        if (w.x + w.y + w.z > 0.0f)
            li = reflection_probes(gb_pos[gid].xyz, nrm, v, r, mt.roughness * (float)(rp_nlev - 1), li,
                                   as_int(gb_dir[gid].w), (uint)(pixel0 * spp + gid), RPROBE_ARGS, CHAIN_ARGS, env_rot, env_scale);
#endif
        color += w * li;
#ifdef HAS_SSR
#ifdef HAS_OCCLUSION_MAP
        ssr_split(ssr_env, gid, w * mt.occlusion, li);
#else
        ssr_split(ssr_env, gid, w, li);
#endif
#endif
    }
#elif SPECULAR_MODE == SPECULAR_LOBE
    color += spec_occ * env_scale * lobe_specular(CHAIN_ARGS, dfg, dfg_size, LOBE_ARGS, mt, nrm, v, nov, env_rot);
#elif SPECULAR_MODE == SPECULAR_BASIS && defined(HAS_BASIS_SPECULAR)
    /* the split sum with the basis's radiance along the warped lobe (kernels/bases.h) */
    color += spec_occ * env_scale * split_sum_albedo(dfg, dfg_size, mt, nov)
             * basis_specular_radiance(basis_coeffs, basis_table,
                                       to_env(dominant_direction(nrm, 2.0f * dot(nrm, v) * nrm - v, mt.alpha), env_rot),
                                       basis_warp_sharpness(mt.alpha, nov));
#elif SPECULAR_MODE == SPECULAR_PROBES && defined(PROBES_BASIS) && defined(HAS_BASIS_SPECULAR)
    /* the split sum with the probes' radiance along the warped lobe (world frame; their radiance
     * holds the panorama's intensity), the distant chain's where they do not reach */
    {
        const float3 sky = env_scale * split_sum_radiance(CHAIN_ARGS, split_sum_direction(nrm, v, mt.alpha), env_rot,
                                                          mt.roughness);
        const float3 d = dominant_direction(nrm, 2.0f * dot(nrm, v) * nrm - v, mt.alpha);
        color += spec_occ * split_sum_albedo(dfg, dfg_size, mt, nov)
                 * probes_specular(gb_pos[gid].xyz, nrm, v, d, basis_warp_sharpness(mt.alpha, nov), sky, basis_table,
                                   PROBE_ARGS, probe_stats);
    }
#elif SPECULAR_MODE == SPECULAR_LIGHTMAP && defined(LIGHTMAP_SPECULAR) && defined(HAS_BASIS_SPECULAR)
    /* the split sum with the lightmap's radiance along the warped lobe (world frame; its radiance
     * holds the panorama's intensity), the distant chain's on what has none */
    {
        const float4 lm = gb_lm[gid];
        float3 li;
        if (lm.z > 0.0f) {
            li = lightmap_specular(lm.xy, dominant_direction(nrm, 2.0f * dot(nrm, v) * nrm - v, mt.alpha),
                                   basis_warp_sharpness(mt.alpha, nov), basis_table, lm_spec, lm_width, lm_height);
            atomic_inc(&lm_stats[2]);
        } else {
            li = env_scale * split_sum_radiance(CHAIN_ARGS, split_sum_direction(nrm, v, mt.alpha), env_rot,
                                                mt.roughness);
            atomic_inc(&lm_stats[3]);
        }
        color += spec_occ * split_sum_albedo(dfg, dfg_size, mt, nov) * li;
    }
#endif
#ifdef HAS_OCCLUSION_MAP
    color *= mt.occlusion;             /* the material's occlusion map: image-based light only */
#endif
#ifdef HAS_EMISSIVE
    color += mt.emissive;
#endif
    radiance[gid] += (float4)(color, 0.0f);   /* lighting passes add */
}
