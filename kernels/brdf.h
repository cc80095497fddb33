/* Metallic-roughness BRDF terms (docs/conventions.md). Mirrors iblbake/core/brdf.py
 * (tests/test_brdf_sampling.py). */
#ifndef IBLBAKE_BRDF_H
#define IBLBAKE_BRDF_H

#define ALPHA_MIN 1e-7f

inline float d_ggx(float noh, float alpha)
{
    float a2 = fmax(alpha * alpha, ALPHA_MIN * ALPHA_MIN);
    noh = clamp(noh, 0.0f, 1.0f);
    /* noh^2 (a2 - 1) + 1 written as (1 - noh)(1 + noh) + noh^2 a2: no cancellation to 0 when
     * noh rounds to 1 and a2 is tiny (roughness -> 0), so D stays finite (1 / (pi a2)) */
    float d = (1.0f - noh) * (1.0f + noh) + noh * noh * a2;
    return a2 / (3.14159265358979323846f * d * d);
}

/* D from sin^2 and cos^2 of the half-vector angle: sin^2 taken as |n x h|^2 keeps its relative
 * precision for near-mirror lobes, where 1 - noh^2 in float32 is only a multiple of 1.2e-7. */
inline float d_ggx_sc(float sin2, float cos2, float alpha)
{
    float a2 = fmax(alpha * alpha, ALPHA_MIN * ALPHA_MIN);
    float d = sin2 + cos2 * a2;
    return a2 / (3.14159265358979323846f * d * d);
}

/* Height-correlated Smith V = G / (4 NoV NoL) (Heitz 2014), as Filament's DFG code. */
inline float v_smith_ggx_correlated(float nov, float nol, float alpha)
{
    float a2 = alpha * alpha;
    nov = clamp(nov, 0.0f, 1.0f);
    nol = clamp(nol, 0.0f, 1.0f);
    float lv = nol * sqrt(nov * nov * (1.0f - a2) + a2);
    float ll = nov * sqrt(nol * nol * (1.0f - a2) + a2);
    return 0.5f / fmax(lv + ll, 1e-30f);
}

/* Sheen (KHR_materials_sheen; Estevez and Kulla 2017): the Charlie NDF, alpha = sheen
 * roughness^2, and Ashikhmin and Premoze's visibility clamped to [0, 1] (the glTF Sample
 * Viewer's; Filament's "Neubelt" unclamped). */
#define SHEEN_ALPHA_MIN 1e-6f

inline float d_charlie(float noh, float alpha)
{
    const float a = fmax(alpha, SHEEN_ALPHA_MIN);
    noh = clamp(noh, 0.0f, 1.0f);
    const float sin2 = (1.0f - noh) * (1.0f + noh);
    return (2.0f + 1.0f / a) * pow(sin2, 0.5f / a) * (0.5f / 3.14159265358979323846f);
}

inline float v_ashikhmin(float nov, float nol)
{
    nov = clamp(nov, 0.0f, 1.0f);
    nol = clamp(nol, 0.0f, 1.0f);
    return fmin(1.0f / fmax(4.0f * (nol + nov - nol * nov), 1e-30f), 1.0f);   /* clamped as the glTF viewer */
}

/* Schlick's Fresnel weight c = (1 - VoH)^5: F = f0 + (1 - f0) c */
inline float schlick_weight(float voh)
{
    const float x = 1.0f - clamp(voh, 0.0f, 1.0f);
    const float x2 = x * x;
    return x2 * x2 * x;
}

inline float3 f_schlick(float voh, float3 f0)
{
    return f0 + (1.0f - f0) * schlick_weight(voh);
}

inline float3 f_schlick_roughness(float nov, float3 f0, float roughness)
{
    float x = 1.0f - clamp(nov, 0.0f, 1.0f);
    float x2 = x * x;
    return f0 + (fmax((float3)(1.0f - roughness), f0) - f0) * (x2 * x2 * x);
}

#endif
