/* Tone mapping (docs/conventions.md). Mirrors iblbake/core/tonemap.py (tests/test_tonemap.py).
 * TONEMAP: 0 aces, 1 reinhard, 2 hable, 3 pbr_neutral, 4 linear (only the chosen operator is
 * compiled). OUTPUT_SRGB: 1 exact sRGB encoding, 0 pure gamma (1/gamma). */
#ifndef IBLBAKE_TONEMAP_H
#define IBLBAKE_TONEMAP_H
#include "common.h"

#ifndef TONEMAP
#define TONEMAP 0
#endif
#ifndef OUTPUT_SRGB
#define OUTPUT_SRGB 1
#endif

#define TONEMAP_INPUT_CAP 1e18f

/* NaN -> 0 (fmax ignores NaN), negative -> 0, +Inf and huge -> cap. */
IBL_INLINE float3 tonemap_sanitize(float3 x)
{
    return fmin(fmax(x, (float3)(0.0f)), (float3)(TONEMAP_INPUT_CAP));
}

#if TONEMAP == 2
IBL_INLINE float3 hable_curve(float3 x)
{
    const float a = 0.15f, b = 0.50f, c = 0.10f, d = 0.20f, e = 0.02f, f = 0.30f;
    return (x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f) - e / f;
}
#endif

IBL_INLINE float3 tonemap_operator(float3 x)
{
#if TONEMAP == 0
    return clamp((x * (2.51f * x + 0.03f)) / (x * (2.43f * x + 0.59f) + 0.14f), 0.0f, 1.0f);
#elif TONEMAP == 1
    return x / (1.0f + x);
#elif TONEMAP == 2
    return clamp(hable_curve(x) / hable_curve((float3)(11.2f)), 0.0f, 1.0f);
#elif TONEMAP == 3
    const float f90 = 0.04f, ks = 0.8f - 0.04f, kd = 0.15f;
    const float m = fmin(x.x, fmin(x.y, x.z));
    const float f = m <= 2.0f * f90 ? m - m * m / (4.0f * f90) : f90;
    const float3 c = x - f;
    const float p = fmax(c.x, fmax(c.y, c.z));
    if (p <= ks) return c;
    const float pn = 1.0f - (1.0f - ks) * (1.0f - ks) / (p + 1.0f - 2.0f * ks);
    const float g = 1.0f / (kd * (p - pn) + 1.0f);
    return c * (pn / p) * g + pn * (1.0f - g);
#else
    return clamp(x, 0.0f, 1.0f);
#endif
}

IBL_INLINE float3 output_transfer(float3 y, float gamma)
{
    y = clamp(y, 0.0f, 1.0f);
#if OUTPUT_SRGB
    return select(1.055f * pow_fast3(y, 1.0f / 2.4f) - 0.055f, 12.92f * y, isless(y, (float3)(0.0031308f)));
#else
    return pow_fast3(y, 1.0f / gamma);
#endif
}

/* Exposure (x 2^EV, given as its scale), operator, transfer: display values in [0, 1]. */
IBL_INLINE float3 tonemap_display(float3 hdr, float exposure_scale, float gamma)
{
    float3 x = tonemap_sanitize(tonemap_sanitize(hdr) * exposure_scale);
    return output_transfer(tonemap_operator(x), gamma);
}

#endif
