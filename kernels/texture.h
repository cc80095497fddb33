/* Material textures: every level of every texture as float32 RGBA texels in one buffer (linear
 * values: colour maps sRGB-decoded, normal maps unit vectors; float32 keeps an 8- or 16-bit texel's
 * decoded value exactly, which half floats round to 11 bits)
 * (tex_levels: first texel, width, height; tex_info: first level, level count, sampler bits), read
 * as glTF's samplers say: wrap repeat | clamp | mirrored repeat per axis, magnification nearest or
 * bilinear, minification within a level nearest or bilinear and between levels nearest or linear
 * (trilinear), from the mip level of the pixel's footprint (kernels/gbuffer.cl). Material maps:
 * the UV set and KHR_texture_transform of each slot of mat_maps (kernels/layout.h).
 * numpy twin: iblbake/scene/textures.py (sample), iblbake/render/twin/material.py. */
#ifndef IBLBAKE_TEXTURE_H
#define IBLBAKE_TEXTURE_H
#include "inline.h"
#include "layout.h"

#define TEXTURE_PARAMS __global const float4 *texels, __global const int4 *tex_levels, __global const int4 *tex_info
#define TEXTURE_ARGS texels, tex_levels, tex_info

#define WRAP_REPEAT 0
#define WRAP_CLAMP 1
#define WRAP_MIRROR 2

/* A texel index of one level from a coordinate of one period (wrap_coordinate): x is within
 * [-1, n] for repeat and [-1, 2n] for mirror, so a compare or two replaces a modulo. */
IBL_INLINE int wrap_index(int i, int n, int mode)
{
    if (mode == WRAP_CLAMP) return clamp(i, 0, n - 1);
    if (mode == WRAP_MIRROR) {
        if (i < 0) i = -1 - i;                    /* -1 mirrors to 0 */
        if (i >= 2 * n) i -= 2 * n;
        return i < n ? i : 2 * n - 1 - i;
    }
    return i < 0 ? i + n : (i >= n ? i - n : i);
}

/* The same texels for any uv of one period (repeat: 1, mirror: 2), so that texel indices stay
 * small whatever the coordinates; clamp keeps [-1, 2], beyond which every lookup is an edge. */
IBL_INLINE float wrap_coordinate(float u, int mode)
{
    if (mode == WRAP_CLAMP) return clamp(u, -1.0f, 2.0f);
    const float p = mode == WRAP_MIRROR ? 2.0f : 1.0f;
    return u - p * floor(u / p);
}

/* Where a texture is read: up to two levels (k0, k1) of four taps each, texel offsets within the
 * level and weights (nearest: one tap of weight 1; no blend between levels: the second level's
 * weights 0). It depends on the level sizes, the coordinates, the level and the sampler only, so
 * maps of one size read through the same UVs and sampler (a material's texture set, as glTF
 * exporters write them) share it, and only their texels differ. */
typedef struct {
    int k0, k1;
    int4 off0, off1;
    float4 w0, w1;
} Footprint;

/* The four taps of one level (dimensions lv.yz) at uv: nearest, or bilinear between texel centres
 * ((i + 0.5) / w); each wrapped column and row index computed once. */
IBL_INLINE void level_taps(int4 lv, float2 uv, int bilinear, int ws, int wt, float scale, int4 *off, float4 *w)
{
    const float x = uv.x * (float)lv.y, y = uv.y * (float)lv.z;
    if (!bilinear) {
        *off = (int4)(wrap_index((int)floor(y), lv.z, wt) * lv.y + wrap_index((int)floor(x), lv.y, ws), 0, 0, 0);
        *w = (float4)(scale, 0.0f, 0.0f, 0.0f);
        return;
    }
    const float fx0 = floor(x - 0.5f), fy0 = floor(y - 0.5f);
    const float fx = x - 0.5f - fx0, fy = y - 0.5f - fy0;
    const int x0 = (int)fx0, y0 = (int)fy0;
    const int c0 = wrap_index(x0, lv.y, ws), c1 = wrap_index(x0 + 1, lv.y, ws);
    const int r0 = wrap_index(y0, lv.z, wt) * lv.y, r1 = wrap_index(y0 + 1, lv.z, wt) * lv.y;
    *off = (int4)(r0 + c0, r0 + c1, r1 + c0, r1 + c1);
    *w = scale * (float4)((1.0f - fx) * (1.0f - fy), fx * (1.0f - fy), (1.0f - fx) * fy, fx * fy);
}

/* The footprint of texture t (its sizes and sampler) at uv for the mip level lod (log2 of the
 * footprint in level-0 texels): the magnification filter where lod <= 0 (or NaN), else the
 * minification filter. */
IBL_INLINE Footprint texture_footprint(TEXTURE_PARAMS, int t, float2 uv, float lod)
{
    const int4 info = tex_info[t];
    const int bits = info.z;
    const int ws = bits & 15, wt = (bits >> 4) & 15, mag = (bits >> 8) & 15;
    const int within = (bits >> 12) & 15, between = (bits >> 16) & 15;
    uv = (float2)(wrap_coordinate(uv.x, ws), wrap_coordinate(uv.y, wt));
    Footprint fp;
    fp.k0 = 0;
    fp.k1 = 0;
    fp.off1 = (int4)(0);
    fp.w1 = (float4)(0.0f);
    int filter = within;
    float f = 0.0f;
    if (!(lod > 0.0f)) filter = mag;
    else if (between != 3) {                   /* 3: no mipmaps */
        const float l = fmin(lod, (float)(info.y - 1));
        if (between == 0) fp.k0 = (int)floor(l + 0.5f);
        else {
            fp.k0 = (int)floor(l);
            fp.k1 = min(fp.k0 + 1, info.y - 1);
            f = l - (float)fp.k0;
        }
    }
    level_taps(tex_levels[info.x + fp.k0], uv, filter, ws, wt, 1.0f - f, &fp.off0, &fp.w0);
    if (f > 0.0f) level_taps(tex_levels[info.x + fp.k1], uv, filter, ws, wt, f, &fp.off1, &fp.w1);
    return fp;
}

/* Texture t read where fp says (any texture of the same sizes and sampler as the one it was made for). */
IBL_INLINE float4 texture_read(TEXTURE_PARAMS, int t, Footprint fp)
{
    const int first = tex_info[t].x;
    __global const float4 *a = texels + tex_levels[first + fp.k0].x;
    float4 c = fp.w0.x * a[fp.off0.x] + fp.w0.y * a[fp.off0.y] + fp.w0.z * a[fp.off0.z] + fp.w0.w * a[fp.off0.w];
    if (fp.w1.x + fp.w1.y + fp.w1.z + fp.w1.w > 0.0f) {
        __global const float4 *b = texels + tex_levels[first + fp.k1].x;
        c += fp.w1.x * b[fp.off1.x] + fp.w1.y * b[fp.off1.y] + fp.w1.z * b[fp.off1.z] + fp.w1.w * b[fp.off1.w];
    }
    return c;
}

IBL_INLINE float4 texture_sample(TEXTURE_PARAMS, int t, float2 uv, float lod)
{
    return texture_read(TEXTURE_ARGS, t, texture_footprint(TEXTURE_ARGS, t, uv, lod));
}

/* A material's map slot (MAP_* of kernels/layout.h): its three rows in mat_maps */
IBL_INLINE __global const float4 *map_slot(__global const float4 *mat_maps, int material, int kind)
{
    return mat_maps + MATERIAL_MAPS_FLOAT4S * material + 2 + 3 * kind;
}

IBL_INLINE int map_texture(__global const float4 *slot) { return as_int(slot[0].w); }

/* The slot's coordinates: its TEXCOORD set (uv01 = (u0, v0, u1, v1)) through its
 * KHR_texture_transform, uv' = M (u, v, 1). */
IBL_INLINE float2 map_uv(__global const float4 *slot, float4 uv01)
{
    const float2 uv = as_int(slot[1].w) == 1 ? uv01.zw : uv01.xy;
    return (float2)(slot[0].x * uv.x + slot[0].y * uv.y + slot[0].z, slot[1].x * uv.x + slot[1].y * uv.y + slot[1].z);
}

/* The slot's mip level: the footprint's level for its set (lods: gb_lod) plus the slot's third
 * row's 0.5 log2 of the texture's texels per unit of UV area, w h |det M| (from the host). */
IBL_INLINE float map_lod(__global const float4 *slot, float2 lods)
{
    return (as_int(slot[1].w) == 1 ? lods.y : lods.x) + slot[2].x;
}

/* The slot of this material whose footprint this one shares (the first with the same texture
 * sizes, sampler, UV set and transform; itself where none: from the host) */
IBL_INLINE int map_shares(__global const float4 *slot) { return as_int(slot[2].y); }

/* A material's map kind read at a G-buffer sample, reusing the footprint of the last slot read
 * (*fp_slot, *fp) where this one shares it. */
IBL_INLINE float4 map_sample(TEXTURE_PARAMS, __global const float4 *slot, float4 uv01, float2 lods, int *fp_slot,
                         Footprint *fp)
{
    const int t = map_texture(slot);
    if (map_shares(slot) != *fp_slot) {
        *fp = texture_footprint(TEXTURE_ARGS, t, map_uv(slot, uv01), map_lod(slot, lods));
        *fp_slot = map_shares(slot);
    }
    return texture_read(TEXTURE_ARGS, t, *fp);
}

#endif
