/* Importance-sampled specular, combined: the importance pass's two sums of a sample
 * (kernels/importance.cl, split around Schlick's Fresnel) with its f0 and f90, F = f0 (1 - c) + f90 c.
 * numpy twin: iblbake/render/twin/shade.py. */
#ifndef IBLBAKE_IMPORTANCE_H
#define IBLBAKE_IMPORTANCE_H
#include "surface.h"

IBL_INLINE float3 importance_specular(__global const float4 *spec_sums, int gid, const Material mt)
{
    return mt.f0 * spec_sums[2 * gid].xyz + mt.f90 * spec_sums[2 * gid + 1].xyz;
}

#endif
