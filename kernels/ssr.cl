/* Stochastic screen-space reflections (Stachowiak 2015, "Stochastic Screen-Space Reflections",
 * Frostbite; AMD FidelityFX SSSR): after the lighting passes, each G-buffer sample of roughness up
 * to max_roughness sends `rays` GGX visible-normal rays (Heitz 2018) through a min-depth pyramid
 * of the frame (Hi-Z, Uludag 2014); where a ray meets the depth buffer within `thickness` behind
 * it, the frame's own radiance there replaces the reflected environment the shade pass added
 * (its split sum's, probes included)
 * (ssr_env: its weight spec_occ (F0 A + B) and the radiance it read), faded out towards
 * max_roughness and the screen's edges. Rays that leave the screen (or the tile), pass behind
 * everything or go below the horizon keep the environment.
 *   ssr_depth   level 0: each pixel's view depth (its first G-buffer sample; +inf: nothing)
 *   ssr_reduce  level k + 1 from level k: the min of each 2 x 2 (a missing texel: +inf)
 *   ssr         the march and the replacement, radiance from ssr_src (the lit frame's copy)
 * Perspective cameras interpolate 1/z across the screen, orthographic ones z.
 * numpy twin: iblbake/render/twin/ssr.py. */
#include "common.h"
#include "brdf.h"
#include "sampling.h"
#include "sampler.h"
#include "surface.h"

/* Continuous pixel coordinates (x right, y down; pixel centres at + 0.5) and view depth of x */
inline float3 ssr_project(__constant float4 *cam, int width, int height, float3 x)
{
    const float3 d = x - cam[0].xyz;
    const float z = dot(d, cam[1].xyz);
    const float3 r = cam[2].xyz, u = cam[3].xyz;
    float sx = dot(d, r) / dot(r, r), sy = dot(d, u) / dot(u, u);
    if (cam[0].w < 0.5f) { sx /= z; sy /= z; }
    return (float3)(0.5f * (sx + 1.0f) * (float)width, 0.5f * (1.0f - sy) * (float)height, z);
}

__kernel void ssr_depth(__global const float4 *gb_pos, __constant float4 *cam, const int width, const int height,
                        const int spp, const int npix, const int pixel0, __global float *ssr_hiz)
{
    const int i = get_global_id(0);
    if (i >= npix) return;
    const float4 p = gb_pos[i * spp];
    ssr_hiz[i] = p.w == MISS_T ? INFINITY : ssr_project(cam, width, height, p.xyz).z;
}

__kernel void ssr_reduce(__global float *ssr_hiz, const int src, const int sw, const int sh, const int dst,
                         const int dw, const int dh)
{
    const int i = get_global_id(0);
    if (i >= dw * dh) return;
    const int x = 2 * (i % dw), y = 2 * (i / dw);
    float m = ssr_hiz[src + y * sw + x];
    if (x + 1 < sw) m = fmin(m, ssr_hiz[src + y * sw + x + 1]);
    if (y + 1 < sh) m = fmin(m, ssr_hiz[src + (y + 1) * sw + x]);
    if (x + 1 < sw && y + 1 < sh) m = fmin(m, ssr_hiz[src + (y + 1) * sw + x + 1]);
    ssr_hiz[dst + i] = m;
}

/* The depth along the screen segment s0 -> s1 at parameter t */
inline float ssr_depth_at(float z0, float z1, float t, int ortho)
{
    return ortho ? mix(z0, z1, t) : 1.0f / mix(1.0f / z0, 1.0f / z1, t);
}

/* March one ray: the hit pixel (tile-local index), or -1. s0, s1 in tile-local pixels. */
inline int ssr_march(float2 s0, float z0, float2 s1, float z1, int ortho, __global const float *ssr_hiz,
                     __global const int *hiz_off, const int nlev, const int width, const int rows, const int steps,
                     const float thickness)
{
    const float2 ds = s1 - s0;
    int level = 0;
    float t = 0.0f;
    /* leave the start pixel first */
    {
        const float2 cell = floor(s0);
        const float2 edge = cell + select((float2)(0.0f), (float2)(1.0f), isgreater(ds, (float2)(0.0f)));
        const float2 tt = (edge - s0) / ds;
        t = fmin(fmin(isnan(tt.x) ? INFINITY : tt.x, isnan(tt.y) ? INFINITY : tt.y), 1.0f) + 1e-4f;
    }
    for (int i = 0; i < steps && t < 1.0f; ++i) {
        const float2 s = s0 + t * ds;
        if (s.x < 0.0f || s.y < 0.0f || s.x >= (float)width || s.y >= (float)rows) return -1;
        const int size = 1 << level;
        const int lw = (width + size - 1) >> level, lh = (rows + size - 1) >> level;
        const int cx = min((int)s.x >> level, lw - 1), cy = min((int)s.y >> level, lh - 1);
        /* where the ray leaves this cell */
        const float2 edge = (float2)((float)((cx + (ds.x > 0.0f ? 1 : 0)) * size),
                                     (float)((cy + (ds.y > 0.0f ? 1 : 0)) * size));
        const float2 tt = (edge - s0) / ds;
        const float t_exit = fmin(fmin(isnan(tt.x) || tt.x <= t ? INFINITY : tt.x,
                                       isnan(tt.y) || tt.y <= t ? INFINITY : tt.y), 1.0f);
        const float za = ssr_depth_at(z0, z1, t, ortho), zb = ssr_depth_at(z0, z1, t_exit, ortho);
        const float cell_min = ssr_hiz[hiz_off[level] + cy * lw + cx];
        if (fmax(za, zb) < cell_min) {          /* in front of everything in the cell: skip it */
            t = t_exit + 1e-4f;
            level = min(level + 1, nlev - 1);
        } else if (level > 0) {
            --level;                            /* look closer */
        } else {
            /* the depth buffer's surface here lies between the ray's depths across the pixel:
             * a hit unless the ray passes more than `thickness` behind it */
            if (fmin(za, zb) <= cell_min + thickness) return cy * width + cx;
            t = t_exit + 1e-4f;
        }
    }
    return -1;
}

__kernel void ssr(__global const float4 *gb_pos, SURFACE_PARAMS, __constant float4 *cam, const int width,
                  const int height, const int spp, const int n, const int pixel0, const int npix,
                  __global const float *ssr_hiz, __global const int *hiz_off, const int nlev,
                  __global const float4 *ssr_env, __global const float4 *ssr_src, __global float4 *radiance,
                  const float max_roughness, const float thickness, const int steps, const int rays,
                  const float ray_length, const uint seed)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    const float4 hitp = gb_pos[gid];
    radiance[gid] = ssr_src[gid];
    if (hitp.w == MISS_T) return;
    Material mt;
    float3 v, nrm;
    const float nov = surface_at(SURFACE_ARGS, gid, &mt, &v, &nrm);
    if (mt.roughness > max_roughness) return;
    const float3 w = ssr_env[2 * gid].xyz, li = ssr_env[2 * gid + 1].xyz;
    if (!(w.x > 0.0f || w.y > 0.0f || w.z > 0.0f)) return;
    const int rows = npix / width, row0 = pixel0 / width, ortho = cam[0].w > 0.5f;
    float3 t, b;
    tangent_frame(nrm, &t, &b);
    const float3 vl = (float3)(dot(v, t), dot(v, b), nov);
    /* fades: towards max_roughness (its last fifth) and within 5% of the screen's edges */
    const float fade_r = clamp((max_roughness - mt.roughness) / (0.2f * max_roughness), 0.0f, 1.0f);
    float3 sum = (float3)(0.0f);
    for (int k = 0; k < rays; ++k) {
        Sampler sp = sampler_start(seed, (uint)(pixel0 * spp + gid), (uint)k);
        const float2 u = sampler_2d(&sp);
        const float3 hl = mt.alpha < DELTA_ALPHA ? (float3)(0.0f, 0.0f, 1.0f) : sample_ggx_vndf(vl, mt.alpha, u);
        const float3 h = t * hl.x + b * hl.y + nrm * hl.z;
        const float3 l = 2.0f * dot(v, h) * h - v;
        float3 got = li;
        if (dot(nrm, l) > 0.0f) {
            const float3 p0 = hitp.xyz + nrm * (1e-4f * (1.0f + hitp.w));
            float len = ray_length;
            const float dz = dot(l, cam[1].xyz);
            const float z0 = dot(p0 - cam[0].xyz, cam[1].xyz);
            if (!ortho && dz < 0.0f) len = fmin(len, 0.99f * (z0 - 1e-3f) / -dz);   /* stay before the eye */
            const float3 a = ssr_project(cam, width, height, p0), c = ssr_project(cam, width, height, p0 + len * l);
            const int hit = ssr_march((float2)(a.x, a.y - (float)row0), a.z, (float2)(c.x, c.y - (float)row0), c.z,
                                      ortho, ssr_hiz, hiz_off, nlev, width, rows, steps, thickness);
            if (hit >= 0) {
                const float ex = ((float)(hit % width) + 0.5f) / (float)width;
                const float ey = ((float)(hit / width + row0) + 0.5f) / (float)height;
                const float fade_e = clamp(fmin(fmin(ex, 1.0f - ex), fmin(ey, 1.0f - ey)) / 0.05f, 0.0f, 1.0f);
                const float f = fade_r * fade_e;
                got = mix(li, ssr_src[hit * spp].xyz, f);
            }
        }
        sum += got;
    }
    radiance[gid] = ssr_src[gid] + (float4)(w * (sum / (float)rays - li), 0.0f);
}
