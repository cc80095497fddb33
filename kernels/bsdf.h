/* The BSDF of the glTF metallic-roughness material (docs/conventions.md "Material model"), once:
 * Lambert's diffuse lobe weighted by kD, and GGX's specular lobe (height-correlated Smith V,
 * Schlick's F) sampled by its visible normals, the two mixed by the specular lobe's probability ps.
 * Every vertex of a path reads it: the reference's first vertex (kernels/paths/reference.cl, a path
 * vertex of the terms the frame asks for; without paths its direct estimate, each term alone),
 * every later vertex (kernels/paths/paths.h) and the lights' exact mode (kernels/lights.cl LIGHTS_EXACT).
 *   bsdf_eval    f NoL of the terms asked for at direction l, and the pdf of sampling l
 *   bsdf_pdf     that pdf alone
 *   bsdf_sample  a direction from the BSDF and its weight f NoL / pdf
 * `diffuse`, `specular` select the terms (the reference's first vertex computes only the terms
 * the frame asks for); ps is specular_probability's (0 for the diffuse term alone, 1 for the
 * specular one). A lobe narrower than float32 resolves (alpha < DELTA_ALPHA) is a mirror: a delta
 * that eval and pdf never meet (no direction but its mirror reaches it) and sample returns with
 * pdf INFINITY.
 * float64 twin: iblbake/core/bsdf.py (tests/test_bsdf.py holds the two together). */
#ifndef IBLBAKE_BSDF_H
#define IBLBAKE_BSDF_H
#include "common.h"
#include "ggx.h"
#include "brdf.h"
#include "sampling.h"
#include "surface.h"

/* The probability of sampling the specular lobe at a vertex: its share of the two lobes' albedos,
 * estimated by Schlick's F at NoV and the diffuse weight, kept within [0.1, 0.9] where both lobes
 * exist (so neither is starved) and 0 or 1 where one does not (specular 0, metals). The specular
 * term asked for alone is always sampled: F(NoV) is 0 for F0 = 0 seen head-on, where F(VoH) off
 * the mirror direction is not, and the panorama's compensated sampling leaves the dimmer texels
 * to the BSDF's samples (core/sampling.py env_sampling_tables). */
IBL_INLINE float specular_probability(const Material mt, float nov, int diffuse, int specular)
{
    if (!diffuse) return specular ? 1.0f : 0.0f;
    const float s = specular ? luminance(f_schlick(nov, mt.f0, mt.f90)) : 0.0f;
    const float d = luminance(diffuse_weight(mt, nov)) * IBL_PI;
    if (!(s > 0.0f)) return 0.0f;
    if (!(d > 0.0f)) return 1.0f;
    return clamp(s / (s + d), 0.1f, 0.9f);
}

/* The GGX lobe at direction l (nol = NoL > 0), the one place its half vector is spelled: returns
 * D V NoL, with *fresnel = F(VoH) (the lobe's f NoL is their product: kept apart so that a caller
 * adding it writes one multiply-add, as the paths always have) and *pdf = ps times the visible
 * normals' pdf of l, G1(v) D(h) / (4 NoV), h = normalize(v + l) (D from |n x h|^2: near-mirror
 * lobes keep their precision). */
IBL_INLINE float ggx_lobe(const Material mt, float3 v, float3 n, float nov, float3 l, float nol, float ps,
                          float3 *fresnel, float *pdf)
{
    const float3 hv = normalize(v + l);
    const float3 cx = cross(n, hv);
    const float noh = fmax(dot(n, hv), 0.0f), voh = fmax(dot(v, hv), 0.0f);
    const float dd = d_ggx_sc(dot(cx, cx), noh * noh, mt.alpha);
    *fresnel = f_schlick(voh, mt.f0, mt.f90);
    *pdf = ps * g1_smith(nov, mt.alpha) * dd / (4.0f * nov);
    return dd * v_smith_ggx_correlated(nov, nol, mt.alpha) * nol;
}

/* The BSDF times NoL of the terms asked for at direction l, and its sampling pdf (the lobes mixed
 * by ps); a delta lobe adds nothing here. */
IBL_INLINE float3 bsdf_eval(const Material mt, float3 v, float3 n, float nov, float3 l, float ps, int diffuse,
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
        float3 fr;
        float pg;
        const float dvn = ggx_lobe(mt, v, n, nov, l, nol, ps, &fr, &pg);
        f += fr * dvn;
        *pdf += pg;
    }
    return f;
}

/* The pdf with which bsdf_sample picks direction l */
IBL_INLINE float bsdf_pdf(const Material mt, float3 v, float3 n, float nov, float3 l, float ps, int diffuse,
                          int specular)
{
    float pdf;
    bsdf_eval(mt, v, n, nov, l, ps, diffuse, specular, &pdf);
    return pdf;
}

/* A direction from the BSDF of the terms asked for: the specular lobe with probability ps (GGX
 * visible normals from u, or the mirror for a delta lobe), else the cosine hemisphere from u.
 * Returns f NoL / pdf (0 where the sample leaves the hemisphere); *pdf = INFINITY for a mirror. */
IBL_INLINE float3 bsdf_sample(const Material mt, float3 v, float3 n, float3 t, float3 b, float nov, float ps,
                              int diffuse, int specular, float u_lobe, float2 u, float3 *l, float *pdf)
{
    if (u_lobe < ps && mt.alpha < DELTA_ALPHA) {
        *l = 2.0f * nov * n - v;
        *pdf = INFINITY;
        return f_schlick(nov, mt.f0, mt.f90) / ps;
    }
    if (u_lobe < ps) {
        float3 h;
        float noh;
        *l = reflect_ggx_vndf(u, t, b, n, v, (float3)(dot(v, t), dot(v, b), nov), mt.alpha, &h, &noh);
    } else {
        const float3 ll = sample_cosine_hemisphere(u);
        *l = t * ll.x + b * ll.y + n * ll.z;
    }
    const float3 f = bsdf_eval(mt, v, n, nov, *l, ps, diffuse, specular, pdf);
    return *pdf > 0.0f ? f / *pdf : (float3)(0.0f);
}

#endif
