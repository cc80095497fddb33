/* Material pass: every hit's material resolved from its material's factors and maps (glTF 2.0's
 * metallic-roughness model), into gb_mat, which the lighting passes read through surface.h:
 *   base colour  factor x map (sRGB-decoded at upload), metallic x map.b, roughness x map.g
 *   normal       the map's tangent-space vector, x and y times the scale, through the hit's frame
 *                (tangent, bitangent = w cross(n, tangent), n) from the G-buffer
 *   occlusion    1 + strength (map.r - 1): the image-based light only
 *   emissive     factor x map (sRGB-decoded)
 * Each map kind's fetch is compiled only where some material has one (HAS_<KIND>_MAP).
 * numpy twin: iblbake/render/twin/material.py resolve_materials. */
#include "common.h"
#include "texture.h"

__kernel void materials(__global const float4 *gb_pos, __global const float4 *gb_nrm, __global const float4 *gb_uv,
                        __global const float4 *gb_tan, __global const float4 *gb_lod, const int n,
                        __global const float4 *materials, __global const float4 *mat_maps, TEXTURE_PARAMS,
                        __global float4 *gb_mat)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    if (gb_pos[gid].w == MISS_T) return;
    const float4 nm = gb_nrm[gid];
    const int m = as_int(nm.w);
    const float4 a = materials[MATERIAL_FLOAT4S * m], b = materials[MATERIAL_FLOAT4S * m + 1];
    float3 base = a.xyz, emissive = b.xyz, nrm = nm.xyz;
    float metallic = a.w, roughness = b.w, occlusion = 1.0f;
    const float4 uv = gb_uv[gid];
    const float2 lods = gb_lod[gid].xy;
    __global const float4 *slot;
    Footprint fp;                        /* shared by the maps of one size, UVs and sampler */
    int fp_slot = -1;
#ifdef HAS_BASE_COLOR_MAP
    slot = map_slot(mat_maps, m, MAP_BASE_COLOR);
    if (map_texture(slot) >= 0) base *= map_sample(TEXTURE_ARGS, slot, uv, lods, &fp_slot, &fp).xyz;
#endif
#ifdef HAS_METALLIC_ROUGHNESS_MAP
    slot = map_slot(mat_maps, m, MAP_METALLIC_ROUGHNESS);
    if (map_texture(slot) >= 0) {
        const float4 mr = map_sample(TEXTURE_ARGS, slot, uv, lods, &fp_slot, &fp);
        metallic *= mr.z;
        roughness *= mr.y;
    }
#endif
#ifdef HAS_NORMAL_MAP
    slot = map_slot(mat_maps, m, MAP_NORMAL);
    if (map_texture(slot) >= 0) {
        const float scale = mat_maps[MATERIAL_MAPS_FLOAT4S * m].z;
        float3 tn = map_sample(TEXTURE_ARGS, slot, uv, lods, &fp_slot, &fp).xyz;
        tn.xy *= scale;
        const float4 tw = gb_tan[gid];
        const float3 bt = tw.w * cross(nrm, tw.xyz);
        const float3 p = tw.xyz * tn.x + bt * tn.y + nrm * tn.z;
        const float lp = length(p);
        if (lp > 1e-12f) nrm = p / lp;
    }
#endif
#ifdef HAS_OCCLUSION_MAP
    slot = map_slot(mat_maps, m, MAP_OCCLUSION);
    if (map_texture(slot) >= 0)
        occlusion = 1.0f + mat_maps[MATERIAL_MAPS_FLOAT4S * m].w * (map_sample(TEXTURE_ARGS, slot, uv, lods, &fp_slot, &fp).x - 1.0f);
#endif
#ifdef HAS_EMISSIVE_MAP
    slot = map_slot(mat_maps, m, MAP_EMISSIVE);
    if (map_texture(slot) >= 0) emissive *= map_sample(TEXTURE_ARGS, slot, uv, lods, &fp_slot, &fp).xyz;
#endif
    gb_mat[3 * gid] = (float4)(base, clamp(metallic, 0.0f, 1.0f));
    gb_mat[3 * gid + 1] = (float4)(emissive, clamp(roughness, 0.0f, 1.0f));
    gb_mat[3 * gid + 2] = (float4)(nrm, clamp(occlusion, 0.0f, 1.0f));
}
