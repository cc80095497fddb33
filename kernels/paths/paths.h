/* Paths (BOUNCES defined: 0 unbounded, N at most N scattering events counted from the first vertex):
 * what every vertex of a path does, the first included: vertex_dims (its sample dimensions, one
 * order), env_direct (the environment sampled, MIS against the BSDF) and env_missed (the
 * environment a BSDF-sampled ray finds, MIS against the panorama's sampling); path_vertex, what a
 * path meets, and follow_path, which carries a ray that has met a surface on through every later
 * bounce, each vertex shaded with the material's BSDF (kernels/bsdf.h) and lit by the environment
 * (ENV_PARAMS, kernels/envmap.h) and the lights. The one path of every ray source: the
 * reference's camera samples (kernels/paths/reference.cl, from their first vertex), the irradiance
 * probes' rays and the reflection captures' texels (kernels/paths/probe_trace.cl, from a point;
 * iblbake/render/paths/ trace()). Each vertex's pieces (first_vertex, vertex_start, env_draw and env_weigh
 * or the two at once, env_sample, light_sample, path_scatter) are functions of their own: an engine
 * that queues a ray instead of tracing it (a wavefront) calls them as the megakernel does.
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

/* A texel of the panorama fetched into the cache ahead of its use (IBL_PREFETCH: CPUs,
 * iblbake/device/programs.py device_options), where other work can hide the miss: a path's
 * lookups in the full-resolution panorama (the environment sample's texel, the escaped ray's)
 * miss a CPU's cache, and one work item has no other path to run meanwhile. */
IBL_INLINE void env_prefetch(int texel, __global const float4 *img)
{
#ifdef IBL_PREFETCH
    __builtin_prefetch(img + texel);
#endif
}

/* the texel env_missed reads where a ray of direction l escapes (no work where nothing is fetched) */
IBL_INLINE void env_prefetch_dir(float3 l, ENV_PARAMS)
{
#ifdef IBL_PREFETCH
    env_prefetch(env_texel_index(to_env(l, env_rot), w, h), img);
#endif
}

/* The environment a BSDF-sampled ray l (pdf pb; INFINITY for a mirror's, which no other strategy
 * finds) meets when it leaves the scene, weighted against the panorama's sampling */
IBL_INLINE float3 env_missed(float3 l, float pb, ENV_PARAMS)
{
    const float3 le = img[env_texel_index(to_env(l, env_rot), w, h)].xyz;
    return le * (isinf(pb) ? 1.0f : power_heuristic(pb, pdf_env(le, env_norm)));
}

#ifdef BOUNCES
/* ---------------------------------------------------------------------------- paths */

/* RR_DEPTH (bounces before Russian roulette) and MAX_PATH (the cap on unbounded paths): kernels/layout.h,
 * from iblbake/scene/layout.py, where the twin reads them too */

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
    /* lobe and roulette as one pair: past the first 8 dimensions both come from one scrambled
     * index (two 1d draws computed it twice), the same numbers */
    const float2 u_lr = sampler_2d(sp);
    u.lobe = u_lr.x;
    u.rr = u_lr.y;
    return u;
}

/* The environment's light at a vertex by sampling the panorama (u: vertex_dims' env), weighted
 * against the BSDF's sampling of the terms asked for (power heuristic, Veach 1997), before its
 * shadow ray, in two steps so that other work hides the texel's miss between them: env_draw, the
 * direction in the panorama and its texel (fetched meanwhile); env_weigh, the direction *l and
 * *c = Le f NoL w / pe, what arrives where it leaves the scene unoccluded; returns whether there
 * is a shadow ray to trace. env_sample: the two at once. */
typedef struct {
    float3 l;
    int texel;
} EnvDraw;

IBL_INLINE EnvDraw env_draw(float4 u, ENV_PARAMS)
{
    EnvDraw e;
    e.l = from_env(sample_env(marginal, conditional, guide, w, h, u, &e.texel), env_rot);
    env_prefetch(e.texel, img);
    return e;
}

IBL_INLINE int env_weigh(const EnvDraw e, const Material mt, float3 v, float3 n, float nov, float ps, int diffuse,
                         int specular, ENV_PARAMS, float3 *l, float3 *c)
{
    *l = e.l;
    float pb;
    const float3 f = bsdf_eval(mt, v, n, nov, e.l, ps, diffuse, specular, &pb);
    *c = (float3)(0.0f);
    if (!(f.x > 0.0f || f.y > 0.0f || f.z > 0.0f)) return 0;     /* no texel read below the horizon */
    const float3 le = img[e.texel].xyz;
    const float pe = pdf_env(le, env_norm);
    if (!(pe > 0.0f)) return 0;
    *c = le * f * (power_heuristic(pe, pb) / pe);
    return 1;
}

IBL_INLINE int env_sample(const Material mt, float3 v, float3 n, float nov, float ps, int diffuse, int specular,
                          float4 u, ENV_PARAMS, float3 *l, float3 *c)
{
    return env_weigh(env_draw(u, ENV_ARGS), mt, v, n, nov, ps, diffuse, specular, ENV_ARGS, l, c);
}

/* env_weigh's light where its direction leaves the scene unoccluded from origin */
IBL_INLINE float3 env_direct(const EnvDraw e, const Material mt, float3 v, float3 n, float nov, float3 origin, float ps,
                             int diffuse, int specular, ENV_PARAMS, SCENE_PARAMS)
{
    float3 l, c;
    if (env_weigh(e, mt, v, n, nov, ps, diffuse, specular, ENV_ARGS, &l, &c) && !occluded(origin, l, SCENE_ARGS))
        return c;
    return (float3)(0.0f);
}

/* A path's vertices, each piece once: the reference's first vertex and follow_path call these, and
 * an engine that cuts a path where a ray is traced would too, drawing the same dimensions in the
 * same order and computing the same estimate. */

/* The first vertex (the G-buffer sample; the terms asked for, diffuse and specular): its
 * dimensions, the environment sampled (env_sample's, before the shadow ray) and one BSDF sample
 * (l, its weight beta and pdf; live: a ray to trace) */
typedef struct {
    float3 env_l, env_c, l, beta;
    float pdf;
    int env_live, live;
} FirstVertex;

IBL_INLINE FirstVertex first_vertex(const Material mt, float3 v, float3 n, float3 t, float3 b, float nov, int diffuse,
                                    int specular, Sampler *sp, ENV_PARAMS)
{
    FirstVertex fv;
    const VertexDims u = vertex_dims(sp);
    const float ps = specular_probability(mt, nov, diffuse, specular);
    /* the environment's texel is fetched while the BSDF is sampled, and the texel the BSDF's ray
     * reads if it escapes while the environment's sample is weighed and its shadow ray traced
     * (the numbers do not depend on the order) */
    const EnvDraw e = env_draw(u.env, ENV_ARGS);
    fv.beta = bsdf_sample(mt, v, n, t, b, nov, ps, diffuse, specular, u.lobe, u.dir, &fv.l, &fv.pdf);
    fv.live = fv.beta.x > 0.0f || fv.beta.y > 0.0f || fv.beta.z > 0.0f;
    if (fv.live) env_prefetch_dir(fv.l, ENV_ARGS);
    fv.env_live = env_weigh(e, mt, v, n, nov, ps, diffuse, specular, ENV_ARGS, &fv.env_l, &fv.env_c);
    return fv;
}

/* A later vertex, shaded with its full material: where the ray o + t d met hit h (path_vertex),
 * the view vector, the offset origin of its rays, its frame and the specular lobe's probability */
typedef struct {
    float3 p, n, v, origin, t, b;
    float nov, ps;
    Material mt;
} PathVertex;

/* The vertex the ray o + t d meets at h; returns whether it may scatter (BOUNCES caps the
 * scattering events; its emission counts either way) */
IBL_INLINE int vertex_start(float3 o, float3 d, Hit h, int bounce, __global const float4 *materials, SCENE_PARAMS,
                            PathVertex *pv)
{
    path_vertex(o, d, h, materials, SCENE_ARGS, &pv->p, &pv->n, &pv->mt);
    pv->v = -d;
    pv->nov = fmax(dot(pv->n, pv->v), 1e-4f);
    pv->origin = ray_offset(pv->p, pv->n, d, h.t);
    tangent_frame(pv->n, &pv->t, &pv->b);
    pv->ps = specular_probability(pv->mt, pv->nov, 1, 1);
    return !(BOUNCES > 0 && bounce > BOUNCES);
}

#ifdef PATH_LIGHTS
/* Analytic light j at a later vertex: one direction over its disk or sphere (uniform in the cone
 * it fills) or its centre (*l, a shadow ray of length *dist), *c = beta E f what arrives unoccluded;
 * no ray finds a light, so this is its only strategy (no MIS). Draws the light's pair of
 * dimensions; returns whether there is a shadow ray to trace. */
IBL_INLINE int light_sample(__global const float4 *lights, int j, Sampler *sp, const PathVertex pv, float3 beta,
                            float3 *l, float *dist, float3 *c)
{
    float3 wc;
    float sin_max;
    const float3 e = light_toward(lights, j, pv.p, &wc, dist, &sin_max);
    const float2 u_light = sampler_2d(sp);
    *l = wc;
    *c = (float3)(0.0f);
    if (e.x + e.y + e.z <= 0.0f) return 0;
    float3 le = e;
    if (sin_max > 0.0f) {          /* radiance E / (pi sin^2) over the cone's solid angle 2 pi omc */
        const float omc = light_omc(sin_max);
        *l = cone_direction(wc, omc, u_light);
        le = e * (2.0f * omc / (sin_max * sin_max));
    }
    float pl;
    const float3 f = bsdf_eval(pv.mt, pv.v, pv.n, pv.nov, *l, pv.ps, 1, 1, &pl);
    *c = beta * le * f;
    return f.x > 0.0f || f.y > 0.0f || f.z > 0.0f;
}
#endif

/* Scatter at a later vertex: a direction from its BSDF (*l, pdf *pb), the throughput times its
 * weight, then Russian roulette from bounce RR_DEPTH on (survival min(max beta, 0.95), beta / q);
 * returns whether the path goes on */
IBL_INLINE int path_scatter(const PathVertex pv, const VertexDims u, int bounce, float3 *beta, float3 *l, float *pb)
{
    const float3 wgt = bsdf_sample(pv.mt, pv.v, pv.n, pv.t, pv.b, pv.nov, pv.ps, 1, 1, u.lobe, u.dir, l, pb);
    if (!(wgt.x > 0.0f || wgt.y > 0.0f || wgt.z > 0.0f)) return 0;
    *beta *= wgt;
    if (bounce >= RR_DEPTH) {
        const float q = fmin(fmax(beta->x, fmax(beta->y, beta->z)), 0.95f);
        if (u.rr >= q) return 0;
        *beta /= q;
    }
    return 1;
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
        PathVertex pv;
        const int scatters = vertex_start(o, l, hit, bounce, materials, SCENE_ARGS, &pv);
        emitted += beta * pv.mt.emissive;
        if (!scatters) break;
        const VertexDims u = vertex_dims(sp);
        /* in first_vertex's order: the panorama's texels fetched ahead (the numbers do not
         * depend on the order) */
        const EnvDraw e = env_draw(u.env, ENV_ARGS);
        float3 beta_next = beta, l_next;
        float pb;
        const int next = path_scatter(pv, u, bounce, &beta_next, &l_next, &pb);
        if (next) env_prefetch_dir(l_next, ENV_ARGS);
        env += beta * env_direct(e, pv.mt, pv.v, pv.n, pv.nov, pv.origin, pv.ps, 1, 1, ENV_ARGS, SCENE_ARGS);
#ifdef PATH_LIGHTS
        for (int j = 0; j < nlights; ++j) {         /* every analytic light */
            float3 ll, c;
            float dist;
            if (light_sample(lights, j, sp, pv, beta, &ll, &dist, &c) && !occluded_to(pv.origin, ll, dist, SCENE_ARGS))
                emitted += c;
        }
#endif
        if (!next) break;
        beta = beta_next;
        l = l_next;
        o = pv.origin;
        hit = trace(o, l, SCENE_ARGS);
        if (hit.kind == PRIM_NONE) env += beta * env_missed(l, pb, ENV_ARGS);
    }
    *env_part = env;
    return emitted;
}
#endif

#endif
