/* Stochastic screen-space reflections (Stachowiak 2015, "Stochastic Screen-Space Reflections",
 * Frostbite; AMD FidelityFX SSSR): after the lighting passes, each pixel's first G-buffer sample of
 * roughness up to max_roughness sends GGX visible-normal rays (Heitz 2018) through a min-depth
 * pyramid of the whole frame (Hi-Z, Uludag 2014). A candidate hit is kept only where it is
 * plausible: the hit pixel's surface faces the ray, and the ray crosses that surface's own plane
 * within a pixel of it (a ray passing behind an object, or grazing its own sphere, crosses
 * the plane elsewhere: the march goes on). Each hit carries a confidence (the plane test's, the
 * screen edges' and the roughness fade's); a spatial resolve over neighbours on the same surface
 * (FidelityFX SSSR's, without its temporal part) removes the single ray's noise. Each sample then
 * replaces the reflected environment the shade pass added (ssr_env: its weight spec_occ (F0 A + B)
 * and the radiance it read, the probes' or the panorama's) by the confidence-weighted frame:
 *   radiance += W (H - C L_env), H = mean(conf L_hit), C = mean(conf) over the pixel's rays, resolved.
 * Where a ray's hit lies on a parallax reflection probe's proxy, the probe already holds that very
 * point (reflection_probes_hold): the hit's confidence gives way to it.
 * Everything the rays read is the whole frame's (ssr_pix, gathered from every tile before the
 * march), so a tiled frame gives the same pixels.
 *   ssr_gather   per tile pixel: its first sample's position and view depth, normal and roughness,
 *                lit radiance (of the samples on its plane) and object (ssr_pix, 3 float4 a pixel)
 *   ssr_depth    Hi-Z level 0 (+inf: nothing); ssr_reduce level k + 1: the min of each 2 x 2
 *   ssr_trace    per pixel: its rays, marched and validated, into (H, C) (ssr_hit)
 *   ssr_resolve  per pixel: the weighted mean of (H, C) over its neighbours (ssr_res)
 *   ssr          per sample of the tile: the replacement
 * Perspective cameras interpolate 1/z across the screen, orthographic ones z.
 * numpy twin: iblbake/render/twin/ssr.py. */
#include "common.h"
#include "brdf.h"
#include "sampling.h"
#include "sampler.h"
#include "surface.h"
#include "reflection_probes.h"

#define SSR_RESOLVE_RADIUS 3      /* pixels, at max_roughness; times sqrt(r / max_roughness) below
                                     (a glossy pixel's few rays need neighbours; a mirror: none) */

/* Continuous pixel coordinates (x right, y down; pixel centres at + 0.5) and view depth of x */
IBL_INLINE float3 ssr_project(__constant float4 *cam, int width, int height, float3 x)
{
    const float3 d = x - cam[0].xyz;
    const float z = dot(d, cam[1].xyz);
    const float3 r = cam[2].xyz, u = cam[3].xyz;
    float sx = dot(d, r) / dot(r, r), sy = dot(d, u) / dot(u, u);
    if (cam[0].w < 0.5f) { sx /= z; sy /= z; }
    return (float3)(0.5f * (sx + 1.0f) * (float)width, 0.5f * (1.0f - sy) * (float)height, z);
}

__kernel void ssr_gather(__global const float4 *gb_pos, SURFACE_PARAMS, __constant float4 *cam, const int width,
                         const int height, const int spp, const int npix, const int pixel0,
                         __global const float4 *radiance, __global float4 *ssr_pix)
{
    const int i = get_global_id(0);
    if (i >= npix) return;
    const int gid = i * spp, px = pixel0 + i;
    const float4 p = gb_pos[gid];
    if (p.w == MISS_T) {
        ssr_pix[3 * px] = (float4)(0.0f, 0.0f, 0.0f, INFINITY);
        ssr_pix[3 * px + 1] = (float4)(0.0f, 0.0f, 1.0f, 2.0f);
        ssr_pix[3 * px + 2] = (float4)(0.0f, 0.0f, 0.0f, as_float(-1));
        return;
    }
    Material mt;
    float3 v, nrm;
    surface_at(SURFACE_ARGS, gid, &mt, &v, &nrm);
    ssr_pix[3 * px] = (float4)(p.xyz, ssr_project(cam, width, height, p.xyz).z);
    ssr_pix[3 * px + 1] = (float4)(nrm, mt.roughness);
    /* the lit radiance: the mean over the pixel's samples on the first one's plane (ssr's test) */
    float3 sum = (float3)(0.0f);
    int k = 0;
    const float z = ssr_pix[3 * px].w;
    for (int j = 0; j < spp; ++j) {
        const float4 q = gb_pos[gid + j];
        if (q.w == MISS_T || !(fabs(dot(q.xyz - p.xyz, nrm)) <= 0.02f * z)) continue;
        sum += radiance[gid + j].xyz;
        ++k;
    }
    ssr_pix[3 * px + 2] = (float4)(sum / (float)k, gb_dir[gid].w);     /* w: the object's index's bits */
}

__kernel void ssr_depth(__global const float4 *ssr_pix, const int npix, __global float *ssr_hiz)
{
    const int i = get_global_id(0);
    if (i >= npix) return;
    ssr_hiz[i] = ssr_pix[3 * i].w;
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
IBL_INLINE float ssr_depth_at(float z0, float z1, float t, int ortho)
{
    return ortho ? mix(z0, z1, t) : 1.0f / mix(1.0f / z0, 1.0f / z1, t);
}

/* How plausible a hit on pixel c is for the ray p0 + t l: 0 where the pixel's surface faces away
 * from the ray, else by how far from the pixel's centre the ray crosses that surface's plane:
 * 1 within a pixel, falling to 0 at two. */
IBL_INLINE float ssr_plausible(__global const float4 *ssr_pix, __constant float4 *cam, int width, int height, int c,
                           float3 p0, float3 l, float3 *x)
{
    const float3 s = ssr_pix[3 * c].xyz, nc = ssr_pix[3 * c + 1].xyz;
    const float den = dot(l, nc);
    if (!(den < 0.0f)) return 0.0f;
    const float t = dot(s - p0, nc) / den;
    if (!(t > 0.0f)) return 0.0f;
    *x = p0 + t * l;                                   /* where the ray meets that plane */
    const float3 q = ssr_project(cam, width, height, *x);
    const float2 d = q.xy - (float2)((float)(c % width) + 0.5f, (float)(c / width) + 0.5f);
    return clamp(2.0f - length(d), 0.0f, 1.0f);
}

/* How far the depth buffer's surface at pixel c spans in depth across a pixel: the largest step to
 * a neighbour (a floor seen at a grazing angle changes depth faster than any one thickness) */
IBL_INLINE float ssr_depth_extent(__global const float *ssr_hiz, int c, int width, int height)
{
    const float z = ssr_hiz[c];
    const int x = c % width, y = c / width;
    float e = 0.0f;
    if (x > 0 && isfinite(ssr_hiz[c - 1])) e = fmax(e, fabs(ssr_hiz[c - 1] - z));
    if (x + 1 < width && isfinite(ssr_hiz[c + 1])) e = fmax(e, fabs(ssr_hiz[c + 1] - z));
    if (y > 0 && isfinite(ssr_hiz[c - width])) e = fmax(e, fabs(ssr_hiz[c - width] - z));
    if (y + 1 < height && isfinite(ssr_hiz[c + width])) e = fmax(e, fabs(ssr_hiz[c + width] - z));
    return e;
}

/* March one ray p0 + t l (its screen segment s0 -> s1, depths z0, z1): the hit pixel, or -1; its
 * plausibility in *conf, where the ray meets the hit surface's plane in *x. A candidate (the depth
 * buffer's surface in front of the ray's depths across the pixel by at most `thickness` plus the
 * surface's own depth extent there) that is not plausible is passed by. */
IBL_INLINE int ssr_march(float2 s0, float z0, float2 s1, float z1, int ortho, __global const float *ssr_hiz,
                     __global const int *hiz_off, const int nlev, const int width, const int height, const int steps,
                     const float thickness, __global const float4 *ssr_pix, __constant float4 *cam, float3 p0,
                     float3 l, float *conf, float3 *x)
{
    const float2 ds = s1 - s0;
    /* steps past a cell's edge by a hundredth of a pixel (in t: a segment to a point near the eye
     * plane spans thousands of pixels, where a fixed step in t would jump over thin crossings) */
    const float eps = 0.01f / fmax(length(ds), 1e-6f);
    int level = 0;
    float t = 0.0f;
    *conf = 0.0f;
    /* leave the start pixel first */
    {
        const float2 cell = floor(s0);
        const float2 edge = cell + select((float2)(0.0f), (float2)(1.0f), isgreater(ds, (float2)(0.0f)));
        const float2 tt = (edge - s0) / ds;
        t = fmin(fmin(isnan(tt.x) ? INFINITY : tt.x, isnan(tt.y) ? INFINITY : tt.y), 1.0f) + eps;
    }
    for (int i = 0; i < steps && t < 1.0f; ++i) {
        const float2 s = s0 + t * ds;
        if (s.x < 0.0f || s.y < 0.0f || s.x >= (float)width || s.y >= (float)height) return -1;
        const int size = 1 << level;
        const int lw = (width + size - 1) >> level, lh = (height + size - 1) >> level;
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
            t = t_exit + eps;
            level = min(level + 1, nlev - 1);
        } else if (level > 0) {
            --level;                            /* look closer */
        } else {
            if (fmin(za, zb) <= cell_min + thickness + ssr_depth_extent(ssr_hiz, cy * width + cx, width, height)) {
                const float c = ssr_plausible(ssr_pix, cam, width, height, cy * width + cx, p0, l, x);
                if (c > 0.0f) {
                    *conf = c;
                    return cy * width + cx;
                }
            }
            t = t_exit + eps;
        }
    }
    return -1;
}

/* Rays of a pixel of roughness r: `rays` at max_roughness, fewer below (a mirror: one) */
IBL_INLINE int ssr_ray_count(float r, float max_roughness, int rays)
{
    return max(1, (int)ceil((float)rays * r / fmax(max_roughness, 1e-6f)));
}

__kernel void ssr_trace(__global const float4 *ssr_pix, __constant float4 *cam, const int width, const int height,
                        __global const float *ssr_hiz, __global const int *hiz_off, const int nlev,
                        __global float4 *ssr_hit, const float max_roughness, const float thickness, const int steps,
                        const int rays, const float ray_length, const uint seed, __global const float4 *rp_info,
                        const int rp_count, __global const uint *rp_excl, const int defer_to_probes)
{
    const int px = get_global_id(0);
    if (px >= width * height) return;
    ssr_hit[px] = (float4)(0.0f);
    const float4 pz = ssr_pix[3 * px], nr = ssr_pix[3 * px + 1];
    if (!isfinite(pz.w) || nr.w > max_roughness) return;
    const int ortho = cam[0].w > 0.5f;
    const float3 p = pz.xyz, nrm = nr.xyz;
    const float3 v = ortho ? -cam[1].xyz : normalize(cam[0].xyz - p);
    const float nov = fmax(dot(nrm, v), 1e-4f), alpha = nr.w * nr.w;
    float3 t, b;
    tangent_frame(nrm, &t, &b);
    const float3 vl = (float3)(dot(v, t), dot(v, b), nov);
    /* fades: towards max_roughness (its last fifth) and within 5% of the screen's edges */
    const float fade_r = clamp((max_roughness - nr.w) / (0.2f * max_roughness), 0.0f, 1.0f);
    const int count = ssr_ray_count(nr.w, max_roughness, rays);
#ifdef HAS_REFLECTION_PROBES
    const int obj = as_int(ssr_pix[3 * px + 2].w);
    const uint own = obj >= 0 ? rprobe_own(p, rp_excl[obj], rp_info, rp_count) : 0u;
#endif
    float3 sum = (float3)(0.0f);
    float csum = 0.0f;
    for (int k = 0; k < count; ++k) {
        Sampler sp = sampler_start(seed, (uint)px, (uint)k);
        const float2 u = sampler_2d(&sp);
        float3 h;
        float noh;
        const float3 l = alpha < DELTA_ALPHA ? 2.0f * dot(v, nrm) * nrm - v
                                             : reflect_ggx_vndf(u, t, b, nrm, v, vl, alpha, &h, &noh);
        if (!(dot(nrm, l) > 0.0f)) continue;                 /* below the horizon: the environment */
        /* the offset in proportion to the distance and to p's own float precision: no scene unit */
        const float3 p0 = p + nrm * (1e-4f * (length(p) + length(p - cam[0].xyz)));
        float len = ray_length;
        const float dz = dot(l, cam[1].xyz);
        const float z0 = dot(p0 - cam[0].xyz, cam[1].xyz);
        if (!ortho && dz < 0.0f) len = fmin(len, 0.99f * z0 / -dz);   /* stay before the eye */
        const float3 a = ssr_project(cam, width, height, p0), c = ssr_project(cam, width, height, p0 + len * l);
        float conf;
        float3 x;
        const int hit = ssr_march(a.xy, a.z, c.xy, c.z, ortho, ssr_hiz, hiz_off, nlev, width, height, steps, thickness,
                                  ssr_pix, cam, p0, l, &conf, &x);
        if (hit < 0) continue;
        const float ex = ((float)(hit % width) + 0.5f) / (float)width;
        const float ey = ((float)(hit / width) + 0.5f) / (float)height;
        const float fade_e = clamp(fmin(fmin(ex, 1.0f - ex), fmin(ey, 1.0f - ey)) / 0.05f, 0.0f, 1.0f);
        float f = conf * fade_r * fade_e;
#ifdef HAS_REFLECTION_PROBES
        if (defer_to_probes) f *= 1.0f - reflection_probes_hold(p0, l, x, alpha, own, rp_info, rp_count);
#endif
        sum += f * ssr_pix[3 * hit + 2].xyz;
        csum += f;
    }
    ssr_hit[px] = (float4)(sum / (float)count, csum / (float)count);
}

/* A neighbour's weight in the resolve: a Gaussian in pixels, the same surface (normals within a
 * few degrees, depth within 2% along the view, roughness within 0.1) */
IBL_INLINE float ssr_neighbour(float4 pz, float4 nr, float4 qz, float4 qr, float d2, float sigma2)
{
    if (!isfinite(qz.w)) return 0.0f;
    const float cn = dot(nr.xyz, qr.xyz);
    if (cn < 0.95f) return 0.0f;
    const float dz = fabs(qz.w - pz.w) / (0.02f * pz.w), dr = fabs(qr.w - nr.w) / 0.1f;
    return exp(-0.5f * d2 / sigma2) * exp(-dz * dz) * exp(-dr * dr) * pown(cn, 16);
}

__kernel void ssr_resolve(__global const float4 *ssr_pix, __global const float4 *ssr_hit, const int width,
                          const int height, const float max_roughness, __global float4 *ssr_res)
{
    const int px = get_global_id(0);
    if (px >= width * height) return;
    const float4 pz = ssr_pix[3 * px], nr = ssr_pix[3 * px + 1];
    if (!isfinite(pz.w) || nr.w > max_roughness) { ssr_res[px] = (float4)(0.0f); return; }
    const int radius = (int)ceil((float)SSR_RESOLVE_RADIUS * sqrt(fmin(nr.w / fmax(max_roughness, 1e-6f), 1.0f)));
    const float sigma2 = fmax(0.25f * (float)(radius * radius), 0.25f);
    const int x = px % width, y = px / width;
    float4 acc = (float4)(0.0f);
    float wsum = 0.0f;
    for (int dy = -radius; dy <= radius; ++dy)
        for (int dx = -radius; dx <= radius; ++dx) {
            const int qx = x + dx, qy = y + dy;
            if (qx < 0 || qy < 0 || qx >= width || qy >= height) continue;
            const int q = qy * width + qx;
            const float w = q == px ? 1.0f : ssr_neighbour(pz, nr, ssr_pix[3 * q], ssr_pix[3 * q + 1],
                                                           (float)(dx * dx + dy * dy), sigma2);
            acc += w * ssr_hit[q];
            wsum += w;
        }
    ssr_res[px] = acc / wsum;
}

/* A sample takes its pixel's resolved reflection where it lies on the pixel's first sample's
 * surface: within 2% of its view depth of that sample's tangent plane (not of the point: a floor
 * seen at a grazing angle spans more depth across one pixel, and its other samples kept the
 * environment at spp > 1). An edge pixel's other surface keeps its environment. */
__kernel void ssr(__global const float4 *gb_pos, const int spp, const int n, const int pixel0,
                  __global const float4 *ssr_pix, __global const float4 *ssr_env, __global const float4 *ssr_res,
                  __global float4 *radiance)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    const float4 p = gb_pos[gid];
    if (p.w == MISS_T) return;
    const float3 w = ssr_env[2 * gid].xyz, li = ssr_env[2 * gid + 1].xyz;
    if (!(w.x > 0.0f || w.y > 0.0f || w.z > 0.0f)) return;
    const int px = pixel0 + gid / spp;
    const float4 first = ssr_pix[3 * px];
    if (!(fabs(dot(p.xyz - first.xyz, ssr_pix[3 * px + 1].xyz)) <= 0.02f * first.w)) return;
    const float4 r = ssr_res[px];
    radiance[gid] += (float4)(w * (r.xyz - r.w * li), 0.0f);
}
