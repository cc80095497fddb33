/* Lights pass: analytic lights in the units of glTF's KHR_lights_punctual (lux for a directional
 * light, candela for point and spot lights, the spec's range window and spot falloff), shaded
 * with the IBL's BRDF (docs/conventions.md) and shadowed as each light asks, added into the
 * radiance buffer. A light seen from a point: kernels/light.h.
 *   LIGHT_DIFFUSE, LIGHT_SPECULAR  the BRDF terms the scene renders
 *   HAS_SHADOWS                    some light traces shadow rays (else none is traced)
 *   LIGHTS_EXACT                   the reference: a light of size > 0 is integrated over its
 *                                  disk (directional) or sphere by exact_samples seeded samples,
 *                                  each shaded with the paths' BSDF (kernels/bsdf.h) and, with
 *                                  VISIBILITY, traced; a mirror adds the light where its one
 *                                  direction meets it
 * Real time: the diffuse term at the light's centre direction; the specular term at the centre
 * for a light of no size, at the representative point for one with a size and hard shadows or
 * none, and for soft shadows the exact integral over the disk or sphere, by the shadows'
 * shadow_samples samples of it and as many of the GGX lobe (multiple importance sampling), each
 * traced. Hard shadows trace one ray to the centre, soft ones the disk's samples (the fraction
 * that arrives shadows the diffuse term).
 * numpy twin: iblbake/render/twin/lights.py lights(). */
#include "common.h"
#include "brdf.h"
#include "bsdf.h"
#include "sampling.h"
#include "scene.h"
#include "surface.h"
#include "light.h"

/* The specular term of a light of angular radius asin(sin_max) at its representative point
 * (Karis 2013, "Real Shading in Unreal Engine 4"): the direction of the light's disk closest to
 * the mirror direction r, with the lobe's energy scaled by (alpha / alpha')^2. Karis widens alpha
 * by the light's radius over twice its distance (sin_max / 2); over sqrt(VoH) more, the mirror
 * limit is exact (D V at the widened peak is 1 / (pi alpha'^2 4 NoV), and NoV = VoH there): the
 * highlight of a sphere light on a glossy plane seen at 17 degrees keeps 0.88-0.95 of the exact
 * integral's energy, its relative RMSE 0.20-0.31 where the centre's alone is 0.93-4.2
 * (tests/test_lights.py). Lights with hard shadows or none only: 16 samples of the disk and 16 of
 * the lobe cost 9-14x the whole hard-shadow pass (the knot, docs/benchmarks.md). *l becomes the
 * direction, the energy is returned. */
IBL_INLINE float representative_point(float3 n, float3 v, float3 *l, float sin_max, float alpha)
{
    const float3 r = 2.0f * dot(n, v) * n - v;
    const float3 c = dot(*l, r) * r - *l;            /* from the centre towards the mirror ray */
    const float cl = sqrt(dot(c, c));
    if (cl > 0.0f) *l = unit3(*l + c * fmin(sin_max / cl, 1.0f));
    const float voh = fmax(dot(v, unit3(v + *l)), 1e-4f);
    const float a = fmax(alpha, ALPHA_MIN);
    const float wide = fmin(a + 0.5f * sin_max / sqrt(voh), 1.0f);
    return (a / wide) * (a / wide);
}

/* The real-time mode's f(v, l) NoL for a light of centre direction l: the diffuse term, and with
 * `specular` the specular one, with sin_max > 0 at the representative point (a light with soft
 * shadows: the pass's estimate of the exact integral, below; the exact mode: exact_brdf_cos) */
IBL_INLINE float3 light_brdf_cos(const Material mt, float3 n, float3 v, float nov, float3 l, float sin_max, int specular)
{
    float3 f = (float3)(0.0f);
#ifdef LIGHT_DIFFUSE
    const float nol = dot(n, l);
    if (nol > 0.0f) f += diffuse_weight(mt, nov) * nol;
#endif
#ifdef LIGHT_SPECULAR
    if (!specular) return f;
    float3 ls = l;
    const float energy = sin_max > 0.0f ? representative_point(n, v, &ls, sin_max, mt.alpha) : 1.0f;
    const float nols = dot(n, ls);
    if (nols > 0.0f) {
        const float3 h = unit3(v + ls);
        f += d_ggx(dot(n, h), mt.alpha) * v_smith_ggx_correlated(nov, nols, mt.alpha) * f_schlick(dot(v, h), mt.f0, mt.f90)
             * (energy * nols);
    }
#endif
    return f;
}

#ifdef LIGHT_DIFFUSE
#define LIGHT_TERM_DIFFUSE 1
#else
#define LIGHT_TERM_DIFFUSE 0
#endif
#ifdef LIGHT_SPECULAR
#define LIGHT_TERM_SPECULAR 1
#else
#define LIGHT_TERM_SPECULAR 0
#endif

#ifdef LIGHTS_EXACT
/* f(v, l) NoL of the terms the frame renders, in the exact mode: the BSDF of every path vertex
 * (kernels/bsdf.h; its pdf unused: the light's cone is sampled). A mirror's delta lobe is met by
 * no direction the cone gives: the lights pass adds it from its one direction. */
IBL_INLINE float3 exact_brdf_cos(const Material mt, float3 n, float3 v, float nov, float3 l)
{
    float pdf;
    return bsdf_eval(mt, v, n, nov, l, 0.5f, LIGHT_TERM_DIFFUSE, LIGHT_TERM_SPECULAR, &pdf);
}
#endif

__kernel void lights(__global const float4 *gb_pos, SURFACE_PARAMS,
                     const int n, __global const float4 *lights, const int nlights,
                     SCENE_PARAMS, const int pixel0, const int spp, const uint light_seed, const int exact_samples,
                     __global float4 *radiance)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    const float4 hitp = gb_pos[gid];
    if (hitp.w == MISS_T) return;
    const uint sid = (uint)(pixel0 * spp + gid);
    Material mt;
    float3 v, nrm;
    const float nov = surface_at(SURFACE_ARGS, gid, &mt, &v, &nrm);
    const float3 p = hitp.xyz;
#if defined(HAS_SHADOWS) || (defined(LIGHTS_EXACT) && defined(VISIBILITY))
    const float3 origin = ray_offset(p, nrm, gb_dir[gid].xyz, hitp.w);
#endif
    float3 color = (float3)(0.0f);
    for (int j = 0; j < nlights; ++j) {
        float3 wc;          /* towards the centre */
        float dist, sin_max;
        const float3 e = light_toward(lights, j, p, &wc, &dist, &sin_max);     /* irradiance facing it */
        if (e.x + e.y + e.z <= 0.0f) continue;
        const uint ls = light_seed ^ pcg_hash((uint)j + 1u);
        const float omc = light_omc(sin_max);
#ifdef LIGHTS_EXACT
        if (sin_max > 0.0f) {
            /* radiance of the disk or sphere: E = Le pi sin^2 on a surface facing it */
            const float3 le = e / (IBL_PI * sin_max * sin_max);
            float3 acc = (float3)(0.0f);
            for (int k = 0; k < exact_samples; ++k) {
                Sampler sp = sampler_start(ls, sid, k);
                const float3 l = cone_direction(wc, omc, sampler_2d(&sp));
                const float3 f = exact_brdf_cos(mt, nrm, v, nov, l);
                if (f.x + f.y + f.z <= 0.0f) continue;      /* below the horizon: no ray */
#ifdef VISIBILITY
                if (occluded_to(origin, l, dist, SCENE_ARGS)) continue;
#endif
                acc += f;
            }
            color += le * (2.0f * IBL_PI * omc) * acc / (float)exact_samples;
#ifdef LIGHT_SPECULAR
            /* a mirror (alpha < DELTA_ALPHA): F(NoV) Le where its one direction falls in the cone,
             * |l - wc|^2 = 2 omc at the edge (precise for the sun's omc of 1e-5) */
            if (mt.alpha < DELTA_ALPHA) {
                float3 t, b, l;
                float pm;
                tangent_frame(nrm, &t, &b);
                const float3 fm = bsdf_sample(mt, v, nrm, t, b, nov, 1.0f, 0, 1, 0.0f, (float2)(0.0f), &l, &pm);
                const float3 dl = l - wc;
                int seen = dot(dl, dl) <= 2.0f * omc;
#ifdef VISIBILITY
                seen = seen && !occluded_to(origin, l, dist, SCENE_ARGS);
#endif
                if (seen) color += le * fm;
            }
#endif
            continue;
        }
        const float3 f = exact_brdf_cos(mt, nrm, v, nov, wc);
        if (f.x + f.y + f.z <= 0.0f) continue;
#ifdef VISIBILITY
        if (occluded_to(origin, wc, dist, SCENE_ARGS)) continue;
#endif
        color += e * f;
#else
        /* a surface the light's whole disk or sphere lies behind traces no shadow ray */
        if (dot(nrm, wc) <= -sin_max) continue;
        int soft = 0;
#ifdef HAS_SHADOWS
        const int shadows = (int)lights[LIGHT_FLOAT4S * j + 1].w;
        soft = shadows == SHADOWS_SOFT && sin_max > 0.0f;
#endif
        const int sized_specular = LIGHT_TERM_SPECULAR && soft;
        const float3 f = light_brdf_cos(mt, nrm, v, nov, wc, sin_max, !sized_specular);
        if (!sized_specular && f.x + f.y + f.z <= 0.0f) continue;     /* nothing to shadow */
        float vis = 1.0f;
#ifdef HAS_SHADOWS
        if (shadows == SHADOWS_HARD || (shadows == SHADOWS_SOFT && sin_max <= 0.0f))
            vis = occluded_to(origin, wc, dist, SCENE_ARGS) ? 0.0f : 1.0f;
#endif
#ifdef HAS_SHADOWS
        if (soft) {
            /* The soft shadows' ns rays over the disk or sphere (the share that arrives), and the
             * specular term the exact integral over it, estimated by the same ns directions of
             * the cone (pdf pd) and ns of the GGX lobe's visible normals (Heitz 2018; those that
             * land in the cone) combined by the balance heuristic (Veach 1997): sum f NoL / (ns
             * (pd + p_lobe)), each traced. A lobe narrower than the disk is met by its own
             * samples, a wider one by the cone's, a mirror's delta by its one direction; the
             * representative point keeps 0.86-0.95 of a glossy lobe's energy (docs/conventions.md,
             * adopted amendment 17). */
            const int ns = (int)lights[LIGHT_FLOAT4S * j + 3].w;
            const float pd = 1.0f / (2.0f * IBL_PI * omc);
            float3 t, b, spec = (float3)(0.0f);
            tangent_frame(nrm, &t, &b);
            int lit = 0;
            for (int k = 0; k < ns; ++k) {
                Sampler sp = sampler_start(ls, sid, k);
                const float3 l = cone_direction(wc, omc, sampler_2d(&sp));
                const int arrives = !occluded_to(origin, l, dist, SCENE_ARGS);
                lit += arrives;
                if (!sized_specular) continue;
                float pl, pll;
                const float3 fl = bsdf_eval(mt, v, nrm, nov, l, 1.0f, 0, 1, &pl);
                if (arrives) spec += fl / (pd + pl);
                float3 ll;
                const float3 w = bsdf_sample(mt, v, nrm, t, b, nov, 1.0f, 0, 1, 0.0f, sampler_2d(&sp), &ll, &pll);
                const float3 dl = ll - wc;
                if (w.x + w.y + w.z <= 0.0f || dot(dl, dl) > 2.0f * omc) continue;
                if (occluded_to(origin, ll, dist, SCENE_ARGS)) continue;
                spec += w / (1.0f + pd / pll);      /* a mirror's pdf is infinite: all of w */
            }
            vis = (float)lit / (float)ns;
            /* per unit irradiance facing the light (E = Le pi sin^2), each sample traced */
            color += e * spec / ((float)ns * IBL_PI * sin_max * sin_max);
        }
#endif
        color += vis * e * f;
#endif
    }
    radiance[gid] += (float4)(color, 0.0f);   /* lighting passes add */
}
