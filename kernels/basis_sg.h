/* Spherical Gaussians, fixed axes and one sharpness (iblbake/core/bases/sg.py, the twin): each
 * lobe's exact cosine convolution, a polynomial of degree SG_PROFILE_DEGREE in mu.n (sg.py
 * profile_power). basis_coeffs: SG_LOBES rows (amplitude rgb), SG_LOBES rows (axis xyz,
 * sharpness), then the polynomial's coefficients of t^0.. four to a row. */
#ifndef IBLBAKE_BASIS_SG_H
#define IBLBAKE_BASIS_SG_H
#include "inline.h"
#ifdef BASIS_SG
#define HAS_BASIS 1

IBL_INLINE float3 basis_irradiance(BASIS_SPACE const float4 *bc, float3 n)
{
    BASIS_SPACE const float *poly = (BASIS_SPACE const float *)(bc + 2 * SG_LOBES);
    float3 e = (float3)(0.0f);
    for (int k = 0; k < SG_LOBES; ++k) {
        const float t = clamp(dot(bc[SG_LOBES + k].xyz, n), -1.0f, 1.0f);
        float s = poly[SG_PROFILE_DEGREE];
        for (int i = SG_PROFILE_DEGREE - 1; i >= 0; --i)      /* Horner */
            s = fma(s, t, poly[i]);
        e += bc[k].xyz * s;
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
