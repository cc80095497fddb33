/* Ground-truth-based ambient occlusion (effects.ao: gtao): Jimenez, Wu, Pesce and Jarabo,
 * "Practical Real-Time Strategies for Accurate Indirect Occlusion" (2016), in the form of Intel's
 * XeGTAO (the falloff, the noise-shifted slices and steps, the final power). A screen-space pass:
 * per pixel of the frame (or of every 2x2 block at resolution half), `slices` half-planes through the view vector, each searched for its two
 * horizons in `steps` depth-buffer samples per side within ao_radius (scaled by radius_scale),
 * and the cosine-weighted visible arc between them integrated in closed form (the paper's eq. 10).
 * The depth buffer is the G-buffer's first sample of every pixel (stride spp) or, when the frame
 * renders in tiles, a full-frame pass of the G-buffer kernel. gtao_denoise then gives every
 * G-buffer sample the mean of the raw values of its pixel's neighbours on the same surface.
 * A depth sample m >= 16 pixels out along its larger axis reads pixel (x, y) snapped down to a
 * multiple of 2^k, k = floor(log2 m) - 3 (at most GTAO_LEVELS): level k of gtao_levels holds
 * every such pixel's position in (w >> k) x (h >> k) texels, so the far samples of a large
 * radius (hundreds of pixels) read a small array that stays in the caches, as XeGTAO's depth
 * MIPs do, while each still reads a real surface point (no average across an edge).
 * numpy twin: iblbake/render/twin/gtao.py. */
#include "common.h"
#include "layout.h"
#include "surface.h"

/* GTAO_LEVELS (the pyramid's levels beyond the full frame) comes from the host:
 * iblbake/render/passes/ao.py GTAO_LEVELS, which the twin reads too */

IBL_INLINE float fract1(float x) { return x - floor(x); }

/* texels of the levels before level k (k >= 1) in gtao_levels */
IBL_INLINE int level_offset(int k, int width, int height)
{
    int off = 0;
    for (int j = 1; j < k; ++j) off += ((width + (1 << j) - 1) >> j) * ((height + (1 << j) - 1) >> j);
    return off;
}

/* One texel of every level 1..GTAO_LEVELS: the position (and miss flag) of pixel (i 2^k, j 2^k) */
__kernel void gtao_pyramid(__global const float4 *ao_pos, const int ao_stride, const int width, const int height,
                           __global float4 *gtao_levels)
{
    int gid = get_global_id(0);
    for (int k = 1; k <= GTAO_LEVELS; ++k) {
        const int wk = (width + (1 << k) - 1) >> k, hk = (height + (1 << k) - 1) >> k;
        if (gid < wk * hk) {
            const int i = gid % wk, j = gid / wk;
            gtao_levels[level_offset(k, width, height) + gid] = ao_pos[((j << k) * width + (i << k)) * ao_stride];
            return;
        }
        gid -= wk * hk;
    }
}

/* interleaved gradient noise (Jimenez 2014): its 3x3 neighbourhoods hold well-spread values, so
 * the 3x3 denoise sees as many slice rotations */
IBL_INLINE float gtao_noise(int x, int y)
{
    return fract1(52.9829189f * fract1(0.06711056f * (float)x + 0.00583715f * (float)y));
}

/* world units one pixel spans at p: the camera's half-width over half the pixels, times the
 * depth for a pinhole camera */
IBL_INLINE float pixel_footprint(__constant float4 *cam, int width, float3 p)
{
    const float s = 2.0f * length(cam[2].xyz) / (float)width;
    return cam[0].w > 0.5f ? s : s * dot(p - cam[0].xyz, cam[1].xyz);
}

/* acos to 7e-5 rad (Abramowitz and Stegun 4.4.45): the search's only inverse trigonometry */
IBL_INLINE float acos_fast(float x)
{
    const float a = fabs(x);
    const float r = sqrt(fmax(1.0f - a, 0.0f)) * (1.5707288f + a * (-0.2121144f + a * (0.0742610f - 0.0187293f * a)));
    return x >= 0.0f ? r : IBL_PI - r;
}

/* The paper's inner integral of one side of a slice, cos(h - n) |sin h| over [0, h] (eq. 7 and
 * 10), with the angles written through their cosines: h = acos(ch) on the side of sign sh (+1 or
 * -1), n given by (cos, sin). cos(2h - n) = cos 2h cos n + sin 2h sin n. */
IBL_INLINE float gtao_arc(float ch, float sh, float cos_n, float sin_n, float ang_n)
{
    const float h = sh * acos_fast(ch);
    const float sin_h = sh * sqrt(fmax(1.0f - ch * ch, 0.0f));
    const float cos_2h_n = (2.0f * ch * ch - 1.0f) * cos_n + 2.0f * ch * sin_h * sin_n;
    return 0.25f * (cos_n + 2.0f * h * sin_n - cos_2h_n);
}

/* One depth sample of a side, read at level k: its horizon cosine pulled towards `low` as its
 * distance leaves the radius; off screen and background samples leave the horizon where it is. */
IBL_INLINE float horizon(__global const float4 *ao_pos, int stride, __global const float4 *levels, int k,
                     int width, int height, int qx, int qy, float3 p, float3 v, float low, float fall_mul,
                     float fall_add, float hc)
{
    if (qx < 0 || qy < 0 || qx >= width || qy >= height) return hc;
    const float4 q = k == 0 ? ao_pos[(qy * width + qx) * stride]
                            : levels[level_offset(k, width, height) + (qy >> k) * ((width + (1 << k) - 1) >> k) + (qx >> k)];
    const float3 d = q.xyz - p;
    const float dd = dot(d, d);
    if (q.w == MISS_T || dd <= 0.0f) return hc;
    const float inv = rsqrt(dd);
    return fmax(hc, mix(low, dot(d, v) * inv, clamp(dd * inv * fall_mul + fall_add, 0.0f, 1.0f)));
}

__kernel void gtao(__constant float4 *cam, const int width, const int height,
                   __global const float4 *ao_pos, __global const float4 *ao_nrm, __global const float4 *ao_dir,
                   const int ao_stride, const float ao_radius, const int gtao_slices, const int gtao_steps,
                   const float gtao_radius_scale, const float gtao_falloff, const float gtao_power,
                   const int gtao_step, __global const float4 *gtao_levels, __global float *gtao_raw)
{
    /* one value per gtao_step x gtao_step block of pixels, at the block's first pixel */
    const int gid = get_global_id(0);
    const int wl = (width + gtao_step - 1) / gtao_step, hl = (height + gtao_step - 1) / gtao_step;
    if (gid >= wl * hl) return;
    const int x = (gid % wl) * gtao_step, y = (gid / wl) * gtao_step;
    const int pix = y * width + x;
    const float4 hp = ao_pos[pix * ao_stride];
    if (hp.w == MISS_T) { gtao_raw[gid] = 1.0f; return; }
    const float3 p = hp.xyz;
    const float3 v = -ao_dir[pix * ao_stride].xyz;
    const float3 nrm = facing_normal(ao_nrm[pix * ao_stride].xyz, v);
    const float radius = ao_radius * gtao_radius_scale;
    const float radius_px = radius / pixel_footprint(cam, width, p);
    if (radius_px < 1.0f) { gtao_raw[gid] = 1.0f; return; }      /* nothing to find within a pixel */
    /* samples count fully out to (1 - falloff) radius, fading to none at the radius */
    const float fall_mul = -1.0f / (gtao_falloff * radius), fall_add = (1.0f - gtao_falloff) / gtao_falloff + 1.0f;
    const float3 right = normalize(cam[2].xyz), up = normalize(cam[3].xyz);
    const float min_s = 1.0f / radius_px;                          /* the first sample leaves the pixel */
    /* noise over the blocks, so the denoise's neighbours hold different slices */
    const int bx = gid % wl, by = gid / wl;
    const float noise_slice = gtao_noise(bx, by), noise_step = gtao_noise(by + 17, bx + 31);
    /* slice k at angle (k + noise) pi / slices: the first by sincos, the rest by rotation */
    const float dphi = IBL_PI / (float)gtao_slices;
    float c = cos(noise_slice * dphi), s = sin(noise_slice * dphi);
    const float cd = cos(dphi), sd = sin(dphi);
    float vis = 0.0f;
    for (int sl = 0; sl < gtao_slices; ++sl) {
        /* the slice: the plane through v holding the screen direction (c, s) (image y is down) */
        const float3 dir = c * right + s * up;
        const float3 odir = dir - dot(dir, v) * v;
        const float3 axis = normalize(cross(odir, v));
        const float3 pn = nrm - axis * dot(nrm, axis);             /* the normal projected into the slice */
        const float pn_len = length(pn);
        const float cos_n = clamp(dot(pn, v) / pn_len, 0.0f, 1.0f);
        const float sgn = dot(odir, pn) >= 0.0f ? 1.0f : -1.0f;
        const float sin_n = sgn * sqrt(1.0f - cos_n * cos_n), ang_n = sgn * acos_fast(cos_n);
        /* the horizons start at the normal's hemisphere: cos(n + pi/2) and cos(n - pi/2) */
        const float low0 = -sin_n, low1 = sin_n;
        float hc0 = low0, hc1 = low1;
        for (int st = 0; st < gtao_steps; ++st) {
            const float jit = fract1(noise_step + (float)(sl + st * gtao_slices) * 0.6180339887f);
            float t = ((float)st + jit) / (float)gtao_steps;
            t = t * t + min_s;                                     /* denser near the centre */
            const int ox = (int)round(t * c * radius_px), oy = (int)round(-t * s * radius_px);
            const int m = max(abs(ox), abs(oy));
            const int k = m < 16 ? 0 : min((31 - (int)clz(m)) - 3, GTAO_LEVELS);
            hc0 = horizon(ao_pos, ao_stride, gtao_levels, k, width, height, x + ox, y + oy, p, v, low0, fall_mul,
                          fall_add, hc0);
            hc1 = horizon(ao_pos, ao_stride, gtao_levels, k, width, height, x - ox, y - oy, p, v, low1, fall_mul,
                          fall_add, hc1);
        }
        /* h1 = acos(hc0) >= 0 and h0 = -acos(hc1) <= 0 stay within n -+ pi/2 (each starts there
         * and only rises): no clamp */
        vis += pn_len * (gtao_arc(clamp(hc1, -1.0f, 1.0f), -1.0f, cos_n, sin_n, ang_n) +
                         gtao_arc(clamp(hc0, -1.0f, 1.0f), 1.0f, cos_n, sin_n, ang_n));
        const float cn = c * cd - s * sd;
        s = s * cd + c * sd;
        c = cn;
    }
    /* unclamped: a slice's arc is cos n + n sin n >= 1 on open ground, and only the mean over
     * slices is 1; clamping each pixel before the denoise would darken open ground by 4% */
    gtao_raw[gid] = vis / (float)gtao_slices;
}

/* Per G-buffer sample of the tile: the mean raw value of the (2r+1)^2 blocks around its pixel's
 * whose first pixels lie on its surface (normals within 37 degrees, within 3 pixel footprints
 * per block step of its tangent plane): neighbouring blocks differ by their noise, so the mean
 * sees all their slices, and at gtao_step 2 it is the edge-aware upsampling too. The mean,
 * clamped to [0, 1], is raised to gtao_power (XeGTAO's final power) only then. */
__kernel void gtao_denoise(__constant float4 *cam, const int width, const int height,
                           __global const float4 *gb_pos, __global const float4 *gb_nrm, __global const float4 *gb_dir,
                           const int n, const int pixel0, const int spp,
                           __global const float4 *ao_pos, __global const float4 *ao_nrm, const int ao_stride,
                           __global const float *gtao_raw, const int gtao_denoise_radius, const int gtao_step,
                           const float gtao_power, __global float *ao_buf)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    const float4 hp = gb_pos[gid];
    if (hp.w == MISS_T) { ao_buf[gid] = 1.0f; return; }
    const int pix = pixel0 + gid / spp, bx = (pix % width) / gtao_step, by = (pix / width) / gtao_step;
    const int wl = (width + gtao_step - 1) / gtao_step, hl = (height + gtao_step - 1) / gtao_step;
    const float3 v = -gb_dir[gid].xyz;
    const float3 nrm = facing_normal(gb_nrm[gid].xyz, v);
    const float tau = 3.0f * (float)gtao_step * pixel_footprint(cam, width, hp.xyz);
    const int r = gtao_denoise_radius;
    float sum = 0.0f, wsum = 0.0f;
    for (int dy = -r; dy <= r; ++dy) {
        for (int dx = -r; dx <= r; ++dx) {
            const int qx = bx + dx, qy = by + dy;
            if (qx < 0 || qy < 0 || qx >= wl || qy >= hl) continue;
            const int q = qy * gtao_step * width + qx * gtao_step;
            const float4 qp = ao_pos[q * ao_stride];
            if (qp.w == MISS_T) continue;
            if (dot(ao_nrm[q * ao_stride].xyz, nrm) < 0.8f || fabs(dot(qp.xyz - hp.xyz, nrm)) > tau) continue;
            sum += gtao_raw[qy * wl + qx];
            wsum += 1.0f;
        }
    }
    const float vis = clamp(wsum > 0.0f ? sum / wsum : gtao_raw[by * wl + bx], 0.0f, 1.0f);
    ao_buf[gid] = pow_fast(vis, gtao_power);
}
