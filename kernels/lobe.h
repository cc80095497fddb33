/* The lobe specular mode: the split sum's chain and DFG table, read along the real lobe.
 * numpy twin: iblbake/render/twin/shade.py lobe. */
#ifndef IBLBAKE_LOBE_H
#define IBLBAKE_LOBE_H
#include "common.h"
#include "brdf.h"
#include "sampling.h"
#include "envmap.h"
#include "surface.h"
#include "split_sum.h"

#define LOBE_PARAMS __global const float4 *lobe_pts, const int lobe_samples, const float lobe_spread
#define LOBE_ARGS lobe_pts, lobe_samples, lobe_spread

/* K visible-normal samples l_i of the view-dependent GGX lobe (Heitz 2018), each reading the
 * prefiltered chain at the roughness whose lobe covers the sample's share 1 / (K pdf(l_i)) of the
 * solid angle (a level-k lobe at N = V = R has peak pdf 1 / (4 pi alpha_k^2): FIS's rule applied to
 * the prefiltered chain), capped at the material's own. Weights are the exact estimator's,
 * f NoL / pdf = 4 F V NoV NoL / G1(NoV); their ratio times the DFG table's albedo F0 A + B keeps the
 * white furnace exact. K = 1: the split sum, read at one sample's direction and level. No sample
 * above the horizon: the split sum at R. The radiance is unscaled (times env_scale by the caller). */
IBL_INLINE float3 lobe_specular(CHAIN_PARAMS, __global const float2 *dfg, const int dfg_size, LOBE_PARAMS,
                            const Material mt, float3 nrm, float3 v, float nov, float2 env_rot)
{
    float3 t, b;
    tangent_frame(nrm, &t, &b);
    const float3 vl = (float3)(dot(v, t), dot(v, b), nov);
    const float g1 = g1_smith(nov, mt.alpha);
    float3 num = (float3)(0.0f), den = (float3)(0.0f);
    for (int i = 0; i < lobe_samples; ++i) {
        float3 h;
        float noh;
        const float3 l = reflect_ggx_vndf(lobe_pts[i].xy, t, b, nrm, v, vl, mt.alpha, &h, &noh);
        const float voh = dot(v, h);
        const float nol = dot(nrm, l);
        if (nol <= 0.0f || voh <= 0.0f) continue;
        const float pdf = g1 * d_ggx(noh, mt.alpha) / (4.0f * nov);
        const float a = fmin(sqrt(lobe_spread / (4.0f * IBL_PI * (float)lobe_samples * pdf)), mt.alpha);
        const float3 w = f_schlick(voh, mt.f0, mt.f90) * (v_smith_ggx_correlated(nov, nol, mt.alpha) * 4.0f * nov * nol / g1);
        num += w * chain_lookup(CHAIN_ARGS, to_env(l, env_rot), sqrt(a) * (float)(nlev - 1));
        den += w;
    }
    const float3 li = den.x > 0.0f ? num / den
        : chain_lookup(CHAIN_ARGS, to_env(2.0f * nov * nrm - v, env_rot), mt.roughness * (float)(nlev - 1));
    return li * split_sum_albedo(dfg, dfg_size, mt, nov);
}

#endif
