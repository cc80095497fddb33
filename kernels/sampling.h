/* Sample sets and warps, each warp a pair sample_x / pdf_x (pbrt-v4's habit). Mirrors
 * iblbake/core/sampling.py; tests/test_sampling.py checks every warp against its own pdf with a
 * chi-square test on both sides (Mitsuba 3's ChiSquareTest). */
#ifndef IBLBAKE_SAMPLING_H
#define IBLBAKE_SAMPLING_H
#include "common.h"
#include "brdf.h"

inline float radical_inverse_vdc(uint b)
{
    b = (b << 16) | (b >> 16);
    b = ((b & 0x55555555u) << 1) | ((b & 0xAAAAAAAAu) >> 1);
    b = ((b & 0x33333333u) << 2) | ((b & 0xCCCCCCCCu) >> 2);
    b = ((b & 0x0F0F0F0Fu) << 4) | ((b & 0xF0F0F0F0u) >> 4);
    b = ((b & 0x00FF00FFu) << 8) | ((b & 0xFF00FF00u) >> 8);
    return (float)b * 2.3283064365386963e-10f;
}

inline float2 hammersley(uint i, uint n)
{
    return (float2)((float)i / (float)n, radical_inverse_vdc(i));
}

/* GGX half-vector, local frame (z = normal). theta = atan2(alpha sqrt(u1), sqrt(1 - u1));
 * pdf over half-vectors = D(h) cos(theta_h). */
inline float3 sample_ggx_half(float2 u, float alpha)
{
    float phi = 2.0f * 3.14159265358979323846f * u.x;
    float theta = atan2(alpha * sqrt(u.y), sqrt(fmax(0.0f, 1.0f - u.y)));
    float st = sin(theta);
    return (float3)(st * cos(phi), st * sin(phi), cos(theta));
}

/* The same warp without trigonometry, for per-pixel loops: the host uploads (cos phi, sin phi, u1)
 * per Hammersley point; cos theta = sqrt((1 - u1) / (1 - u1 + alpha^2 u1)) is the atan2 form's cosine. */
inline float3 sample_ggx_half_cs(float4 pt, float alpha)
{
    const float a2u = alpha * alpha * pt.z;
    const float den = (1.0f - pt.z) + a2u;
    const float ct = den > 0.0f ? sqrt((1.0f - pt.z) / den) : 1.0f;
    const float st = den > 0.0f ? sqrt(a2u / den) : 0.0f;
    return (float3)(st * pt.x, st * pt.y, ct);
}

inline float pdf_ggx_half(float noh, float alpha)
{
    return d_ggx(noh, alpha) * fmax(noh, 0.0f);
}

/* ---- random and quasi-random numbers */

/* PCG hash (Jarzynski and Olano 2020, "Hash Functions for GPU Rendering"): one 32-bit state step
 * of PCG plus its output permutation. */
inline uint pcg_hash(uint x)
{
    uint state = x * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

inline float hash_uniform(uint x)
{
    return (float)(pcg_hash(x) >> 8) * (1.0f / 16777216.0f);
}

/* Radical inverse of j in base b: Halton points, a quasi-random sequence that stays uniform at
 * every prefix, so a frame converges faster than with independent random numbers. */
inline float radical_inverse(uint j, uint b)
{
    const float inv_b = 1.0f / (float)b;
    float f = inv_b, r = 0.0f;
    while (j > 0u) {
        r += f * (float)(j % b);
        j /= b;
        f *= inv_b;
    }
    return fmin(r, 0x1.fffffep-1f);
}

/* Dimension d of sample j of replicate `rep` for G-buffer sample gid: Halton in base
 * HALTON_BASES[d], shifted by a random rotation per (seed, gid, replicate, dimension)
 * (Cranley-Patterson). Two replicates (even and odd sample numbers) with independent rotations
 * give an honest error estimate (their difference); a variance of QMC samples would not. */
__constant uint HALTON_BASES[8] = {2u, 3u, 5u, 7u, 11u, 13u, 17u, 19u};

inline float qmc(uint seed, uint gid, uint k, int d)
{
    const uint rep = k & 1u, j = k >> 1;
    const float shift = hash_uniform(seed ^ pcg_hash(gid * 16u + rep * 8u + (uint)d));
    const float x = radical_inverse(j, HALTON_BASES[d]) + shift;
    return x >= 1.0f ? x - 1.0f : x;
}

/* ---- warps: local frame z = normal */

/* Cosine-weighted hemisphere (Malley's method: a uniform disk point lifted to the hemisphere);
 * pdf = cos(theta) / pi. */
inline float3 sample_cosine_hemisphere(float2 u)
{
    const float r = sqrt(u.x), phi = 2.0f * IBL_PI * u.y;
    return (float3)(r * cos(phi), r * sin(phi), sqrt(fmax(0.0f, 1.0f - u.x)));
}

inline float pdf_cosine_hemisphere(float cos_theta)
{
    return fmax(cos_theta, 0.0f) * (1.0f / IBL_PI);
}

/* Uniform in the cone cos(theta) >= cos_max (a sphere light or the sun seen from a point):
 * cos(theta) = 1 - u (1 - cos_max); pdf = 1 / (2 pi (1 - cos_max)). */
inline float3 sample_uniform_cone(float2 u, float cos_max)
{
    const float ct = 1.0f - u.x * (1.0f - cos_max);
    const float st = sqrt(fmax(0.0f, 1.0f - ct * ct)), phi = 2.0f * IBL_PI * u.y;
    return (float3)(st * cos(phi), st * sin(phi), ct);
}

inline float pdf_uniform_cone(float cos_max)
{
    return 1.0f / (2.0f * IBL_PI * (1.0f - cos_max));
}

/* Smith G1 for GGX, the masking of the view direction. */
inline float g1_smith(float nov, float alpha)
{
    const float a2 = alpha * alpha;
    return 2.0f * nov / (nov + sqrt(a2 + (1.0f - a2) * nov * nov));
}

/* Visible normals of GGX (Heitz 2018, "Sampling the GGX Distribution of Visible Normals"):
 * stretch the view vector, sample the projected hemisphere, unstretch. pdf over half-vectors
 * = G1(v) max(0, v.h) D(h) / NoV; over reflected directions that divided by 4 v.h. */
inline float3 sample_ggx_vndf(float3 vl, float alpha, float2 u)
{
    const float3 vh = normalize((float3)(alpha * vl.x, alpha * vl.y, vl.z));
    const float lensq = vh.x * vh.x + vh.y * vh.y;
    const float3 t1 = lensq > 0.0f ? (float3)(-vh.y, vh.x, 0.0f) * rsqrt(lensq) : (float3)(1.0f, 0.0f, 0.0f);
    const float3 t2 = cross(vh, t1);
    const float r = sqrt(u.x), phi = 2.0f * IBL_PI * u.y;
    const float p1 = r * cos(phi);
    float p2 = r * sin(phi);
    const float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * sqrt(fmax(0.0f, 1.0f - p1 * p1)) + s * p2;
    const float3 nh = p1 * t1 + p2 * t2 + sqrt(fmax(0.0f, 1.0f - p1 * p1 - p2 * p2)) * vh;
    return normalize((float3)(alpha * nh.x, alpha * nh.y, fmax(1e-7f, nh.z)));
}

inline float pdf_ggx_vndf_reflected(float nov, float noh, float alpha)
{
    return g1_smith(nov, alpha) * d_ggx(noh, alpha) / (4.0f * nov);
}

/* ---- the environment: piecewise constant over the panorama's texels, p(texel) proportional to
 * luminance x solid angle (tables built by iblbake/core/sampling.py: EnvironmentDistribution).
 * Row from the marginal CDF, column from the row's CDF, then uniform in (phi, cos theta) inside
 * the texel, so the pdf over solid angle is p_texel / Omega_texel (the pdf table). */
inline int cdf_search(__global const float *cdf, int n, float u)
{
    int lo = 0, hi = n - 1;                 /* cdf[0..n], cdf[0] = 0, cdf[n] = 1 */
    while (lo < hi) {
        const int mid = (lo + hi) >> 1;
        if (cdf[mid + 1] <= u) lo = mid + 1; else hi = mid;
    }
    return lo;
}

/* Direction in the panorama's frame from four uniforms; *texel = j * w + i. */
inline float3 sample_env(__global const float *marginal, __global const float *conditional, int w, int h,
                         float4 u, int *texel)
{
    const int j = cdf_search(marginal, h, u.x);
    const int i = cdf_search(conditional + j * (w + 1), w, u.y);
    const float uu = ((float)i + u.z) / (float)w;
    const float c0 = cospi((float)j / h), c1 = cospi((float)(j + 1) / h);
    const float ct = mix(c0, c1, u.w);
    const float stt = sqrt(fmax(0.0f, 1.0f - ct * ct)), phi = 2.0f * IBL_PI * (0.5f - uu);
    *texel = j * w + i;
    return (float3)(stt * sin(phi), ct, stt * cos(phi));
}

/* The texel a direction (panorama frame) falls in, nearest: the pdf table's index for it. */
inline int env_texel_index(float3 e, int w, int h)
{
    const float2 uv = equirect_uv_from_dir(e);
    return min((int)(uv.y * h), h - 1) * w + min((int)(uv.x * w), w - 1);
}

inline float pdf_env(__global const float *pdf_table, int texel)
{
    return pdf_table[texel];
}

/* ---- multiple importance sampling */

/* Power heuristic a^2 / (a^2 + b^2) (Veach 1997), written so that an infinite or huge pdf (a
 * near-mirror lobe) gives 1 or 0 instead of inf / inf. */
inline float power_heuristic(float a, float b)
{
    if (!(a > 0.0f)) return 0.0f;
    const float r = b / a;
    return 1.0f / (1.0f + r * r);
}

#endif
