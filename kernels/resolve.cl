/* Resolve pass: the frame from the per-sample radiance, and the AOVs (WRITE_AOVS). */
#include "layout.h"

/* Pixel = mean of its samples' radiance (what every lighting pass added); alpha = coverage. */
__kernel void resolve(__global const float4 *radiance,
                      __global const float4 *gb_pos, __global const float4 *gb_nrm, __global const float4 *gb_dir,
                      __global const float4 *materials, __global const float4 *gb_mat, const int spp, const int npix,
                      __global float4 *hdr, __global float4 *aov_normal, __global float4 *aov_albedo,
                      __global float *aov_depth, __global float *aov_object)
{
    const int px = get_global_id(0);
    if (px >= npix) return;
    float3 c = (float3)(0.0f);
    float cover = 0.0f;
#ifdef WRITE_AOVS
    float3 nsum = (float3)(0.0f), asum = (float3)(0.0f);
    float dsum = 0.0f;
#endif
    for (int s = 0; s < spp; ++s) {
        const int g = px * spp + s;
        c += radiance[g].xyz;
        const float4 p = gb_pos[g];
        if (p.w != MISS_T) {
            cover += 1.0f;
#ifdef WRITE_AOVS
#ifdef HAS_TEXTURES
            nsum += gb_mat[3 * g + 2].xyz;             /* the material pass's: normal-mapped, textured */
            asum += gb_mat[3 * g].xyz;
#else
            const float4 nm = gb_nrm[g];
            nsum += nm.xyz;
            asum += materials[MATERIAL_FLOAT4S * as_int(nm.w)].xyz;
#endif
            dsum += p.w;
#endif
        }
    }
    const float inv = 1.0f / (float)spp;
    hdr[px] = (float4)(c * inv, cover * inv);
#ifdef WRITE_AOVS
    aov_normal[px] = (float4)(nsum * inv, cover * inv);
    aov_albedo[px] = (float4)(asum * inv, cover * inv);
    aov_depth[px] = cover > 0.0f ? dsum / cover : 0.0f;
    /* the first sample's object (objects.N), -1 where it hit nothing */
    aov_object[px] = gb_pos[px * spp].w != MISS_T ? (float)as_int(gb_dir[px * spp].w) : -1.0f;
#endif
}
