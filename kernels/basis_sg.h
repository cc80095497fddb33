/* Spherical Gaussians, fixed axes and one sharpness (iblbake/core/bases/sg.py, the twin): Hill's
 * fitted SG-cosine irradiance (Pettineo's SG Series part 3, SGIrradianceFitted). basis_coeffs:
 * SG_LOBES rows (amplitude rgb), then SG_LOBES rows (axis xyz, sharpness). */
#ifndef IBLBAKE_BASIS_SG_H
#define IBLBAKE_BASIS_SG_H
#include "inline.h"
#ifdef BASIS_SG
#define HAS_BASIS 1

IBL_INLINE float3 basis_irradiance(BASIS_SPACE const float4 *bc, float3 n)
{
    const float lam = bc[SG_LOBES].w;
    const float eml = exp(-lam), em2l = eml * eml;
    const float scale = 1.0f + 2.0f * em2l - 1.0f / lam;
    const float bias = (eml - em2l) / lam - em2l;
    const float x = sqrt(1.0f - scale), x1 = x / (4.0f * 0.36f);
    const float integral = 6.28318530717958648f / lam;      /* the approximate SG integral, 2 pi / lambda */
    float3 e = (float3)(0.0f);
    for (int k = 0; k < SG_LOBES; ++k) {
        const float mdn = dot(bc[SG_LOBES + k].xyz, n), x0 = 0.36f * mdn;
        const float y = fabs(x0) <= x1 ? (x0 + x1) * (x0 + x1) / x : clamp(mdn, 0.0f, 1.0f);
        e += bc[k].xyz * ((scale * y + bias) * integral);
    }
    return fmax(e, (float3)(0.0f));
}

/* s[k]: the normalised SG-SG inner product of lobe k with the warped GGX lobe about r of
 * sharpness lam_w (sg.py specular_weights; kernels/bases.h sums s[k] A_k) */
#define HAS_BASIS_SPECULAR 1
#define BASIS_SPECULAR_ROWS SG_LOBES
IBL_INLINE void basis_specular_weights(BASIS_SPACE const float4 *bc, __global const float *basis_table, float3 r,
                                   float lam_w, float *s)
{
    const float lam = bc[SG_LOBES].w;
    const float norm = lam_w / -expm1(-2.0f * lam_w);
    for (int k = 0; k < SG_LOBES; ++k) {
        const float t = dot(bc[SG_LOBES + k].xyz, r);
        const float d = sqrt(fmax(lam * lam + lam_w * lam_w + 2.0f * lam * lam_w * t, 1e-12f));
        /* d - lam - lam_w without cancellation (sg.py) */
        const float x = lam * (lam + 2.0f * lam_w * t) / (d + lam_w) - lam;
        s[k] = (exp(x) - exp(-d - lam - lam_w)) / d * norm;
    }
}

#endif
#endif
