/* The split sum (Karis 2013, "Real Shading in Unreal Engine 4"): the prefiltered chain read at the
 * reflected direction (Lagarde's dominant direction with DOMINANT_DIRECTION), level roughness
 * (K - 1), times the DFG table's directional albedo F0 A + F90 B. Also read by the lobe (lobe.h).
 * numpy twin: iblbake/render/twin/shade.py. */
#ifndef IBLBAKE_SPLIT_SUM_H
#define IBLBAKE_SPLIT_SUM_H
#include "common.h"
#include "brdf.h"
#include "envmap.h"
#include "surface.h"

/* The DFG table (x: NoV, y: roughness, texel centres at the ends): bilinear. */
IBL_INLINE float2 dfg_lookup(__global const float2 *dfg, const int dfg_size, float nov, float roughness)
{
    const float x = clamp(nov, 0.0f, 1.0f) * (dfg_size - 1), y = roughness * (dfg_size - 1);
    const int x0 = min((int)x, dfg_size - 2), y0 = min((int)y, dfg_size - 2);
    const float fx = x - x0, fy = y - y0;
    return mix(mix(dfg[y0 * dfg_size + x0], dfg[y0 * dfg_size + x0 + 1], fx),
               mix(dfg[(y0 + 1) * dfg_size + x0], dfg[(y0 + 1) * dfg_size + x0 + 1], fx), fy);
}

/* The directional albedo of the material's lobe at NoV, from the table: F0 A + F90 B */
IBL_INLINE float3 split_sum_albedo(__global const float2 *dfg, const int dfg_size, const Material mt, float nov)
{
    const float2 ab = dfg_lookup(dfg, dfg_size, nov, mt.roughness);
    return mt.f0 * ab.x + mt.f90 * ab.y;
}

/* Where a rough lobe really points: between N and R (Lagarde and de Rousiers 2014, Frostbite,
 * getSpecularDominantDir with their alpha). The split sum reads its prefiltered chain there. */
IBL_INLINE float3 dominant_direction(float3 n, float3 r, float a)
{
    const float s = clamp(1.0f - a, 0.0f, 1.0f);
    return normalize(mix(n, r, s * (sqrt(s) + a)));
}

/* The direction the split sum reads its chain along (world frame) */
IBL_INLINE float3 split_sum_direction(float3 n, float3 v, float alpha)
{
    const float3 r = 2.0f * dot(n, v) * n - v;
#ifdef DOMINANT_DIRECTION
    return dominant_direction(n, r, alpha);
#else
    return r;
#endif
}

/* The prefiltered chain's radiance along r (world frame), unscaled, at the material's roughness */
IBL_INLINE float3 split_sum_radiance(CHAIN_PARAMS, float3 r, float2 env_rot, float roughness)
{
    return chain_lookup(CHAIN_ARGS, to_env(r, env_rot), roughness * (float)(nlev - 1));
}

#endif
