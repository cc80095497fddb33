/* Material textures: every level of every texture as float32 RGBA texels in one buffer (linear
 * values: colour maps sRGB-decoded, normal maps unit vectors; float32 keeps an 8- or 16-bit texel's
 * decoded value exactly, which half floats round to 11 bits)
 * (tex_levels: first texel, width, height; tex_info: first level, level count, sampler bits), read
 * as glTF's samplers say: wrap repeat | clamp | mirrored repeat per axis, magnification nearest or
 * bilinear, minification within a level nearest or bilinear and between levels nearest or linear
 * (trilinear), from the mip level of the pixel's footprint (kernels/gbuffer.cl). Material maps:
 * the UV set and KHR_texture_transform of each slot of mat_maps (kernels/layout.h).
 * numpy twin: iblbake/scene/textures.py (sample), iblbake/render/twin.py (resolve_materials). */
#ifndef IBLBAKE_TEXTURE_H
#define IBLBAKE_TEXTURE_H
#include "layout.h"

#define TEXTURE_PARAMS __global const float4 *texels, __global const int4 *tex_levels, __global const int4 *tex_info
#define TEXTURE_ARGS texels, tex_levels, tex_info

#define WRAP_REPEAT 0
#define WRAP_CLAMP 1
#define WRAP_MIRROR 2

inline int wrap_index(int i, int n, int mode)
{
    if (mode == WRAP_CLAMP) return clamp(i, 0, n - 1);
    if (mode == WRAP_MIRROR) {
        int k = i % (2 * n);
        if (k < 0) k += 2 * n;
        return k < n ? k : 2 * n - 1 - k;
    }
    int k = i % n;
    return k < 0 ? k + n : k;
}

/* The same texels for any uv of one period (repeat: 1, mirror: 2), so that texel indices stay
 * small whatever the coordinates; clamp keeps [-1, 2], beyond which every lookup is an edge. */
inline float wrap_coordinate(float u, int mode)
{
    if (mode == WRAP_CLAMP) return clamp(u, -1.0f, 2.0f);
    const float p = mode == WRAP_MIRROR ? 2.0f : 1.0f;
    return u - p * floor(u / p);
}

inline float4 texel_fetch(TEXTURE_PARAMS, int4 lv, int x, int y, int ws, int wt)
{
    return texels[lv.x + wrap_index(y, lv.z, wt) * lv.y + wrap_index(x, lv.y, ws)];
}

/* One level at uv: nearest, or bilinear between texel centres ((i + 0.5) / w). */
inline float4 sample_level(TEXTURE_PARAMS, int level, float2 uv, int bilinear, int ws, int wt)
{
    const int4 lv = tex_levels[level];
    const float x = uv.x * (float)lv.y, y = uv.y * (float)lv.z;
    if (!bilinear) return texel_fetch(TEXTURE_ARGS, lv, (int)floor(x), (int)floor(y), ws, wt);
    const float fx0 = floor(x - 0.5f), fy0 = floor(y - 0.5f);
    const float fx = x - 0.5f - fx0, fy = y - 0.5f - fy0;
    const int x0 = (int)fx0, y0 = (int)fy0;
    const float4 a = mix(texel_fetch(TEXTURE_ARGS, lv, x0, y0, ws, wt), texel_fetch(TEXTURE_ARGS, lv, x0 + 1, y0, ws, wt), fx);
    const float4 b = mix(texel_fetch(TEXTURE_ARGS, lv, x0, y0 + 1, ws, wt), texel_fetch(TEXTURE_ARGS, lv, x0 + 1, y0 + 1, ws, wt), fx);
    return mix(a, b, fy);
}

/* Texture t at uv for the mip level lod (log2 of the footprint in level-0 texels): the
 * magnification filter where lod <= 0 (or NaN), else the minification filter. */
inline float4 texture_sample(TEXTURE_PARAMS, int t, float2 uv, float lod)
{
    const int4 info = tex_info[t];
    const int bits = info.z;
    const int ws = bits & 15, wt = (bits >> 4) & 15, mag = (bits >> 8) & 15;
    const int within = (bits >> 12) & 15, between = (bits >> 16) & 15;
    uv = (float2)(wrap_coordinate(uv.x, ws), wrap_coordinate(uv.y, wt));
    if (!(lod > 0.0f)) return sample_level(TEXTURE_ARGS, info.x, uv, mag, ws, wt);
    if (between == 3) return sample_level(TEXTURE_ARGS, info.x, uv, within, ws, wt);     /* no mipmaps */
    const float l = fmin(lod, (float)(info.y - 1));
    if (between == 0) return sample_level(TEXTURE_ARGS, info.x + (int)floor(l + 0.5f), uv, within, ws, wt);
    const int k0 = (int)floor(l), k1 = min(k0 + 1, info.y - 1);
    return mix(sample_level(TEXTURE_ARGS, info.x + k0, uv, within, ws, wt),
               sample_level(TEXTURE_ARGS, info.x + k1, uv, within, ws, wt), l - (float)k0);
}

/* A material's map slot (MAP_* of kernels/layout.h): its two rows in mat_maps */
inline __global const float4 *map_slot(__global const float4 *mat_maps, int material, int kind)
{
    return mat_maps + MATERIAL_MAPS_FLOAT4S * material + 2 + 2 * kind;
}

inline int map_texture(__global const float4 *slot) { return as_int(slot[0].w); }

/* The slot's coordinates: its TEXCOORD set (uv01 = (u0, v0, u1, v1)) through its
 * KHR_texture_transform, uv' = M (u, v, 1). */
inline float2 map_uv(__global const float4 *slot, float4 uv01)
{
    const float2 uv = as_int(slot[1].w) == 1 ? uv01.zw : uv01.xy;
    return (float2)(slot[0].x * uv.x + slot[0].y * uv.y + slot[0].z, slot[1].x * uv.x + slot[1].y * uv.y + slot[1].z);
}

/* The slot's mip level: the footprint's level for its set (lods: gb_lod) plus 0.5 log2 of the
 * texture's texels per unit of UV area, w h |det M|. */
inline float map_lod(TEXTURE_PARAMS, __global const float4 *slot, float2 lods)
{
    const int4 lv = tex_levels[tex_info[map_texture(slot)].x];
    const float det = fabs(slot[0].x * slot[1].y - slot[0].y * slot[1].x);
    return (as_int(slot[1].w) == 1 ? lods.y : lods.x) + 0.5f * log2((float)lv.y * (float)lv.z * det);
}

inline float4 map_sample(TEXTURE_PARAMS, __global const float4 *slot, float4 uv01, float2 lods)
{
    return texture_sample(TEXTURE_ARGS, map_texture(slot), map_uv(slot, uv01), map_lod(TEXTURE_ARGS, slot, lods));
}

#endif
