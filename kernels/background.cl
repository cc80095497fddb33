/* Background pass: what the samples that hit nothing see, added into the radiance buffer (a
 * miss carries no lighting, so it composes by coverage). BACKGROUND: BACKGROUND_SHOW (the
 * panorama), BACKGROUND_BLUR (a prefiltered level), BACKGROUND_COLOR. */
#include "common.h"
#include "envmap.h"
/* contraction off from here, as in the kernels that trace rays (scene.h turns it off before
 * surface.h in each of them): to_env's rotation rounds the same in every program */
#pragma OPENCL FP_CONTRACT OFF
#include "surface.h"

__kernel void background(__global const float4 *gb_pos, __global const float4 *gb_dir, const int n,
                         const float2 env_rot, const float env_scale, const float4 color,
                         CHAIN_PARAMS, const float lod, __global float4 *radiance)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    if (gb_pos[gid].w != MISS_T) return;
#if BACKGROUND == BACKGROUND_SHOW || BACKGROUND == BACKGROUND_BLUR
    radiance[gid] += (float4)(env_scale * chain_lookup(CHAIN_ARGS, to_env(gb_dir[gid].xyz, env_rot), lod), 0.0f);
#elif BACKGROUND == BACKGROUND_COLOR
    radiance[gid] += (float4)(color.xyz, 0.0f);
#endif
}
