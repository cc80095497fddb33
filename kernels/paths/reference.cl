/* Reference pass: progressive Monte Carlo of the exact integral of environment lighting, the
 * ground truth the approximations are measured against. The BSDF, here and at every later vertex,
 * is kernels/bsdf.h's; MIS weights are the power heuristic's (Veach 1997).
 * With BOUNCES (0: unbounded, N: at most N scattering events; path tracing, Kajiya 1986; pbrt-v4's
 * PathIntegrator, Mitsuba 3's `path`) the G-buffer sample is a path's first vertex like any other
 * (kernels/paths/paths.h): per sample the environment sampled from the panorama's tables, and one
 * direction from the BSDF of the terms the frame asks for, whose ray brings the environment where
 * it leaves the scene and continues the path where it meets a surface; every later vertex adds its
 * emission, samples the environment and every analytic light (PATH_LIGHTS), scatters with its full
 * material and continues, Russian roulette from the RR_DEPTH-th bounce on with survival
 * min(max throughput, 0.95), unbiased.
 * Without BOUNCES (the direct light, `bounces: 1`), two strategies for each term, each term alone:
 *   1. the environment, piecewise constant over the full-resolution panorama (sample_env);
 *   2. the term's BSDF: cosine hemisphere for diffuse, GGX visible normals for specular.
 * With VISIBILITY, every sample's light direction is traced for any hit (occluded(), from an
 * offset origin), so the integral is the occluded one: a sphere above a plane darkens the plane.
 *   DIFFUSE_MODE == DIFFUSE_REFERENCE, SPECULAR_MODE == SPECULAR_REFERENCE select the terms.
 * numpy twins: iblbake/render/twin/paths.py (the paths, sample for sample) and
 * iblbake/render/twin/reference.py exact() (the direct integral by quadrature over every texel). */
#include "common.h"
#include "bsdf.h"
#include "sampling.h"
#include "envmap.h"
#include "scene.h"
#include "surface.h"
/* unconditionally: a frame program places each header once, where it is first included */
#include "material.h"
#include "light.h"
#include "paths/paths.h"


#if DIFFUSE_MODE == DIFFUSE_REFERENCE
#define FIRST_DIFFUSE 1
#else
#define FIRST_DIFFUSE 0
#endif
#if SPECULAR_MODE == SPECULAR_REFERENCE
#define FIRST_SPECULAR 1
#else
#define FIRST_SPECULAR 0
#endif

#ifdef VISIBILITY
#define VISIBLE(l) (!occluded(origin, (l), SCENE_ARGS))
#else
#define VISIBLE(l) 1
#endif


/* lights, nlights: the analytic lights a path's later vertices sample (PATH_LIGHTS; the lights
 * pass lights the first vertex); a placeholder otherwise.
 * One batch of `batch` samples per G-buffer sample, shared by `slices` work items (slice s takes
 * samples s, s + slices, ...: a GPU gets enough work items from a small frame; 1 on a CPU):
 * ref_batch[s n + gid] = (sum of its estimates, sum of its odd-numbered samples' luminance).
 * Samples are numbered globally (first + k), so the frame is the same whatever the batching and
 * wherever the run stops. */
/* Intel's CPU runtime vectorises this kernel 16 work items wide where paths meet triangles, and
 * each lane's BVH traversal diverges: the knot's reference ran 2.9x slower than one work item per
 * lane (benchmarks/bench_devices.py). IBL_SCALAR_BVH (runtime.device_options, that runtime only)
 * asks for one (cl_intel_vec_len_hint): SCALAR_BVH. */
#if defined(IBL_SCALAR_BVH) && defined(HAS_TRIANGLES)
#define SCALAR_BVH __attribute__((intel_vec_len_hint(1)))
#else
#define SCALAR_BVH
#endif
SCALAR_BVH
__kernel void reference(__global const float4 *gb_pos, SURFACE_PARAMS, const int n, ENV_PARAMS,
                        SCENE_PARAMS, const int pixel0, const int spp,
                        const uint seed, const int replicates, const int first, const int batch,
                        const int slices, __global float4 *ref_batch, __global const float4 *lights,
                        const int nlights)
{
    const int item = get_global_id(0);
    if (item >= n * slices) return;
    const int gid = item % n, slice = item / n;
    /* the sample's number in the whole frame (a tile starts at pixel0): its random streams */
    const uint sid = (uint)(pixel0 * spp + gid);
    const float4 hitp = gb_pos[gid];
    if (hitp.w == MISS_T) { ref_batch[item] = (float4)(0.0f); return; }
    Material mt;
    float3 v, nrm;
    const float nov = surface_at(SURFACE_ARGS, gid, &mt, &v, &nrm);
#ifdef VISIBILITY
    const float3 origin = ray_offset(hitp.xyz, nrm, gb_dir[gid].xyz, hitp.w);
#endif
    float3 t, b;
    tangent_frame(nrm, &t, &b);
    float3 sum = (float3)(0.0f);
    float odd = 0.0f;
    for (int k = slice; k < batch; k += slices) {
        const uint sk = (uint)(first + k);
        Sampler sp = sampler_replicate(seed, sid, sk, replicates);
#ifdef BOUNCES
        /* the first vertex is a path vertex of the terms asked for: the environment sampled
         * (MIS against the BSDF), and one BSDF-sampled ray that brings the environment where it
         * leaves the scene (MIS against the environment's sampling) and the light of the surface
         * it meets where it does not (follow_path); the occlusion map, which approximates what
         * this computes, is not applied */
        const FirstVertex fv = first_vertex(mt, v, nrm, t, b, nov, FIRST_DIFFUSE, FIRST_SPECULAR, &sp, ENV_ARGS);
        float3 est = fv.env_live && !occluded(origin, fv.env_l, SCENE_ARGS) ? fv.env_c : (float3)(0.0f);
        float3 env_part = (float3)(0.0f), emitted = (float3)(0.0f);
        if (fv.live) {
            const Hit hh = trace(origin, fv.l, SCENE_ARGS);
            if (hh.kind == PRIM_NONE)
                est += fv.beta * env_missed(fv.l, fv.pdf, ENV_ARGS);
            else
                emitted = follow_path(origin, fv.l, hh, fv.beta, &sp, materials, ENV_ARGS, SCENE_ARGS, &env_part,
                                      lights, nlights);
        }
        est = (est + env_part) * env_scale + emitted;
#else
        /* the sample's numbers, in the order of its dimensions: a direction in the
         * environment's texel (its row and column), the GGX and the cosine warps, the point in
         * the texel */
        const float2 u_env = sampler_2d(&sp), u_ggx = sampler_2d(&sp), u_cos = sampler_2d(&sp),
                     u_texel = sampler_2d(&sp);
        float3 est = (float3)(0.0f);
        /* strategy 1: the environment, each term weighted against its own BSDF's sampling */
        {
            int texel;
            const float4 u = (float4)(u_env, u_texel);
            const float3 l = from_env(sample_env(marginal, conditional, guide, w, h, u, &texel), env_rot);
            const float3 li = dot(nrm, l) > 0.0f ? img[texel].xyz : (float3)(0.0f);
            const float pe = pdf_env(li, env_norm);
            if (dot(nrm, l) > 0.0f && pe > 0.0f && VISIBLE(l)) {
                float pb;
#if DIFFUSE_MODE == DIFFUSE_REFERENCE
                const float3 fd = bsdf_eval(mt, v, nrm, nov, l, 0.0f, 1, 0, &pb);
                est += li * fd * (power_heuristic(pe, pb) / pe);
#endif
#if SPECULAR_MODE == SPECULAR_REFERENCE
                const float3 fs = bsdf_eval(mt, v, nrm, nov, l, 1.0f, 0, 1, &pb);
                est += li * fs * (power_heuristic(pe, pb) / pe);
#endif
            }
        }
        /* strategy 2: each term's BSDF (the cosine hemisphere; GGX visible normals, or for a lobe
         * narrower than float32 resolves the mirror, weight F and no other strategy), weighted
         * against the environment's sampling */
#if DIFFUSE_MODE == DIFFUSE_REFERENCE
        {
            float3 l;
            float pb;
            const float3 wgt = bsdf_sample(mt, v, nrm, t, b, nov, 0.0f, 1, 0, 1.0f, u_cos, &l, &pb);
            if ((wgt.x > 0.0f || wgt.y > 0.0f || wgt.z > 0.0f) && VISIBLE(l))
                est += wgt * env_missed(l, pb, ENV_ARGS);
        }
#endif
#if SPECULAR_MODE == SPECULAR_REFERENCE
        {
            float3 l;
            float pb;
            const float3 wgt = bsdf_sample(mt, v, nrm, t, b, nov, 1.0f, 0, 1, 0.0f, u_ggx, &l, &pb);
            if ((wgt.x > 0.0f || wgt.y > 0.0f || wgt.z > 0.0f) && VISIBLE(l))
                est += wgt * env_missed(l, pb, ENV_ARGS);
        }
#endif
#ifdef HAS_OCCLUSION_MAP
        est *= env_scale * mt.occlusion;     /* the material's occlusion map: image-based light only */
#else
        est *= env_scale;
#endif
#endif
        sum += est;
        if (sk & 1u) odd += luminance(est);
    }
    ref_batch[item] = (float4)(sum, odd);
}
