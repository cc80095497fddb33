/* Background pass: what the samples that hit nothing see, added into the radiance buffer (a
 * miss carries no lighting, so it composes by coverage). BACKGROUND: BACKGROUND_SHOW (the
 * panorama), BACKGROUND_BLUR (a prefiltered level), BACKGROUND_COLOR. */
#include "common.h"
#include "brdf.h"
#include "sampling.h"
#include "envmap.h"
#include "sh.h"
#include "scene.h"
#include "surface.h"

__kernel void background(__global const float4 *gb_pos, __global const float4 *gb_dir, const int n,
                         const float2 env_rot, const float env_scale, const float4 color,
                         __global const float *chain, __constant int *off, __constant int *lw,
                         __constant int *lh, const int nlev, const float lod, __global float4 *radiance)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    if (gb_pos[gid].w != MISS_T) return;
#if BACKGROUND == BACKGROUND_SHOW || BACKGROUND == BACKGROUND_BLUR
    radiance[gid] += (float4)(env_scale * chain_lookup(chain, off, lw, lh, nlev, to_env(gb_dir[gid].xyz, env_rot), lod), 0.0f);
#elif BACKGROUND == BACKGROUND_COLOR
    radiance[gid] += (float4)(color.xyz, 0.0f);
#endif
}
