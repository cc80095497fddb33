/* Real orthonormal spherical harmonics (docs/conventions.md): z polar axis, no Condon-Shortley phase,
 * k = l*(l+1) + m. Mirrors iblbake/core/sh.py (sh_basis); tests/test_sh.py checks the two agree.
 * Legendre recurrences on P~ = P_l^m / sin^m(theta), times Re/Im((x + i y)^m) = sin^m cos/sin(m phi)
 * (as Filament's computeShBasis), so no trigonometric call is needed. */
#ifndef IBLBAKE_SH_H
#define IBLBAKE_SH_H
#include "inline.h"

#ifndef SH_BANDS
#define SH_BANDS 3
#endif
#define SH_COEFFS (SH_BANDS * SH_BANDS)

IBL_INLINE void sh_eval(float3 d, float *Y)
{
    /* K_l^m kept per l, stepped in m: K_l^m = K_l^{m-1} / sqrt((l+m)(l-m+1)). */
    float K[SH_BANDS];
    for (int l = 0; l < SH_BANDS; ++l) K[l] = sqrt((2.0f * l + 1.0f) / (4.0f * 3.14159265358979323846f));
    float pmm = 1.0f, cm = 1.0f, sm = 0.0f;
    for (int m = 0; m < SH_BANDS; ++m) {
        if (m > 0) {
            pmm *= (float)(2 * m - 1);
            float c = cm * d.x - sm * d.y;
            sm = sm * d.x + cm * d.y;
            cm = c;
            for (int l = m; l < SH_BANDS; ++l) K[l] *= rsqrt((float)((l + m) * (l - m + 1)));
        }
        float p2 = 0.0f, p1 = pmm;
        for (int l = m; l < SH_BANDS; ++l) {
            float p;
            if (l == m) p = pmm;
            else if (l == m + 1) p = (2.0f * m + 1.0f) * d.z * pmm;
            else p = ((2.0f * l - 1.0f) * d.z * p1 - (float)(l + m - 1) * p2) / (float)(l - m);
            if (l > m) { p2 = p1; p1 = p; }
            if (m == 0) {
                Y[l * (l + 1)] = K[l] * p;
            } else {
                float kp = 1.41421356237309515f * K[l] * p;
                Y[l * (l + 1) + m] = kp * cm;
                Y[l * (l + 1) - m] = kp * sm;
            }
        }
    }
}

/* Irradiance at normal n from SH_COEFFS irradiance coefficients (E_lm = Ahat_l L_lm; docs/conventions.md),
 * clamped at 0: a band-limited fit rings below zero behind a bright sun. */
IBL_INLINE float3 sh_irradiance(__constant float4 *coeffs, float3 n)
{
    float Y[SH_COEFFS];
    sh_eval(n, Y);
    float3 e = (float3)(0.0f);
    for (int k = 0; k < SH_COEFFS; ++k) e += coeffs[k].xyz * Y[k];
    return fmax(e, (float3)(0.0f));
}

#endif
