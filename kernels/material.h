/* A hit's material from its material's factors and maps (glTF 2.0's metallic-roughness model), in
 * one place for the material pass (kernels/material.cl: each G-buffer sample at its footprint's
 * mip level) and the reference's paths (kernels/paths/reference.cl: later vertices at level 0):
 *   base colour  factor x map (sRGB-decoded at upload), metallic x map.b, roughness x map.g
 *   normal       the map's tangent-space vector, x and y times the scale, through the hit's frame
 *                tw = (tangent, w), bitangent = w cross(n, tangent)
 *   occlusion    1 + strength (map.r - 1): the image-based light only
 *   emissive     factor x map (sRGB-decoded)
 * Each map kind's fetch is compiled only where some material has one (HAS_<KIND>_MAP).
 * numpy twin: iblbake/render/twin/material.py resolve_materials. */
#ifndef IBLBAKE_MATERIAL_H
#define IBLBAKE_MATERIAL_H
#include "common.h"
#include "layout.h"
#include "texture.h"

typedef struct {
    float3 base, emissive, nrm;
    float metallic, roughness, occlusion;
} MaterialSample;

/* Material m at texture coordinates uv (u0, v0, u1, v1) and mip levels lods of its two sets (<= 0:
 * level 0), shading normal nrm with tangent frame tw; metallic, roughness and occlusion unclamped. */
IBL_INLINE MaterialSample material_sample(__global const float4 *materials, __global const float4 *mat_maps,
                                      TEXTURE_PARAMS, int m, float4 uv, float2 lods, float3 nrm, float4 tw)
{
    const float4 a = materials[MATERIAL_FLOAT4S * m], b = materials[MATERIAL_FLOAT4S * m + 1];
    MaterialSample s;
    s.base = a.xyz; s.emissive = b.xyz; s.nrm = nrm;
    s.metallic = a.w; s.roughness = b.w; s.occlusion = 1.0f;
    __global const float4 *slot;
    Footprint fp;                        /* shared by the maps of one size, UVs and sampler */
    int fp_slot = -1;
#ifdef HAS_BASE_COLOR_MAP
    slot = map_slot(mat_maps, m, MAP_BASE_COLOR);
    if (map_texture(slot) >= 0) s.base *= map_sample(TEXTURE_ARGS, slot, uv, lods, &fp_slot, &fp).xyz;
#endif
#ifdef HAS_METALLIC_ROUGHNESS_MAP
    slot = map_slot(mat_maps, m, MAP_METALLIC_ROUGHNESS);
    if (map_texture(slot) >= 0) {
        const float4 mr = map_sample(TEXTURE_ARGS, slot, uv, lods, &fp_slot, &fp);
        s.metallic *= mr.z;
        s.roughness *= mr.y;
    }
#endif
#ifdef HAS_NORMAL_MAP
    slot = map_slot(mat_maps, m, MAP_NORMAL);
    if (map_texture(slot) >= 0) {
        const float scale = mat_maps[MATERIAL_MAPS_FLOAT4S * m].z;
        float3 tn = map_sample(TEXTURE_ARGS, slot, uv, lods, &fp_slot, &fp).xyz;
        tn.xy *= scale;
        const float3 bt = tw.w * cross(nrm, tw.xyz);
        const float3 p = tw.xyz * tn.x + bt * tn.y + nrm * tn.z;
        const float lp = length(p);
        if (lp > 1e-12f) s.nrm = p / lp;
    }
#endif
#ifdef HAS_OCCLUSION_MAP
    slot = map_slot(mat_maps, m, MAP_OCCLUSION);
    if (map_texture(slot) >= 0)
        s.occlusion = 1.0f + mat_maps[MATERIAL_MAPS_FLOAT4S * m].w * (map_sample(TEXTURE_ARGS, slot, uv, lods, &fp_slot, &fp).x - 1.0f);
#endif
#ifdef HAS_EMISSIVE_MAP
    slot = map_slot(mat_maps, m, MAP_EMISSIVE);
    if (map_texture(slot) >= 0) s.emissive *= map_sample(TEXTURE_ARGS, slot, uv, lods, &fp_slot, &fp).xyz;
#endif
    return s;
}

#endif
