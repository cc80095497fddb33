/* Lightmap texels (iblbake/render/lightmaps/): the light arriving at each texel's point along each of
 * its own rays over the texel's hemisphere, by the reference's path tracer (kernels/paths/paths.h
 * follow_path), as probe_trace.cl brings it to a probe; every bounce the scene's BOUNCES allows, the
 * lights and emission included.
 *   texel_pos[first + i]: the texel's start point (its surface point, lifted along its normal)
 *   ray_dirs[i nrays + r]: ray r of that texel (world space): r < paths a path (w its share of the
 *                          hemisphere), then shadow rays drawn from the panorama's importance
 *                          table (w 0: behind the surface, not traced) (render/lightmaps/bake.py
 *                          device_shares; the weights ray_weights). No shadow ray to the analytic
 *                          lights: their direct light is the frame's (the lights pass); the paths'
 *                          later vertices sample them (follow_path)
 *   a miss reads the panorama's texel (what the importance table samples and the camera's paths
 *   meet, paths.h env_missed; a filtered read spreads a lamp where only the uniform rays find it)
 *   out[i nrays + r] = (radiance, t): t = +INFINITY a miss; the back of a solid (scene.h
 *                      probe_back_face) -t and no light (a texel inside geometry: its rays are
 *                      rejected there and the texel dilated over)
 * Its random stream is the texel's and ray's number, never its launch's.
 * lightmap_nudge: BakingLab's fix of a texel start point behind a nearby surface: rays along the
 * texel's tangent plane (nudge_dirs, 4 a texel) out to its reach (w of texel_pos); where one meets
 * the back of a solid (scene.h probe_back_face: an open surface has no inside) the point moves to
 * just past it, on its front, where it lands there (lands_on_front).
 * numpy twins: iblbake/render/lightmaps/bake.py nudge_twin (lightmap_nudge) and project() (what a
 * texel keeps of its rays). */
#include "common.h"
#include "envmap.h"
#include "scene.h"
#include "surface.h"
#include "material.h"
#include "light.h"
#include "paths/paths.h"

__kernel void lightmap_trace(__global const float4 *texel_pos, __global const float4 *ray_dirs, const int nrays,
                             const int paths, const int first, const int count, const uint seed,
                             ENV_PARAMS, __global const float4 *materials, SCENE_PARAMS,
                             __global const float4 *lights, const int nlights, __global float4 *ray_out)
{
    const int item = get_global_id(0);
    if (item >= count * nrays) return;
    const int texel = first + item / nrays, r = item % nrays;
    const float3 o = texel_pos[texel].xyz, d = ray_dirs[item].xyz;
    if (ray_dirs[item].w == 0.0f) {     /* a shadow ray behind the surface */
        ray_out[item] = (float4)(0.0f, 0.0f, 0.0f, INFINITY);
        return;
    }
    const Hit hh = trace_range(o, d, 0.0f, INFINITY, 0, 2, SCENE_ARGS);
    if (hh.kind == PRIM_NONE) {        /* the panorama's texel, as its importance table has it */
        ray_out[item] = (float4)(img[env_texel_index(to_env(d, env_rot), w, h)].xyz * env_scale, INFINITY);
        return;
    }
    if (r >= paths) {                   /* a shadow ray to the panorama: the paths bring what it meets */
        ray_out[item] = (float4)(0.0f, 0.0f, 0.0f, hh.t);
        return;
    }
    float3 ng, ns;
    int m, obj;
    hit_normals(hh.kind, hh.index, o + hh.t * d, hh.b1, hh.b2, &ng, &ns, &m, &obj, SCENE_ARGS);
    if (probe_back_face(hh.kind, hh.index, ng, d, SCENE_ARGS)) {
        ray_out[item] = (float4)(0.0f, 0.0f, 0.0f, -hh.t);
        return;
    }
    Sampler sp = sampler_start(seed, (uint)texel, (uint)r);
    float3 env_part;
    const float3 emitted = follow_path(o, d, hh, (float3)(1.0f), &sp, materials, ENV_ARGS, SCENE_ARGS, &env_part,
                                       lights, nlights);
    ray_out[item] = (float4)(env_part * env_scale + emitted, hh.t);
}

/* Whether a point just past a solid's back face lies on that solid's front: the nearest surface
 * back along the move (d, within dist) is a solid's front face. Not where another surface lies in
 * or just past it (a zero-thickness wall of either winding the solid stands flush against: past both
 * is the wall's far side, outside the room). Where the two lie in one plane the trace meets
 * whichever its BVH reaches first (the twin refuses such a tie): a texel hidden inside a box's
 * footprint may still cross there. */
IBL_INLINE int lands_on_front(float3 p, float3 d, float dist, SCENE_PARAMS)
{
    const Hit h = trace_range(p, d, 0.0f, dist, 0, 0, SCENE_ARGS);
    if (h.kind == PRIM_NONE) return 0;
    float3 ng, ns;
    int m, obj;
    hit_normals(h.kind, h.index, p + h.t * d, h.b1, h.b2, &ng, &ns, &m, &obj, SCENE_ARGS);
    return (surface_flags(h.kind, h.index, SCENE_ARGS) & SURFACE_SOLID)
           && !probe_back_face(h.kind, h.index, ng, d, SCENE_ARGS);
}

__kernel void lightmap_nudge(__global const float4 *texel_pos, __global const float4 *nudge_dirs,
                             __global const float4 *texel_nrm, const int count, SCENE_PARAMS,
                             __global float4 *pos_out)
{
    const int i = get_global_id(0);
    if (i >= count) return;
    float3 o = texel_pos[i].xyz;
    const float reach = texel_pos[i].w;
    const float3 n = texel_nrm[i].xyz;
    float nearest = reach;
    float3 moved = o;
    for (int k = 0; k < 4; ++k) {
        const float3 d = nudge_dirs[4 * i + k].xyz;
        const Hit h = trace_range(o, d, 0.0f, reach, 0, 0, SCENE_ARGS);
        if (h.kind == PRIM_NONE || h.t >= nearest) continue;
        float3 ng, ns;
        int m, obj;
        hit_normals(h.kind, h.index, o + h.t * d, h.b1, h.b2, &ng, &ns, &m, &obj, SCENE_ARGS);
        if (!probe_back_face(h.kind, h.index, ng, d, SCENE_ARGS)) continue;   /* its front: the texel sees it */
        const float past = h.t + 0.05f * reach;
        if (!lands_on_front(o + past * d, -d, past, SCENE_ARGS)) continue;
        nearest = h.t;
        moved = o + past * d + 0.05f * reach * n;      /* just past it, on its front */
    }
    pos_out[i] = (float4)(moved, reach);
}
