/* The environment: lookups in a chain of equirect levels stored back to back in one buffer of
 * RGB floats (the radiance chain, the prefiltered chain; off[] counts texels; CHAIN_PARAMS), and
 * its importance sampling. Mirrors iblbake/bake/radiance.py: chain_lookup_twin and
 * iblbake/core/sampling.py: EnvironmentDistribution. */
#ifndef IBLBAKE_ENVMAP_H
#define IBLBAKE_ENVMAP_H
#include "common.h"

/* A chain's kernel parameters and arguments (bound by name from Bakes.chain's table). */
#define CHAIN_PARAMS __global const float *chain, __constant int *off, __constant int *lw, __constant int *lh, \
                     const int nlev
#define CHAIN_ARGS chain, off, lw, lh, nlev

/* The environment a path samples and meets, as kernel parameters and arguments (bound by name:
 * the frame's env_rot and env_scale, render/device_scene.py environment_frame; the panorama's
 * texels and its importance-sampling tables, panorama_args): its rotation about y as (cos, sin)
 * and its intensity, the full-resolution panorama (w x h RGBA texels, read piecewise constant),
 * the marginal CDF over rows, one CDF per row, the guide tables (ENV_GUIDE_BINS + 1 entries each,
 * core/sampling.py cdf_guides: the h rows', then the marginal's), and env_norm, what turns a
 * texel's luminance into the pdf over solid angle of sampling it (pdf_env: 1 / total, the offset). */
#define ENV_PARAMS const float2 env_rot, const float env_scale, __global const float4 *img, const int w, \
                   const int h, __global const float *marginal, __global const float *conditional, \
                   __global const int *guide, const float2 env_norm
#define ENV_ARGS env_rot, env_scale, img, w, h, marginal, conditional, guide, env_norm

/* Trilinear lookup in the radiance chain: bilinear in two levels, blended. */
/* Solid angle of a level-0 texel (w0 x h0) of the chain at direction l: (2 pi / w0)(pi / h0)
 * sin(theta), floored at the polar row's centre; continuous in latitude so that the level a
 * filtered lookup picks does not jump at row boundaries. Mirrors iblbake/bake/radiance.py: texel_solid_angle_at. */
IBL_INLINE float texel_solid_angle(float3 l, int w0, int h0)
{
    const float st = fmax(sqrt(fmax(0.0f, 1.0f - l.y * l.y)), sin(0.5f * IBL_PI / h0));
    return (2.0f * IBL_PI / w0) * (IBL_PI / h0) * st;
}

IBL_INLINE float3 chain_lookup(CHAIN_PARAMS, float3 d, float lod)
{
    const float2 uv = equirect_uv_from_dir(d);
    /* +-inf clamp to the ends; NaN (the 0/0 pdf of a delta lobe) reads level 0 */
    lod = isnan(lod) ? 0.0f : clamp(lod, 0.0f, (float)(nlev - 1));
    const int l0 = (int)lod;
    const int l1 = min(l0 + 1, nlev - 1);
    const float f = lod - (float)l0;
    float3 a = bilinear_equirect(chain + 3 * (size_t)off[l0], lw[l0], lh[l0], uv);
    if (f <= 0.0f) return a;
    return mix(a, bilinear_equirect(chain + 3 * (size_t)off[l1], lw[l1], lh[l1], uv), f);
}

/* Importance sampling: piecewise constant over the panorama's texels, p(texel) proportional to
 * (luminance - the panorama's mean, floored at 0) x solid angle (MIS compensation; tables built
 * by iblbake/core/sampling.py env_sampling_tables).
 * Row from the marginal CDF, column from the row's CDF, then uniform in (phi, cos theta) inside
 * the texel, so the pdf over solid angle is p_texel / Omega_texel (the pdf table). */
/* The bin of u in a CDF: the smallest i in [lo, hi] with cdf[i + 1] > u, hi where none is */
IBL_INLINE int cdf_search(__global const float *cdf, int lo, int hi, float u)
{
    while (lo < hi) {
        const int mid = (lo + hi) >> 1;
        if (cdf[mid + 1] <= u) lo = mid + 1; else hi = mid;
    }
    return lo;
}

/* Direction in the panorama's frame from four uniforms; *texel = j * w + i. */
IBL_INLINE float3 sample_env(__global const float *marginal, __global const float *conditional,
                             __global const int *guide, int w, int h, float4 u, int *texel)
{
    /* a guide table (Chen and Asau 1974) brackets u's bin between the bins of the multiples of
     * 1 / ENV_GUIDE_BINS around it (exact in float32): the same bin as a search of the whole CDF
     * in one or two cache lines, not ~11 dependent loads and mispredicted branches (on PoCL the
     * marginal's whole search was a fifth of a draw: benchmarks/bench_env_sampling.py) */
    const int gm = min((int)(u.x * ENV_GUIDE_BINS), ENV_GUIDE_BINS - 1);
    __global const int *gmr = guide + h * (ENV_GUIDE_BINS + 1);
    const int j = cdf_search(marginal, gmr[gm], gmr[gm + 1], u.x);
    const int g = min((int)(u.y * ENV_GUIDE_BINS), ENV_GUIDE_BINS - 1);
    __global const int *gr = guide + j * (ENV_GUIDE_BINS + 1);
    const int i = cdf_search(conditional + j * (w + 1), gr[g], gr[g + 1], u.y);
    const float uu = ((float)i + u.z) / (float)w;
    const float c0 = cospi((float)j / h), c1 = cospi((float)(j + 1) / h);
    const float ct = mix(c0, c1, u.w);
    const float stt = sqrt(fmax(0.0f, 1.0f - ct * ct));
    const float2 cs = cossin_2pi(0.5f - uu);              /* phi = 2 pi (0.5 - u) */
    *texel = j * w + i;
    return (float3)(stt * cs.y, ct, stt * cs.x);
}

/* The texel a direction (panorama frame) falls in, nearest: the pdf table's index for it. */
IBL_INLINE int env_texel_index(float3 e, int w, int h)
{
    const float2 uv = equirect_uv_from_dir(e);
    return min((int)(uv.y * h), h - 1) * w + min((int)(uv.x * w), w - 1);
}

/* The pdf over solid angle of sampling the texel of radiance c: p(texel) / Omega(texel) with p
 * proportional to (luminance - the panorama's mean, floored at 0) x Omega (MIS compensation:
 * core/sampling.py env_sampling_tables) is (luminance - env_norm.y) x env_norm.x (1 / total:
 * core/sampling.py EnvironmentDistribution.norm). Read from the radiance a path loads anyway, not
 * from a table: on a CPU the tables of a 2048 x 1024 panorama (40 MB) miss the cache, and a table
 * of pdfs was one miss more a sample (docs/benchmarks.md "The environment's tables in the cache"). */
IBL_INLINE float pdf_env(float3 c, float2 env_norm)
{
    return fmax(luminance(c) - env_norm.y, 0.0f) * env_norm.x;
}

#endif
