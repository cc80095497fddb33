/* Lookups in a chain of equirect levels stored back to back in one buffer of RGB floats (the
 * radiance chain, the prefiltered chain; off[] counts texels). Mirrors iblbake/bake/radiance.py:
 * chain_lookup_twin. */
#ifndef IBLBAKE_ENVMAP_H
#define IBLBAKE_ENVMAP_H
#include "common.h"

/* Trilinear lookup in the radiance chain: bilinear in two levels, blended. */
/* Solid angle of a level-0 texel (w0 x h0) of the chain at direction l: (2 pi / w0)(pi / h0)
 * sin(theta), floored at the polar row's centre; continuous in latitude so that the level a
 * filtered lookup picks does not jump at row boundaries. Mirrors iblbake/bake/radiance.py: texel_solid_angle_at. */
inline float texel_solid_angle(float3 l, int w0, int h0)
{
    const float st = fmax(sqrt(fmax(0.0f, 1.0f - l.y * l.y)), sin(0.5f * IBL_PI / h0));
    return (2.0f * IBL_PI / w0) * (IBL_PI / h0) * st;
}

inline float3 chain_lookup(__global const float *chain, __constant int *off, __constant int *lw,
                           __constant int *lh, const int nlev, float3 d, float lod)
{
    const float2 uv = equirect_uv_from_dir(d);
    /* +-inf clamp to the ends; NaN (the 0/0 pdf of a delta lobe) reads level 0 */
    lod = isnan(lod) ? 0.0f : clamp(lod, 0.0f, (float)(nlev - 1));
    const int l0 = (int)lod;
    const int l1 = min(l0 + 1, nlev - 1);
    const float f = lod - (float)l0;
    float3 a = bilinear_equirect(chain + 3 * (size_t)off[l0], lw[l0], lh[l0], uv);
    if (f <= 0.0f) return a;
    return mix(a, bilinear_equirect(chain + 3 * (size_t)off[l1], lw[l1], lh[l1], uv), f);
}

#endif
