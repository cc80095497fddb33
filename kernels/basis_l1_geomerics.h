/* L1 SH with Geomerics' non-linear reconstruction (iblbake/core/bases/l1_geomerics.py, the twin:
 * the formula and its constants). basis_coeffs: the 4 L1 radiance coefficients, k = l (l + 1) + m
 * (Y1 ~ y, Y2 ~ z, Y3 ~ x), rgb. */
#ifndef IBLBAKE_BASIS_L1_GEOMERICS_H
#define IBLBAKE_BASIS_L1_GEOMERICS_H
#include "inline.h"
#ifdef BASIS_L1_GEOMERICS
#define HAS_BASIS 1

IBL_INLINE float l1_geomerics_channel(float l0, float3 l1, float3 n)
{
    const float r0 = 3.14159265358979324f * 0.282094792f * l0;           /* pi Y0 L00 */
    const float3 r1 = (3.14159265358979324f / 3.0f) * 0.488602512f * l1;  /* (2 pi / 3) Y1 L1 / 2 */
    if (r0 <= 0.0f) return 0.0f;
    const float len = length(r1), r = fmin(len / r0, 1.0f);
    const float q = len > 0.0f ? clamp(0.5f * (1.0f + dot(n, r1 / len)), 0.0f, 1.0f) : 0.5f;
    const float p = 1.0f + 2.0f * r, a = (1.0f - r) / (1.0f + r);
    return r0 * (a + (1.0f - a) * (p + 1.0f) * pow(q, p));
}

IBL_INLINE float3 basis_irradiance(BASIS_SPACE const float4 *bc, float3 n)
{
    return (float3)(l1_geomerics_channel(bc[0].x, (float3)(bc[3].x, bc[1].x, bc[2].x), n),
                    l1_geomerics_channel(bc[0].y, (float3)(bc[3].y, bc[1].y, bc[2].y), n),
                    l1_geomerics_channel(bc[0].z, (float3)(bc[3].z, bc[1].z, bc[2].z), n));
}

#endif
#endif
