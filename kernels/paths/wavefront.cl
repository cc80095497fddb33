/* The reference's paths as a wavefront of stages (Laine, Karras and Aila 2013, "Megakernels
 * considered harmful: wavefront path tracing on GPUs"): the estimator of the megakernel
 * (kernels/paths/reference.cl `reference`, kernels/paths/paths.h follow_path), the same sample dimensions in
 * the same order and the same functions, cut where a ray is traced so that each stage is a small
 * kernel run over a compacted queue of the paths that need it:
 *   wf_generate    the first vertex of each (G-buffer sample, sample k) of a wave: the environment's
 *                  NEE as a shadow ray, one BSDF sample as the path's ray
 *   wf_extend      the closest hit of every live path's ray; a miss adds the environment (MIS)
 *   wf_shade       a later vertex: emission, the environment's and each light's NEE as shadow rays,
 *                  scatter, Russian roulette
 *   wf_shadow      the any-hit of a vertex's queued shadow rays, adding what arrives
 *   wf_accumulate  the per G-buffer sample sums of the megakernel's ref_batch
 * Each path's state is a PATH record (kernels/layout.h, iblbake/scene/layout.py); a queue is a list
 * of path slots in wf_queue (extend, shade and shadow, npaths each) grown with an atomic counter
 * (wf_count[0..2]), the host reading the counts to size the next stage (paper section 4.2). A
 * vertex's shadow rays (the environment's, then each light's) stay one queue entry, added in that
 * order, so the sums are the megakernel's in its order: the frames agree to float32 rounding.
 * Only with BOUNCES (the direct light alone has no path): iblbake/render/passes/reference.py. */
#include "common.h"
#include "scene.h"
#include "surface.h"
#include "paths/paths.h"

/* part of reference.cl's program (its end includes this file): FIRST_DIFFUSE, FIRST_SPECULAR and
 * SCALAR_BVH are its */
#if defined(BOUNCES) && defined(WAVEFRONT)

#define WF_EXTEND 0
#define WF_SHADE 1
#define WF_SHADOW 2
#define WF_FIRST 0           /* a shadow ray's accumulator: the first vertex's estimate */
#define WF_ENV 1             /* the environment found past it */
#define WF_EMITTED 2         /* emission and the lights */

IBL_INLINE void wf_push(__global int *wf_queue, __global int *wf_count, int q, int npaths, int slot)
{
    wf_queue[q * npaths + atomic_inc(&wf_count[q])] = slot;
}

IBL_INLINE void wf_save_sampler(__global float4 *ps, const Sampler sp)
{
    ps[3] = (float4)(as_float(sp.seed), as_float(sp.gid), as_float(sp.k), as_float(sp.dim));
}

/* the Sampler as sampler_start made it (what it derives from seed, gid, k: its stream), at dim */
IBL_INLINE Sampler wf_load_sampler(__global const float4 *ps)
{
    const float4 r = ps[3];
    Sampler sp = sampler_start(as_uint(r.x), as_uint(r.y), as_uint(r.z));
    sp.dim = as_int(r.w);
    return sp;
}

/* shadow ray j of a vertex (0 the environment's, 1 + i light i's); live 0: none */
IBL_INLINE void wf_shadow_ray(__global float4 *wf_shadow, int slot, int nlights, int j, float3 o, float3 d,
                              float tmax, int target, float3 c, int live)
{
    __global float4 *r = wf_shadow + SHADOW_FLOAT4S * (slot * (1 + nlights) + j);
    r[0] = (float4)(o, tmax);
    r[1] = (float4)(d, as_float(live ? target : -1));
    r[2] = (float4)(c, 0.0f);
}

__kernel void wf_generate(__global const float4 *gb_pos, SURFACE_PARAMS, const int n, ENV_PARAMS, SCENE_PARAMS,
                          const int pixel0, const int spp, const uint seed, const int replicates, const int first,
                          const int wave,
                          const int npaths, __global float4 *wf_paths, __global float4 *wf_shadow,
                          __global int *wf_queue, __global int *wf_count, const int nlights)
{
    const int slot = get_global_id(0);
    if (slot >= n * wave) return;
    const int gid = slot % n, kk = slot / n;
    __global float4 *ps = wf_paths + PATH_FLOAT4S * slot;
    ps[4] = ps[5] = ps[6] = (float4)(0.0f);
    const float4 hitp = gb_pos[gid];
    if (hitp.w == MISS_T) return;
    Material mt;
    float3 v, nrm;
    const float nov = surface_at(SURFACE_ARGS, gid, &mt, &v, &nrm);
    const float3 origin = ray_offset(hitp.xyz, nrm, gb_dir[gid].xyz, hitp.w);
    float3 t, b;
    tangent_frame(nrm, &t, &b);
    Sampler sp = sampler_replicate(seed, (uint)(pixel0 * spp + gid), (uint)(first + kk), replicates);
    const FirstVertex fv = first_vertex(mt, v, nrm, t, b, nov, FIRST_DIFFUSE, FIRST_SPECULAR, &sp, ENV_ARGS);
    for (int j = 0; j <= nlights; ++j)
        wf_shadow_ray(wf_shadow, slot, nlights, j, origin, fv.env_l, INFINITY, WF_FIRST, fv.env_c, j == 0 && fv.env_live);
    if (fv.env_live) wf_push(wf_queue, wf_count, WF_SHADOW, npaths, slot);
    wf_save_sampler(ps, sp);
    if (fv.live) {
        ps[0] = (float4)(origin, as_float(2));
        ps[1] = (float4)(fv.l, as_float(gid));
        ps[2] = (float4)(fv.beta, fv.pdf);
        wf_push(wf_queue, wf_count, WF_EXTEND, npaths, slot);
    }
}

SCALAR_BVH
__kernel void wf_extend(const int count, const int npaths, __global float4 *wf_paths, __global int *wf_queue,
                        __global int *wf_count, ENV_PARAMS, SCENE_PARAMS)
{
    const int item = get_global_id(0);
    if (item >= count) return;
    const int slot = wf_queue[WF_EXTEND * npaths + item];
    __global float4 *ps = wf_paths + PATH_FLOAT4S * slot;
    const float4 r0 = ps[0], r1 = ps[1], r2 = ps[2];
    const int bounce = as_int(r0.w);
    const Hit hit = trace(r0.xyz, r1.xyz, SCENE_ARGS);
    if (hit.kind == PRIM_NONE) {
        /* the first vertex's ray brings the sky into its estimate, a later one into env_part */
        __global float4 *acc = ps + (bounce == 2 ? 4 : 5);
        acc->xyz += r2.xyz * env_missed(r1.xyz, r2.w, ENV_ARGS);
        return;
    }
    ps[4].w = as_float(hit.kind);
    ps[7] = (float4)(hit.t, hit.b1, hit.b2, as_float(hit.index));
    if (bounce <= MAX_PATH) wf_push(wf_queue, wf_count, WF_SHADE, npaths, slot);
}

__kernel void wf_shade(const int count, const int npaths, __global float4 *wf_paths, __global float4 *wf_shadow,
                       __global int *wf_queue, __global int *wf_count, __global const float4 *materials, ENV_PARAMS,
                       SCENE_PARAMS, __global const float4 *lights, const int nlights)
{
    const int item = get_global_id(0);
    if (item >= count) return;
    const int slot = wf_queue[WF_SHADE * npaths + item];
    __global float4 *ps = wf_paths + PATH_FLOAT4S * slot;
    const float4 r0 = ps[0], r1 = ps[1], r2 = ps[2], r7 = ps[7];
    const int bounce = as_int(r0.w);
    Hit hit;
    hit.kind = as_int(ps[4].w); hit.t = r7.x; hit.b1 = r7.y; hit.b2 = r7.z; hit.index = as_int(r7.w);
    float3 beta = r2.xyz;
    Sampler sp = wf_load_sampler(ps);
    PathVertex pv;
    const int scatters = vertex_start(r0.xyz, r1.xyz, hit, bounce, materials, SCENE_ARGS, &pv);
    float3 emitted = ps[6].xyz + beta * pv.mt.emissive;
    if (!scatters) { ps[6].xyz = emitted; return; }
    const VertexDims u = vertex_dims(&sp);
    float3 le, c;
    const int env_live = env_sample(pv.mt, pv.v, pv.n, pv.nov, pv.ps, 1, 1, u.env, ENV_ARGS, &le, &c);
    wf_shadow_ray(wf_shadow, slot, nlights, 0, pv.origin, le, INFINITY, WF_ENV, beta * c, env_live);
    int any = env_live;
#ifdef PATH_LIGHTS
    for (int j = 0; j < nlights; ++j) {
        float3 ll;
        float dist;
        const int live = light_sample(lights, j, &sp, pv, beta, &ll, &dist, &c);
        wf_shadow_ray(wf_shadow, slot, nlights, 1 + j, pv.origin, ll, dist, WF_EMITTED, c, live);
        any |= live;
    }
#endif
    ps[6].xyz = emitted;
    if (any) wf_push(wf_queue, wf_count, WF_SHADOW, npaths, slot);
    float3 nl;
    float pb;
    const int on = path_scatter(pv, u, bounce, &beta, &nl, &pb);
    wf_save_sampler(ps, sp);
    if (on) {
        ps[0] = (float4)(pv.origin, as_float(bounce + 1));
        ps[1].xyz = nl;
        ps[2] = (float4)(beta, pb);
        wf_push(wf_queue, wf_count, WF_EXTEND, npaths, slot);
    }
}

SCALAR_BVH
__kernel void wf_shadow(const int count, const int npaths, __global float4 *wf_paths, __global const float4 *wf_shadow,
                        __global const int *wf_queue, const int nlights, SCENE_PARAMS)
{
    const int item = get_global_id(0);
    if (item >= count) return;
    const int slot = wf_queue[WF_SHADOW * npaths + item];
    __global float4 *ps = wf_paths + PATH_FLOAT4S * slot;
    for (int j = 0; j <= nlights; ++j) {
        __global const float4 *r = wf_shadow + SHADOW_FLOAT4S * (slot * (1 + nlights) + j);
        const float4 r0 = r[0], r1 = r[1];
        const int target = as_int(r1.w);
        if (target < 0 || occluded_to(r0.xyz, r1.xyz, r0.w, SCENE_ARGS)) continue;
        ps[4 + target].xyz += r[2].xyz;
    }
}

/* ref_batch[gid] (+)= the wave's estimates (first + env) env_scale + emitted, summed over k in the
 * megakernel's order, and the odd-numbered ones' luminance */
__kernel void wf_accumulate(const int n, const int first, const int wave, const int add, const float env_scale,
                            __global const float4 *wf_paths, __global float4 *ref_batch)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    float4 s = add ? ref_batch[gid] : (float4)(0.0f);
    float3 sum = s.xyz;
    float odd = s.w;
    for (int kk = 0; kk < wave; ++kk) {
        __global const float4 *ps = wf_paths + PATH_FLOAT4S * (kk * n + gid);
        const float3 est = (ps[4].xyz + ps[5].xyz) * env_scale + ps[6].xyz;
        sum += est;
        if ((uint)(first + kk) & 1u) odd += luminance(est);
    }
    ref_batch[gid] = (float4)(sum, odd);
}

#endif
