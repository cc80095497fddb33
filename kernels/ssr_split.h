/* The split for screen-space reflections: per sample, the weight W = spec_occ (F0 A + F90 B) (times
 * the occlusion map) of the split sum's reflected environment and the radiance li it read (the probes'
 * or the panorama's), which the ssr pass replaces where its rays meet the frame (kernels/ssr.cl).
 * numpy twin: iblbake/render/twin/shade.py (ssr_out). */
#ifndef IBLBAKE_SSR_SPLIT_H
#define IBLBAKE_SSR_SPLIT_H
#include "inline.h"

IBL_INLINE void ssr_split(__global float4 *ssr_env, int gid, float3 w, float3 li)
{
    ssr_env[2 * gid] = (float4)(w, 0.0f);
    ssr_env[2 * gid + 1] = (float4)(li, 0.0f);
}

#endif
