/* Probe rays: the light arriving at each irradiance probe along each of its ray directions, by the
 * reference's path tracer (kernels/paths/paths.h follow_path), and how far the ray went (the probes'
 * distance moments and their relocation and classification read it; DDGI, Majercik et al. 2019).
 *   a miss:       the panorama averaged over the ray's share of the sphere (ray_dirs[r].w, or where that
 *                 is 0 ray_solid_angle = 4 pi / rays)
 *                 (the radiance chain at that footprint, as the importance pass filters its samples),
 *                 times env_scale; distance +INFINITY. A sun smaller than a ray's share is neither
 *                 missed nor hit by chance: its light lands in the ray whose share holds it, seen or
 *                 shadowed as that ray is (the probes' own angular resolution)
 *   a back face:  (scene.h probe_back_face: the inside of a solid; an open surface has none,
 *                 docs/conventions.md "Sides") no light where back_faces_black (the irradiance
 *                 probes: a probe inside geometry, whose rays meet a closed single-sided mesh from
 *                 inside too), else shaded as the camera sees it (captures: their rays meet what
 *                 camera rays meet);
 *                 distance -t, negative as RTXGI marks it (RTXGI stores -0.2 t)
 *   a front face: the surface's emission plus the light it scatters towards the probe, every
 *                 bounce the scene's BOUNCES allows; distance t
 * shade = 0: distances only (relocation looks at nothing else). ray_obj: the object each ray met
 * (-1: none), for the bakes' warnings. skip_obj[object] != 0 (where skip): the first ray passes
 * through that object (a capture's exclude list; later bounces see it).
 * Work item (probe first + i, ray r): out[i nrays + r]; the ray's random stream is its probe and
 * ray number ray0 + r, so a bake is the same however it is split into launches. by_ids: the probes
 * are probe_ids[first + i] (those traced of a grid, each with its own number and stream). The reflection
 * probes' captures (iblbake/render/reflection_probes.py) trace their texels' rays here too.
 * numpy twin of what the probes make of these rays: iblbake/render/probes/project.py. */
#include "common.h"
#include "envmap.h"
#include "scene.h"
#include "surface.h"
#include "material.h"
#include "light.h"
#include "paths/paths.h"

__kernel void probe_trace(__global const float4 *probe_pos, __global const int *probe_ids, const int by_ids,
                          __global const float4 *ray_dirs, const int nrays,
                          const int first, const int count, const int ray0, const uint seed, const int shade,
                          const int back_faces_black, ENV_PARAMS, CHAIN_PARAMS, const float ray_solid_angle,
                          __global const float4 *materials, SCENE_PARAMS,
                          __global const float4 *lights, const int nlights, __global const int *skip_obj,
                          const int skip, __global float4 *ray_out, __global int *ray_obj)
{
    const int item = get_global_id(0);
    if (item >= count * nrays) return;
    const int slot = first + item / nrays, r = item % nrays;
    const int probe = by_ids ? probe_ids[slot] : slot;      /* its position and random stream */
    const float3 o = probe_pos[probe].xyz, d = ray_dirs[r].xyz;
    const int cull = back_faces_black ? 2 : 1;       /* a probe meets solids' insides; a capture, what the camera does */
    Hit hh = trace_range(o, d, 0.0f, INFINITY, 0, cull, SCENE_ARGS);
    for (int k = 0; skip && k < 64 && hh.kind != PRIM_NONE && skip_obj[hit_object(hh.kind, hh.index, SCENE_ARGS)]; ++k)
        hh = trace_range(o, d, hh.t, INFINITY, 0, cull, SCENE_ARGS);
    ray_obj[item] = hh.kind == PRIM_NONE ? -1 : hit_object(hh.kind, hh.index, SCENE_ARGS);
    if (hh.kind == PRIM_NONE) {
        const float3 e = to_env(d, env_rot);
        const float share = ray_dirs[r].w > 0.0f ? ray_dirs[r].w : ray_solid_angle;
        const float lod = 0.5f * log2(share / texel_solid_angle(e, lw[0], lh[0]));
        ray_out[item] = (float4)(chain_lookup(CHAIN_ARGS, e, lod) * env_scale, INFINITY);
        return;
    }
    float3 ng, ns;
    int m, obj;
    hit_normals(hh.kind, hh.index, o + hh.t * d, hh.b1, hh.b2, &ng, &ns, &m, &obj, SCENE_ARGS);
    const int back = probe_back_face(hh.kind, hh.index, ng, d, SCENE_ARGS);
    if ((back && back_faces_black) || !shade) {
        ray_out[item] = (float4)(0.0f, 0.0f, 0.0f, back ? -hh.t : hh.t);
        return;
    }
    Sampler sp = sampler_start(seed, (uint)probe, (uint)(ray0 + r));
    float3 env_part;
    const float3 emitted = follow_path(o, d, hh, (float3)(1.0f), &sp, materials, ENV_ARGS, SCENE_ARGS, &env_part,
                                       lights, nlights);
    ray_out[item] = (float4)(env_part * env_scale + emitted, back ? -hh.t : hh.t);
}
