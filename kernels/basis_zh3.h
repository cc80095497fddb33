/* ZH3 (iblbake/core/bases/zh3.py, the twin): L1 SH plus one zonal L2 coefficient along the
 * luminance-weighted L1 direction, recomputed here from the stored L1 (+y where it cancels).
 * basis_coeffs: the 4 L1 radiance coefficients (k = l (l + 1) + m; Y1 ~ y, Y2 ~ z, Y3 ~ x), then
 * the zonal coefficient, rgb. */
#ifndef IBLBAKE_BASIS_ZH3_H
#define IBLBAKE_BASIS_ZH3_H
#include "inline.h"
#ifdef BASIS_ZH3
#define HAS_BASIS 1

IBL_INLINE float3 basis_irradiance(BASIS_SPACE const float4 *bc, float3 n)
{
    const float3 lum = (float3)(0.2126f, 0.7152f, 0.0722f);
    const float3 v = (float3)(dot(bc[3].xyz, lum), dot(bc[1].xyz, lum), dot(bc[2].xyz, lum));
    const float vv = dot(v, v);
    const float3 a = vv > 0.0f ? v * rsqrt(vv) : (float3)(0.0f, 1.0f, 0.0f);
    const float t = dot(a, n);
    const float pi = 3.14159265358979324f;
    const float3 e = pi * 0.282094792f * bc[0].xyz
                   + (2.0f * pi / 3.0f) * 0.488602512f * (bc[1].xyz * n.y + bc[2].xyz * n.z + bc[3].xyz * n.x)
                   + (pi / 4.0f) * 0.315391565f * (3.0f * t * t - 1.0f) * bc[4].xyz;
    return fmax(e, (float3)(0.0f));
}

#endif
#endif
