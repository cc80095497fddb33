/* Rays alone: the path profile's recorded rays (kernels/scene.h PROFILE_RAYS, recorded by the
 * reference's own kernel) traced again with nothing around them, so their launch times the
 * traversal and nothing else (iblbake/render/paths/profile.py). Work item i traces, in the order
 * its reference work item traced them, the rays ray_ix[ray_start[i] .. ray_start[i + 1]) of one
 * bounce and kind: the same rays, on the same work items, through the same trace_range as
 * scene.h's trace (closest hit) and occluded / occluded_to (any hit, to the recorded tmax), each
 * kind its own kernel so that any_hit is a constant as it is where the paths call them.
 * ray_sink[i]: a sum of what was found, so that no traversal is optimised away. */
#include "common.h"
#include "scene.h"

/* the rays of one work item: their closest or any hit, summed */
IBL_INLINE float trace_recorded(__global const float4 *prof_rays, __global const int *ray_ix, int first, int end,
                                int any_hit, SCENE_PARAMS)
{
    float found = 0.0f;
    for (int j = first; j < end; ++j) {
        __global const float4 *r = prof_rays + 3 * ray_ix[j];
        const float4 a = r[0], b = r[1];
        const Hit h = trace_range(a.xyz, b.xyz, 0.0f, a.w, any_hit, 1, SCENE_ARGS);
        found += (float)h.kind + (any_hit ? 0.0f : h.t);
    }
    return found;
}

__kernel void trace_closest(__global const float4 *prof_rays, __global const int *ray_ix,
                            __global const int *ray_start, const int items, SCENE_PARAMS, __global float *ray_sink)
{
    const int i = get_global_id(0);
    if (i < items) ray_sink[i] = trace_recorded(prof_rays, ray_ix, ray_start[i], ray_start[i + 1], 0, SCENE_ARGS);
}

__kernel void trace_shadow(__global const float4 *prof_rays, __global const int *ray_ix,
                           __global const int *ray_start, const int items, SCENE_PARAMS, __global float *ray_sink)
{
    const int i = get_global_id(0);
    if (i < items) ray_sink[i] = trace_recorded(prof_rays, ray_ix, ray_start[i], ray_start[i + 1], 1, SCENE_ARGS);
}
