/* GGX (Trowbridge-Reitz) in one place: the distribution D, Smith's masking G1 and the
 * height-correlated visibility V, and the two warps that sample it with their pdfs (half vectors;
 * visible normals). alpha = roughness^2 (docs/conventions.md). Mirrors iblbake/core/brdf.py and
 * iblbake/core/sampling.py (tests/test_brdf_sampling.py, tests/test_sampling.py). */
#ifndef IBLBAKE_GGX_H
#define IBLBAKE_GGX_H
#include "common.h"

#define ALPHA_MIN 1e-7f

IBL_INLINE float d_ggx(float noh, float alpha)
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
IBL_INLINE float d_ggx_sc(float sin2, float cos2, float alpha)
{
    float a2 = fmax(alpha * alpha, ALPHA_MIN * ALPHA_MIN);
    float d = sin2 + cos2 * a2;
    return a2 / (3.14159265358979323846f * d * d);
}

/* Height-correlated Smith V = G / (4 NoV NoL) (Heitz 2014), as Filament's DFG code. */
IBL_INLINE float v_smith_ggx_correlated(float nov, float nol, float alpha)
{
    float a2 = alpha * alpha;
    nov = clamp(nov, 0.0f, 1.0f);
    nol = clamp(nol, 0.0f, 1.0f);
    float lv = nol * sqrt(nov * nov * (1.0f - a2) + a2);
    float ll = nov * sqrt(nol * nol * (1.0f - a2) + a2);
    return 0.5f / fmax(lv + ll, 1e-30f);
}

/* Smith G1 for GGX, the masking of the view direction. */
IBL_INLINE float g1_smith(float nov, float alpha)
{
    const float a2 = alpha * alpha;
    return 2.0f * nov / (nov + sqrt(a2 + (1.0f - a2) * nov * nov));
}

/* GGX half-vector, local frame (z = normal). theta = atan2(alpha sqrt(u1), sqrt(1 - u1));
 * pdf over half-vectors = D(h) cos(theta_h). */
IBL_INLINE float3 sample_ggx_half(float2 u, float alpha)
{
    const float2 cs = cossin_2pi(u.x);
    float theta = atan2(alpha * sqrt(u.y), sqrt(fmax(0.0f, 1.0f - u.y)));
    float st = sin(theta);
    return (float3)(st * cs.x, st * cs.y, cos(theta));
}

/* The same warp without trigonometry, for per-pixel loops: the host uploads (cos phi, sin phi, u1)
 * per Hammersley point; cos theta = sqrt((1 - u1) / (1 - u1 + alpha^2 u1)) is the atan2 form's cosine. */
IBL_INLINE float3 sample_ggx_half_cs(float4 pt, float alpha)
{
    const float a2u = alpha * alpha * pt.z;
    const float den = (1.0f - pt.z) + a2u;
    const float ct = den > 0.0f ? sqrt((1.0f - pt.z) / den) : 1.0f;
    const float st = den > 0.0f ? sqrt(a2u / den) : 0.0f;
    return (float3)(st * pt.x, st * pt.y, ct);
}

IBL_INLINE float pdf_ggx_half(float noh, float alpha)
{
    return d_ggx(noh, alpha) * fmax(noh, 0.0f);
}

/* Visible normals of GGX (Heitz 2018, "Sampling the GGX Distribution of Visible Normals"):
 * stretch the view vector, sample the projected hemisphere, unstretch. pdf over half-vectors
 * = G1(v) max(0, v.h) D(h) / NoV; over reflected directions that divided by 4 v.h. */
IBL_INLINE float3 sample_ggx_vndf(float3 vl, float alpha, float2 u)
{
    const float3 vh = normalize((float3)(alpha * vl.x, alpha * vl.y, vl.z));
    const float lensq = vh.x * vh.x + vh.y * vh.y;
    const float3 t1 = lensq > 0.0f ? (float3)(-vh.y, vh.x, 0.0f) * rsqrt(lensq) : (float3)(1.0f, 0.0f, 0.0f);
    const float3 t2 = cross(vh, t1);
    const float r = sqrt(u.x);
    const float2 cs = cossin_2pi(u.y);
    const float p1 = r * cs.x;
    float p2 = r * cs.y;
    const float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * sqrt(fmax(0.0f, 1.0f - p1 * p1)) + s * p2;
    const float3 nh = p1 * t1 + p2 * t2 + sqrt(fmax(0.0f, 1.0f - p1 * p1 - p2 * p2)) * vh;
    return normalize((float3)(alpha * nh.x, alpha * nh.y, fmax(1e-7f, nh.z)));
}

/* One GGX visible normal drawn from u, seen from v whose components in the frame (t, b, n) are
 * vl (z the caller's NoV), and v reflected about it: the reflected direction; *h the world half
 * vector, *noh its NoH (unfloored). The twin: core/sampling.py reflect_ggx_vndf. */
IBL_INLINE float3 reflect_ggx_vndf(float2 u, float3 t, float3 b, float3 n, float3 v, float3 vl, float alpha,
                                   float3 *h, float *noh)
{
    const float3 hl = sample_ggx_vndf(vl, alpha, u);
    *noh = hl.z;
    *h = t * hl.x + b * hl.y + n * hl.z;
    return 2.0f * dot(v, *h) * *h - v;
}

IBL_INLINE float pdf_ggx_vndf_reflected(float nov, float noh, float alpha)
{
    return g1_smith(nov, alpha) * d_ggx(noh, alpha) / (4.0f * nov);
}

#endif
