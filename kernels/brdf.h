/* Metallic-roughness BRDF terms beside GGX (ggx.h): Fresnel and the sheen lobe
 * (docs/conventions.md). Mirrors iblbake/core/brdf.py (tests/test_brdf_sampling.py). */
#ifndef IBLBAKE_BRDF_H
#define IBLBAKE_BRDF_H
#include "ggx.h"

/* Sheen (KHR_materials_sheen; Estevez and Kulla 2017): the Charlie NDF, alpha = sheen
 * roughness^2, and Ashikhmin and Premoze's visibility clamped to [0, 1] (the glTF Sample
 * Viewer's; Filament's "Neubelt" unclamped). */
#define SHEEN_ALPHA_MIN 1e-6f

IBL_INLINE float d_charlie(float noh, float alpha)
{
    const float a = fmax(alpha, SHEEN_ALPHA_MIN);
    noh = clamp(noh, 0.0f, 1.0f);
    const float sin2 = (1.0f - noh) * (1.0f + noh);
    return (2.0f + 1.0f / a) * pow(sin2, 0.5f / a) * (0.5f / 3.14159265358979323846f);
}

IBL_INLINE float v_ashikhmin(float nov, float nol)
{
    nov = clamp(nov, 0.0f, 1.0f);
    nol = clamp(nol, 0.0f, 1.0f);
    return fmin(1.0f / fmax(4.0f * (nol + nov - nol * nov), 1e-30f), 1.0f);   /* clamped as the glTF viewer */
}

/* Schlick's Fresnel weight c = (1 - VoH)^5: F = f0 + (f90 - f0) c */
IBL_INLINE float schlick_weight(float voh)
{
    const float x = 1.0f - clamp(voh, 0.0f, 1.0f);
    const float x2 = x * x;
    return x2 * x2 * x;
}

IBL_INLINE float3 f_schlick(float voh, float3 f0, float3 f90)
{
    return f0 + (f90 - f0) * schlick_weight(voh);
}

/* Fdez-Aguera's roughness-dependent Fresnel for the diffuse weight, its grazing value
 * max(F90 - roughness, F0) (F90 = 1: the usual max(1 - roughness, F0)) */
IBL_INLINE float3 f_schlick_roughness(float nov, float3 f0, float3 f90, float roughness)
{
    float x = 1.0f - clamp(nov, 0.0f, 1.0f);
    float x2 = x * x;
    return f0 + (fmax(f90 - roughness, f0) - f0) * (x2 * x2 * x);
}

#endif
