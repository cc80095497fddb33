/* Paths (BOUNCES defined: 0 unbounded, N at most N scattering events counted from the first vertex):
 * what every vertex of a path does, the first included: vertex_dims (its sample dimensions, one
 * order), env_direct (the environment sampled, MIS against the BSDF) and env_missed (the
 * environment a BSDF-sampled ray finds, MIS against the panorama's sampling); path_vertex, what a
 * path meets, and follow_path, which carries a ray that has met a surface on through every later
 * bounce, each vertex shaded with the material's BSDF (kernels/bsdf.h) and lit by the environment
 * (ENV_PARAMS, kernels/envmap.h) and the lights. The one path of every ray source: the
 * reference's camera samples (kernels/reference.cl, from their first vertex), the irradiance
 * probes' rays and the reflection captures' texels (kernels/probe_trace.cl, from a point;
 * iblbake/render/paths/).
 * numpy twin: iblbake/render/twin/paths.py. */
#ifndef IBLBAKE_PATHS_H
#define IBLBAKE_PATHS_H
#include "common.h"
#include "bsdf.h"
#include "sampling.h"
#include "envmap.h"
#include "scene.h"
#include "surface.h"
#include "material.h"
#include "light.h"

/* The environment a BSDF-sampled ray l (pdf pb; INFINITY for a mirror's, which no other strategy
 * finds) meets when it leaves the scene, weighted against the panorama's sampling */
IBL_INLINE float3 env_missed(float3 l, float pb, ENV_PARAMS)
{
    const int texel = env_texel_index(to_env(l, env_rot), w, h);
    return img[texel].xyz * (isinf(pb) ? 1.0f : power_heuristic(pb, pdf_env(pdf_table, texel)));
}

#ifdef BOUNCES
/* ---------------------------------------------------------------------------- paths */

#define RR_DEPTH 3              /* bounces before Russian roulette (pbrt-v4: 1, Mitsuba 3: 5) */
#define MAX_PATH 256            /* a float-safety cap on unbounded paths: survival <= 0.95 per bounce */

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

/* One vertex's sample dimensions, drawn in this order at every vertex, the first included (which
 * leaves u_rr unused: no roulette before the RR_DEPTH-th bounce) */
typedef struct {
    float4 env;                 /* the environment's texel (its row and column) and the point in it */
    float2 dir;                 /* the BSDF's direction */
    float lobe, rr;             /* the BSDF's lobe, Russian roulette */
} VertexDims;

IBL_INLINE VertexDims vertex_dims(Sampler *sp)
{
    VertexDims u;
    const float2 u_env = sampler_2d(sp), u_texel = sampler_2d(sp);
    u.env = (float4)(u_env, u_texel);
    u.dir = sampler_2d(sp);
    u.lobe = sampler_1d(sp);
    u.rr = sampler_1d(sp);
    return u;
}

/* The environment's light at a vertex by sampling the panorama (u: vertex_dims' env), weighted
 * against the BSDF's sampling of the terms asked for (power heuristic, Veach 1997): Le f NoL w / pe
 * where the direction leaves the scene unoccluded from origin. */
IBL_INLINE float3 env_direct(const Material mt, float3 v, float3 n, float nov, float3 origin, float ps, int diffuse,
                             int specular, float4 u, ENV_PARAMS, SCENE_PARAMS)
{
    int texel;
    const float3 l = from_env(sample_env(marginal, conditional, guide, w, h, u, &texel), env_rot);
    const float pe = pdf_env(pdf_table, texel);
    float pb;
    const float3 f = bsdf_eval(mt, v, n, nov, l, ps, diffuse, specular, &pb);
    if (pe > 0.0f && (f.x > 0.0f || f.y > 0.0f || f.z > 0.0f) && !occluded(origin, l, SCENE_ARGS))
        return img[texel].xyz * f * (power_heuristic(pe, pb) / pe);
    return (float3)(0.0f);
}

/* The light a path brings back to the first vertex from direction l (after BSDF weight beta):
 * env_part the environment's radiance found on the way (times env_scale later), the return value
 * the emission met. The ray o + t l has already been traced to hit h. */
IBL_INLINE float3 follow_path(float3 o, float3 l, Hit hit, float3 beta, Sampler *sp, __global const float4 *materials,
                              ENV_PARAMS, SCENE_PARAMS, float3 *env_part, __global const float4 *lights,
                              const int nlights)
{
    float3 emitted = (float3)(0.0f), env = (float3)(0.0f);
    for (int bounce = 2; bounce <= MAX_PATH; ++bounce) {
        if (hit.kind == PRIM_NONE) break;               /* the vertex before counted the sky */
        float3 p, n;
        Material mt;
        path_vertex(o, l, hit, materials, SCENE_ARGS, &p, &n, &mt);
        emitted += beta * mt.emissive;
        if (BOUNCES > 0 && bounce > BOUNCES) break;
        const float3 v = -l;
        const float nov = fmax(dot(n, v), 1e-4f);
        const float3 origin = ray_offset(p, n, l, hit.t);
        float3 t, b;
        tangent_frame(n, &t, &b);
        const float ps = specular_probability(mt, nov, 1, 1);
        const VertexDims u = vertex_dims(sp);
        env += beta * env_direct(mt, v, n, nov, origin, ps, 1, 1, u.env, ENV_ARGS, SCENE_ARGS);
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
            const float3 f = bsdf_eval(mt, v, n, nov, ll, ps, 1, 1, &pl);
            if ((f.x > 0.0f || f.y > 0.0f || f.z > 0.0f) && !occluded_to(origin, ll, dist, SCENE_ARGS))
                emitted += beta * le * f;
        }
#endif
        /* scatter */
        float pb;
        float3 nl;
        const float3 wgt = bsdf_sample(mt, v, n, t, b, nov, ps, 1, 1, u.lobe, u.dir, &nl, &pb);
        if (!(wgt.x > 0.0f || wgt.y > 0.0f || wgt.z > 0.0f)) break;
        beta *= wgt;
        if (bounce >= RR_DEPTH) {
            const float q = fmin(fmax(beta.x, fmax(beta.y, beta.z)), 0.95f);
            if (u.rr >= q) break;
            beta /= q;
        }
        l = nl;
        o = origin;
        hit = trace(o, l, SCENE_ARGS);
        if (hit.kind == PRIM_NONE) env += beta * env_missed(l, pb, ENV_ARGS);
    }
    *env_part = env;
    return emitted;
}
#endif

#endif
