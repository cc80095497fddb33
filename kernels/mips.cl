/* The specular bakes of `iblbake mips`. numpy twins in iblbake/bake/ (radiance, prefilter, dfg); tests compare them.
 *   downsample  one level of the radiance chain (solid-angle-weighted mean of covered texels)
 *   prefilter   one level of the GGX-prefiltered chain (Karis 2013, N = V = R, NoL-weighted,
 *               filtered importance sampling, Krivanek and Colbert 2008), for LAYOUT
 *               0 = equirect, 1 = cubemap (faces +X -X +Y -Y +Z -Z stacked), 2 = octahedral
 *   dfg         the split-sum DFG table (Karis 2013's DFG with the height-correlated Smith V) */
#include "common.h"
#include "brdf.h"
#include "sampling.h"
#include "envmap.h"

#ifndef LAYOUT
#define LAYOUT 0
#endif

/* Parent texel (i, j) of a dw x dh level = the mean of the child texels it covers, each weighted
 * by the solid angle of the overlap (azimuth overlap x (cos a - cos b)); exact for any sizes. */
__kernel void downsample(__global float *chain, const int src_off, const int sw, const int sh,
                         const int dst_off, const int dw, const int dh)
{
    __global const float *src = chain + 3 * (size_t)src_off;
    __global float *dst = chain + 3 * (size_t)dst_off;
    const int i = get_global_id(0), j = get_global_id(1);
    if (i >= dw || j >= dh) return;
    const float ua = (float)i * sw / dw, ub = (float)(i + 1) * sw / dw;
    const float va = (float)j * sh / dh, vb = (float)(j + 1) * sh / dh;
    float3 acc = (float3)(0.0f);
    float wsum = 0.0f;
    for (int cj = (int)floor(va); cj < (int)ceil(vb) && cj < sh; ++cj) {
        const float lo = fmax(va, (float)cj), hi = fmin(vb, (float)(cj + 1));
        if (hi <= lo) continue;
        /* cos(pi lo/sh) - cos(pi hi/sh) = 2 sin(pi (lo+hi)/(2 sh)) sin(pi (hi-lo)/(2 sh)), pole-symmetric */
        const float mid = fmin(lo + hi, 2.0f * sh - lo - hi);
        const float wt = sin(IBL_PI * 0.5f * mid / sh) * sin(IBL_PI * 0.5f * (hi - lo) / sh);
        for (int ci = (int)floor(ua); ci < (int)ceil(ub) && ci < sw; ++ci) {
            const float wu = fmin(ub, (float)(ci + 1)) - fmax(ua, (float)ci);
            if (wu <= 0.0f) continue;
            acc += (wt * wu) * vload3(cj * sw + ci, src);
            wsum += wt * wu;
        }
    }
    vstore3(acc / wsum, j * dw + i, dst);
}

IBL_INLINE float3 output_dir(int idx, int size)
{
#if LAYOUT == 0
    const int w = 2 * size;
    return dir_from_equirect_uv((float2)(((float)(idx % w) + 0.5f) / w, ((float)(idx / w) + 0.5f) / size));
#elif LAYOUT == 1
    const int face = idx / (size * size), r = idx % (size * size);
    return dir_from_cube(face, ((float)(r % size) + 0.5f) / size, ((float)(r / size) + 0.5f) / size);
#else
    return dir_from_octahedral(((float)(idx % size) + 0.5f) / size, ((float)(idx / size) + 0.5f) / size);
#endif
}

/* samples[k] = (l_local.xyz, log2 of the sample's solid angle 1/(N pdf(l))), accepted (NoL > 0)
 * samples only, computed once per level on the host (iblbake/bake/prefilter.py: ggx_sample_set) from
 * Hammersley points: pdf(l) = D(h) NoH / (4 VoH) = D(h) / 4 with N = V.
 * Filtered importance sampling: a sample reads the chain at the level whose texel solid angle
 * matches its own, lod = 0.5 log2(Omega_s / Omega_texel(l)) + bias, Omega_texel being a level-0
 * texel's solid angle at the sample's latitude, (2 pi / W)(pi / H) sin(theta), floored at the
 * polar row's centre (equirect texels shrink towards the poles). A continuous density, not the
 * row-exact value: a level choice that jumps at row boundaries made float32 and float64 disagree.
 * The estimate is sum L(l) NoL / sum NoL (Karis 2013). */
__kernel void prefilter(CHAIN_PARAMS,
                        __global const float4 *samples, const int nsamples, const float lod_bias,
                        const int use_fis, const int size, const int ntexels, __global float4 *out)
{
    const int idx = get_global_id(0);
    if (idx >= ntexels) return;
    const float3 n = output_dir(idx, size);
    float3 t, b;
    tangent_frame(n, &t, &b);
    const int w0 = lw[0], h0 = lh[0];
    float3 acc = (float3)(0.0f);
    float wsum = 0.0f;
    for (int k = 0; k < nsamples; ++k) {
        const float4 s = samples[k];
        const float3 l = normalize(t * s.x + b * s.y + n * s.z);
        float lod = 0.0f;
        if (use_fis)
            lod = 0.5f * (s.w - log2(texel_solid_angle(l, w0, h0))) + lod_bias;
        acc += s.z * chain_lookup(CHAIN_ARGS, l, lod);
        wsum += s.z;
    }
    out[idx] = (float4)(acc / fmax(wsum, 1e-30f), 0.0f);
}

/* Mirror level (roughness 0): the source resampled to the layout (bilinear in level 0). */
__kernel void resample(CHAIN_PARAMS, const int size, const int ntexels,
                       __global float4 *out)
{
    const int idx = get_global_id(0);
    if (idx >= ntexels) return;
    out[idx] = (float4)(chain_lookup(CHAIN_ARGS, output_dir(idx, size), 0.0f), 0.0f);
}

/* DFG over NoV (x) and perceptual roughness (y), both on grids including 0 and 1:
 * NoV = max(x/(n-1), 1e-4), r = y/(n-1), alpha = r^2. With N = (0,0,1), V = (sqrt(1-NoV^2), 0, NoV),
 * h ~ D(h) NoH: the weight of a sample is G_vis = 4 V NoL VoH / NoH (Filament's GDFG * VoH / NoH):
 *   A = mean G_vis (1 - Fc), B = mean G_vis Fc, Fc = (1 - VoH)^5; specular = F0 A + F90 B.
 * MULTISCATTER stores (B, A + B) instead (Filament's layout for energy compensation). */
/* Texel (x, y) of an n x n table over NoV and roughness: NoV (>= 1e-4), alpha, and V. */
IBL_INLINE float3 table_view(int x, int y, int n, float *nov, float *alpha)
{
    *nov = fmax((float)x / (float)(n - 1), 1e-4f);
    const float r = (float)y / (float)(n - 1);
    *alpha = r * r;
    return (float3)(sqrt(1.0f - *nov * *nov), 0.0f, *nov);
}

__kernel void dfg(const int n, const int y0, const int nsamples, __global float2 *out)
{
    const int x = get_global_id(0), y = y0 + get_global_id(1);
    if (x >= n || y >= n) return;
    float nov, alpha;
    const float3 v = table_view(x, y, n, &nov, &alpha);
    float a = 0.0f, bsum = 0.0f;
    for (int k = 0; k < nsamples; ++k) {
        const float3 h = sample_ggx_half(hammersley((uint)k, (uint)nsamples), alpha);
        const float voh = dot(v, h);
        const float3 l = 2.0f * voh * h - v;
        const float nol = clamp(l.z, 0.0f, 1.0f), noh = clamp(h.z, 0.0f, 1.0f);
        if (nol > 0.0f && voh > 0.0f) {
            const float gv = 4.0f * v_smith_ggx_correlated(nov, nol, alpha) * nol * voh / noh;
            const float x1 = 1.0f - voh, x2 = x1 * x1;
            const float fc = x2 * x2 * x1;
            a += gv * (1.0f - fc);
            bsum += gv * fc;
        }
    }
    a /= (float)nsamples;
    bsum /= (float)nsamples;
    /* the exact A + B is <= 1 (energy); the quasi-Monte Carlo estimate can overshoot by ~1e-4 */
    const float e = a + bsum;
    if (e > 1.0f) { a /= e; bsum /= e; }
#ifdef MULTISCATTER
    out[y * n + x] = (float2)(bsum, a + bsum);
#else
    out[y * n + x] = (float2)(a, bsum);
#endif
}

/* Deterministic prefilter: with N = V = R the lobe weight D(h) NoL depends only on c = n.w, so a
 * level is the convolution sum_w L(w) D(h) c dOmega / sum_w D(h) c dOmega over the texels w of a
 * radiance-chain level fine enough for the lobe (chosen on the host), restricted to the cone
 * c > cos_cut outside which the weight is below a set fraction of its peak. Rows outside the
 * cone are skipped, and in each row only the azimuth interval the cone crosses is visited.
 * No sampling noise, no aliasing of small bright sources. */
__kernel void convolve(__global const float4 *level, const int w, const int h,
                       __global const float2 *col_sc, const int sub, const float alpha,
                       const float cos_cut, const int size, const int ntexels, __global float4 *out)
{
    const int idx = get_global_id(0);
    if (idx >= ntexels) return;
    const float3 n = output_dir(idx, size);
    const float gamma = acos(cos_cut);
    const float theta_n = acos(clamp(n.y, -1.0f, 1.0f));
    const float phi_n = atan2(n.x, n.z);
    const int j0 = max(0, (int)floor((theta_n - gamma) / IBL_PI * h));
    const int j1 = min(h - 1, (int)floor((theta_n + gamma) / IBL_PI * h));
    const float sin_gamma = sin(gamma);
    const int ws = w * sub, hs = h * sub;          /* the sub-texel grid: col_sc has ws entries */
    float3 acc = (float3)(0.0f);
    float wsum = 0.0f;
    for (int js = j0 * sub; js < (j1 + 1) * sub; ++js) {
        const float theta = IBL_PI * ((float)js + 0.5f) / hs;
        const float st = sin(theta), ct = cos(theta);
        const float d_omega = equirect_row_solid_angle(js, ws, hs);
        /* azimuth half-width of the cone on this row (the whole row near the poles) */
        int i0 = 0, i1 = ws - 1;
        const float st_min = fmin(sin(IBL_PI * (float)js / hs), sin(IBL_PI * (float)(js + 1) / hs));
        if (gamma < 0.5f * IBL_PI && sin_gamma < st_min) {
            const float half_width = asin(sin_gamma / st_min) + 2.0f * IBL_PI / ws;
            const float uc = 0.5f - phi_n * (0.5f / IBL_PI);
            i0 = (int)floor((uc - half_width * (0.5f / IBL_PI)) * ws - 0.5f);
            i1 = (int)ceil((uc + half_width * (0.5f / IBL_PI)) * ws - 0.5f);
            if (i1 - i0 >= ws) { i0 = 0; i1 = ws - 1; }
        }
        __global const float4 *row = level + (js / sub) * w;
        for (int ii = i0; ii <= i1; ++ii) {
            int i = ii % ws; if (i < 0) i += ws;
            const float2 sc = col_sc[i];
            const float c = n.x * st * sc.x + n.y * ct + n.z * st * sc.y;
            if (c > cos_cut) {
                const float wgt = d_ggx(sqrt(0.5f * (1.0f + c)), alpha) * c * d_omega;
                acc += wgt * row[i / sub].xyz;
                wsum += wgt;
            }
        }
    }
    out[idx] = (float4)(acc / fmax(wsum, 1e-30f), 0.0f);
}

/* Sheen albedo over NoV (x) and sheen roughness (y), the DFG grid: E = int D_charlie(h)
 * V_ashikhmin NoL dl with N = (0,0,1), V = (sqrt(1-NoV^2), 0, NoV), estimated as Filament's
 * DFV_Charlie_Uniform: h uniform on the hemisphere (pdf 1/(2 pi)) from Hammersley points, dl =
 * 4 VoH dh, so E = 8 pi mean(V D NoL VoH). The sheen counterpart of the DFG table's A + B
 * (KHR_materials_sheen's albedo scaling; the IBL's sheen term is its prefiltered radiance times E). */
__kernel void dfg_sheen(const int n, const int nsamples, __global float *out)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= n || y >= n) return;
    float nov, alpha;
    const float3 v = table_view(x, y, n, &nov, &alpha);
    float acc = 0.0f;
    for (int k = 0; k < nsamples; ++k) {
        const float2 u = hammersley((uint)k, (uint)nsamples);
        const float cz = u.x, sz = sqrt(fmax(0.0f, 1.0f - cz * cz)), phi = 2.0f * IBL_PI * u.y;
        const float3 h = (float3)(sz * cos(phi), sz * sin(phi), cz);
        const float voh = dot(v, h);
        const float nol = 2.0f * voh * h.z - v.z;
        if (nol > 0.0f && voh > 0.0f)
            acc += v_ashikhmin(nov, nol) * d_charlie(h.z, alpha) * nol * voh;
    }
    out[y * n + x] = acc * (8.0f * IBL_PI / (float)nsamples);
}
