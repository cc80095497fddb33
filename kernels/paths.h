/* Paths (BOUNCES defined: 0 unbounded, N at most N scattering events counted from the first vertex):
 * the BSDF's sampling and evaluation at a path vertex, and follow_path, which carries a ray that has
 * met a surface on through every later bounce. Shared by the reference (kernels/reference.cl, from its
 * first vertex) and the probe baker (kernels/probe_trace.cl, from a probe).
 * numpy twin: iblbake/render/twin/paths.py. */
#ifndef IBLBAKE_PATHS_H
#define IBLBAKE_PATHS_H
#include "common.h"
#include "brdf.h"
#include "sampling.h"
#include "envmap.h"
#include "scene.h"
#include "surface.h"
#include "material.h"
#include "light.h"

#ifdef BOUNCES
/* ---------------------------------------------------------------------------- paths */

#define RR_DEPTH 3              /* bounces before Russian roulette (pbrt-v4: 1, Mitsuba 3: 5) */
#define MAX_PATH 256            /* a float-safety cap on unbounded paths: survival <= 0.95 per bounce */

/* The probability of sampling the specular lobe at a vertex: its share of the two lobes' albedos,
 * estimated by Schlick's F at NoV and the diffuse weight, kept within [0.1, 0.9] where both lobes
 * exist (so neither is starved) and 0 or 1 where one does not (specular 0, metals). */
IBL_INLINE float specular_probability(const Material mt, float nov, int diffuse, int specular)
{
    const float s = specular ? luminance(f_schlick(nov, mt.f0, mt.f90)) : 0.0f;
    const float d = diffuse ? luminance(diffuse_weight(mt, nov)) * IBL_PI : 0.0f;
    if (!(s > 0.0f)) return 0.0f;
    if (!(d > 0.0f)) return 1.0f;
    return clamp(s / (s + d), 0.1f, 0.9f);
}

/* The BSDF times NoL of the terms asked for at direction l, and its sampling pdf (the lobes mixed
 * by ps); a delta lobe (alpha < DELTA_ALPHA) adds nothing here, as no direction but its mirror
 * reaches it. */
IBL_INLINE float3 bsdf_cos(const Material mt, float3 v, float3 n, float nov, float3 l, float ps, int diffuse,
                       int specular, float *pdf)
{
    const float nol = dot(n, l);
    *pdf = 0.0f;
    if (!(nol > 0.0f)) return (float3)(0.0f);
    float3 f = (float3)(0.0f);
    if (diffuse) {
        f += diffuse_weight(mt, nov) * nol;
        *pdf += (1.0f - ps) * pdf_cosine_hemisphere(nol);
    }
    if (specular && mt.alpha >= DELTA_ALPHA) {
        const float3 hv = normalize(v + l);
        const float3 cx = cross(n, hv);
        const float noh = fmax(dot(n, hv), 0.0f), voh = fmax(dot(v, hv), 0.0f);
        const float dd = d_ggx_sc(dot(cx, cx), noh * noh, mt.alpha);
        f += f_schlick(voh, mt.f0, mt.f90) * (dd * v_smith_ggx_correlated(nov, nol, mt.alpha) * nol);
        *pdf += ps * g1_smith(nov, mt.alpha) * dd / (4.0f * nov);
    }
    return f;
}

/* A direction from the BSDF of the terms asked for: the specular lobe with probability ps (GGX
 * visible normals, or the mirror for a delta lobe), else the cosine hemisphere. Returns f NoL / pdf
 * (0 where the sample leaves the hemisphere); *pdf = INFINITY for a mirror. */
IBL_INLINE float3 bsdf_sample(const Material mt, float3 v, float3 n, float3 t, float3 b, float nov, float ps,
                          int diffuse, int specular, float u_lobe, float2 u, float3 *l, float *pdf)
{
    if (u_lobe < ps && mt.alpha < DELTA_ALPHA) {
        *l = 2.0f * nov * n - v;
        *pdf = INFINITY;
        return f_schlick(nov, mt.f0, mt.f90) / ps;
    }
    if (u_lobe < ps) {
        const float3 vl = (float3)(dot(v, t), dot(v, b), nov);
        const float3 hl = sample_ggx_vndf(vl, mt.alpha, u);
        const float3 hs = t * hl.x + b * hl.y + n * hl.z;
        *l = 2.0f * dot(v, hs) * hs - v;
    } else {
        const float3 ll = sample_cosine_hemisphere(u);
        *l = t * ll.x + b * ll.y + n * ll.z;
    }
    const float3 f = bsdf_cos(mt, v, n, nov, *l, ps, diffuse, specular, pdf);
    return *pdf > 0.0f ? f / *pdf : (float3)(0.0f);
}

/* Where a path meets a surface: the point, the shading normal bent towards the incoming ray's
 * origin, and the full material, its maps read at level 0 (a later vertex's ray cone is not
 * tracked; docs/conventions.md "Paths"). */
IBL_INLINE void path_vertex(float3 o, float3 d, Hit h, __global const float4 *materials, SCENE_PARAMS,
                       float3 *p, float3 *n, Material *mt)
{
    *p = o + h.t * d;
    float3 ng, ns;
    int m, obj;
    hit_normals(h.kind, h.index, *p, h.b1, h.b2, &ng, &ns, &m, &obj, SCENE_ARGS);
    *mt = material_at(materials, m);
#ifdef HAS_TEXTURES
    float2 density;
    float4 tw = hit_tangent(h.kind, h.index, *p, ns, h.b1, h.b2, &density, SCENE_ARGS);
    const MaterialSample s = material_sample(materials, mat_maps, TEXTURE_ARGS, m,
                                             hit_texcoords(h.kind, h.index, *p, h.b1, h.b2, SCENE_ARGS),
                                             (float2)(-INFINITY), ns, tw);
    *mt = material_from((float4)(s.base, clamp(s.metallic, 0.0f, 1.0f)),
                        (float4)(s.emissive, clamp(s.roughness, 0.0f, 1.0f)), materials[MATERIAL_FLOAT4S * m + 2]);
    ns = s.nrm;
#endif
    /* two-sided: the surface faces where the ray came from */
    if (dot(ng, d) > 0.0f) ns = -ns;
    *n = facing_normal(ns, -d);
}

/* The light a path brings back to the first vertex from direction l (after BSDF weight beta):
 * env_part the environment's radiance found on the way (times env_scale later), the return value
 * the emission met. The ray o + t l has already been traced to hit h. */
IBL_INLINE float3 follow_path(float3 o, float3 l, Hit h, float3 beta, Sampler *sp, __global const float4 *materials,
                          const float2 env_rot, __global const float4 *img, const int w, const int h_env,
                          __global const float *marginal, __global const float *conditional,
                          __global const float *pdf_table, SCENE_PARAMS, float3 *env_part,
                          __global const float4 *lights, const int nlights)
{
    float3 emitted = (float3)(0.0f), env = (float3)(0.0f);
    for (int bounce = 2; bounce <= MAX_PATH; ++bounce) {
        if (h.kind == PRIM_NONE) break;               /* the first vertex's direct estimate counted the sky */
        float3 p, n;
        Material mt;
        path_vertex(o, l, h, materials, SCENE_ARGS, &p, &n, &mt);
        emitted += beta * mt.emissive;
        if (BOUNCES > 0 && bounce > BOUNCES) break;
        const float3 v = -l;
        const float nov = fmax(dot(n, v), 1e-4f);
        const float3 origin = ray_offset(p, n, l, h.t);
        float3 t, b;
        tangent_frame(n, &t, &b);
        const float ps = specular_probability(mt, nov, 1, 1);
        const float2 u_env = sampler_2d(sp), u_texel = sampler_2d(sp), u_dir = sampler_2d(sp);
        const float u_lobe = sampler_1d(sp), u_rr = sampler_1d(sp);
        /* the environment, weighted against the BSDF's sampling */
        {
            int texel;
            const float3 le = from_env(sample_env(marginal, conditional, w, h_env, (float4)(u_env, u_texel), &texel), env_rot);
            const float pe = pdf_env(pdf_table, texel);
            float pb;
            const float3 f = bsdf_cos(mt, v, n, nov, le, ps, 1, 1, &pb);
            if (pe > 0.0f && (f.x > 0.0f || f.y > 0.0f || f.z > 0.0f) && !occluded(origin, le, SCENE_ARGS))
                env += beta * img[texel].xyz * f * (power_heuristic(pe, pb) / pe);
        }
#ifdef PATH_LIGHTS
        /* every analytic light, one direction over its disk or sphere (uniform in the cone it
         * fills) or its centre; no ray finds a light, so this is its only strategy (no MIS) */
        for (int j = 0; j < nlights; ++j) {
            float3 wc;
            float dist, sin_max;
            const float3 e = light_toward(lights, j, p, &wc, &dist, &sin_max);
            const float2 u_light = sampler_2d(sp);
            if (e.x + e.y + e.z <= 0.0f) continue;
            float3 ll = wc, le = e;
            if (sin_max > 0.0f) {          /* radiance E / (pi sin^2) over the cone's solid angle 2 pi omc */
                const float omc = light_omc(sin_max);
                ll = cone_direction(wc, omc, u_light);
                le = e * (2.0f * omc / (sin_max * sin_max));
            }
            float pl;
            const float3 f = bsdf_cos(mt, v, n, nov, ll, ps, 1, 1, &pl);
            if ((f.x > 0.0f || f.y > 0.0f || f.z > 0.0f) && !occluded_to(origin, ll, dist, SCENE_ARGS))
                emitted += beta * le * f;
        }
#endif
        /* scatter */
        float pb;
        float3 nl;
        const float3 wgt = bsdf_sample(mt, v, n, t, b, nov, ps, 1, 1, u_lobe, u_dir, &nl, &pb);
        if (!(wgt.x > 0.0f || wgt.y > 0.0f || wgt.z > 0.0f)) break;
        beta *= wgt;
        if (bounce >= RR_DEPTH) {
            const float q = fmin(fmax(beta.x, fmax(beta.y, beta.z)), 0.95f);
            if (u_rr >= q) break;
            beta /= q;
        }
        l = nl;
        o = origin;
        h = trace(o, l, SCENE_ARGS);
        if (h.kind == PRIM_NONE) {
            const int texel = env_texel_index(to_env(l, env_rot), w, h_env);
            env += beta * img[texel].xyz * (isinf(pb) ? 1.0f : power_heuristic(pb, pdf_env(pdf_table, texel)));
        }
    }
    *env_part = env;
    return emitted;
}
#endif

#endif
