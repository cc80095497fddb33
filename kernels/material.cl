/* Material pass: every hit's material resolved from its material's factors and maps
 * (kernels/material.h) at the G-buffer's footprint, into gb_mat, which the lighting passes read
 * through surface.h. numpy twin: iblbake/render/twin/material.py resolve_materials. */
#include "common.h"
#include "texture.h"
#include "material.h"

__kernel void materials(__global const float4 *gb_pos, __global const float4 *gb_nrm, __global const float4 *gb_uv,
                        __global const float4 *gb_tan, __global const float4 *gb_lod, const int n,
                        __global const float4 *materials, __global const float4 *mat_maps, TEXTURE_PARAMS,
                        __global float4 *gb_mat)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    if (gb_pos[gid].w == MISS_T) return;
    const float4 nm = gb_nrm[gid];
#ifdef HAS_NORMAL_MAP
    const float4 tw = gb_tan[gid];
#else
    const float4 tw = (float4)(0.0f);
#endif
    const MaterialSample s = material_sample(materials, mat_maps, TEXTURE_ARGS, as_int(nm.w), gb_uv[gid],
                                             gb_lod[gid].xy, nm.xyz, tw);
    gb_mat[3 * gid] = (float4)(s.base, clamp(s.metallic, 0.0f, 1.0f));
    gb_mat[3 * gid + 1] = (float4)(s.emissive, clamp(s.roughness, 0.0f, 1.0f));
    gb_mat[3 * gid + 2] = (float4)(s.nrm, clamp(s.occlusion, 0.0f, 1.0f));
}
