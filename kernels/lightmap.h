/* Lightmaps (`effects.diffuse: lightmap`; iblbake/render/lightmaps, docs/manual.md "Lightmaps"):
 * compiled only with HAS_LIGHTMAP. float64 twin: iblbake/render/lightmaps/read.py.
 *
 * Where a hit lies in the atlas (the G-buffer pass, gb_lm): lm_prims holds per primitive record
 * (spheres, then planes, then triangles in BVH order) the first of its atlas triangles and their
 * count (0: not lightmapped); lm_tris per atlas triangle its corners in world space and its corners'
 * UV1 in texel units (c0, c1, c2, (u0 v0 u1 v1), (u2 v2 - -)). A mesh triangle has its one atlas
 * triangle, a finite plane two, a sphere the facets of its mesh (LM_SPHERE_AROUND x LM_SPHERE_BANDS,
 * render/lightmaps/uv.py sphere_mesh): the point is projected onto a candidate's plane (along the
 * facet's normal; a sphere's point along its radius, the inverse of the bake putting texels back on
 * the sphere) and the candidate it lies inside (the least outside) gives the UV1 from its
 * barycentrics.
 *
 * What the atlas holds per texel (the shade pass): LM_ROWS float4 rows of the basis the frame reads
 *   LIGHTMAP_IRRADIANCE   the irradiance (rgb)
 *   LIGHTMAP_SH           LIGHTMAP_SH_COEFFS SH irradiance coefficients E_lm (sh.h's basis)
 *   LIGHTMAP_BASIS        a directional basis's block as the probes store one (core/bases/probes.py
 *                         PROBE_BASES pack), evaluated by its header's basis_irradiance
 *                         (kernels/bases.h, BASIS_SPACE __global)
 * read bilinearly at UV1 (texel centres at half-integers, clamped at the atlas' edges): each of the
 * four texels' irradiance at the shading normal (clamped at 0), blended.
 *   LIGHTMAP_SPECULAR     (`specular: lightmap`) lm_spec: LM_SPEC_ROWS float4 rows a texel, the
 *                         basis's second set fitted for the radiance, packed as LIGHTMAP_BASIS's
 *                         block; lightmap_specular reads the radiance along the warped lobe from it
 *                         (kernels/bases.h basis_specular_weights), bilinearly as above. */
#ifndef IBLBAKE_LIGHTMAP_H
#define IBLBAKE_LIGHTMAP_H
#include "common.h"
#include "sh.h"
#include "bases.h"
/* the kernels' parameters (bound to placeholders in a frame without a lightmap: the code reading
 * them is compiled only with HAS_LIGHTMAP) */
#define LIGHTMAP_UV_PARAMS __global const int4 *lm_prims, __global const float4 *lm_tris
#define LIGHTMAP_UV_ARGS lm_prims, lm_tris
#define LIGHTMAP_PARAMS __global const float4 *lm_atlas, const int lm_width, const int lm_height
#define LIGHTMAP_ARGS lm_atlas, lm_width, lm_height

#ifdef HAS_LIGHTMAP
#ifndef LM_ROWS
#define LM_ROWS 1             /* float4 rows a texel (the shade pass's basis; the G-buffer reads none) */
#endif

/* How far p projected onto atlas triangle k lies outside it (in barycentrics, x 1e3, plus the
 * projection's length: of the triangles it lies inside, the nearest plane), projected along the
 * triangle's normal, or with `radial` along the ray from `origin` (a sphere's centre); its UV1 in *uv. */
IBL_INLINE float lightmap_facet(__global const float4 *lm_tris, int k, float3 p, float3 origin, int radial, float2 *uv)
{
    __global const float4 *t = lm_tris + 5 * k;
    const float3 c0 = t[0].xyz, e1 = t[1].xyz - c0, e2 = t[2].xyz - c0;
    const float3 ng = cross(e1, e2);
    float3 q = p - c0;
    float dist;
    if (radial) {                       /* along the ray from the sphere's centre through p */
        const float3 d = p - origin;
        const float s = dot(ng, c0 - origin) / dot(ng, d);
        if (!(s > 0.0f)) return INFINITY;
        q = origin + d * s - c0;
        dist = fabs(s - 1.0f) * length(d);
    } else {
        const float3 nn = normalize(ng);
        const float h = dot(q, nn);
        q -= h * nn;
        dist = fabs(h);
    }
    const float d00 = dot(e1, e1), d01 = dot(e1, e2), d11 = dot(e2, e2);
    const float d20 = dot(q, e1), d21 = dot(q, e2);
    const float den = d00 * d11 - d01 * d01;
    float b1 = (d11 * d20 - d01 * d21) / den, b2 = (d00 * d21 - d01 * d20) / den;
    const float out = fmax(0.0f, -fmin(fmin(b1, b2), 1.0f - b1 - b2)) * 1e3f + dist;
    b1 = clamp(b1, 0.0f, 1.0f);
    b2 = clamp(b2, 0.0f, 1.0f);
    const float s = fmax(b1 + b2, 1.0f);
    b1 /= s;
    b2 /= s;
    *uv = (1.0f - b1 - b2) * t[3].xy + b1 * t[3].zw + b2 * t[4].xy;
    return out;
}

/* (u, v, 1, 0): UV1 in texel units of a hit on primitive (kind, index) at p, ng its geometric normal
 * towards the viewer; (0, 0, 0, 0) where it has no lightmap. */
IBL_INLINE float4 lightmap_uv(int kind, int index, float3 p, float3 ng, const int nspheres, const int nplanes,
                              __global const float4 *spheres, LIGHTMAP_UV_PARAMS)
{
    const int rec = kind == PRIM_SPHERE ? index : kind == PRIM_PLANE ? nspheres + index : nspheres + nplanes + index;
    const int4 r = lm_prims[rec];
    if (r.y <= 0) return (float4)(0.0f);
    float2 uv = (float2)(0.0f), cand;
    float best = INFINITY;
    if (kind == PRIM_SPHERE) {
        /* the facet of the mesh's band and segment, and those of the bands beside it (a ring's chord
         * seen from the centre bends towards the pole) */
        const float3 c = spheres[SPHERE_FLOAT4S * index].xyz;
        const float3 d = normalize(p - c);
        const float th = acos(clamp(d.y, -1.0f, 1.0f));
        float ph = atan2(d.z, d.x);
        if (ph < 0.0f) ph += 2.0f * M_PI_F;
        const int na = LM_SPHERE_AROUND, nb = LM_SPHERE_BANDS;
        const int band = clamp((int)(th * (float)nb / M_PI_F), 0, nb - 1);
        const int seg = clamp((int)(ph * (float)na / (2.0f * M_PI_F)), 0, na - 1);
        for (int i = max(band - 1, 0); i <= min(band + 1, nb - 1); ++i) {
            /* uv.py sphere_mesh's faces: (a, b, c) of bands 1.., then (b, d, c) of bands ..nb-2 */
            for (int tri = 0; tri < 2; ++tri) {
                if ((tri == 0 && i < 1) || (tri == 1 && i > nb - 2)) continue;
                const int k = tri == 0 ? (i - 1) * na + seg : (nb - 1) * na + i * na + seg;
                const float o = lightmap_facet(lm_tris, r.x + k, p, c, 1, &cand);
                if (o < best) { best = o; uv = cand; }
            }
        }
    } else {
        for (int k = r.x; k < r.x + r.y; ++k) {
            /* a chart facing away from the viewer last: a surface lit on both sides has one a side */
            __global const float4 *t = lm_tris + 5 * k;
            const float away = dot(cross(t[1].xyz - t[0].xyz, t[2].xyz - t[0].xyz), ng) < 0.0f ? 1e6f : 0.0f;
            const float o = lightmap_facet(lm_tris, k, p, p, 0, &cand) + away;
            if (o < best) { best = o; uv = cand; }
        }
    }
    return (float4)(uv, 1.0f, 0.0f);
}

/* One texel's irradiance at the shading normal n (world frame), clamped at 0. */
IBL_INLINE float3 lightmap_texel(__global const float4 *block, float3 n)
{
#if defined(LIGHTMAP_SH)
    float Y[SH_COEFFS];
    sh_eval(n, Y);
    float3 e = (float3)(0.0f);
    for (int k = 0; k < LIGHTMAP_SH_COEFFS; ++k) e += block[k].xyz * Y[k];
    return fmax(e, (float3)(0.0f));
#elif defined(LIGHTMAP_BASIS)
    return basis_irradiance(block, n);
#else
    return fmax(block[0].xyz, (float3)(0.0f));
#endif
}

/* The four texels around UV1 uv (texel units; centres at half-integers, clamped at the edges):
 * their indices in t and bilinear weights in w, in the order (x0 y0) (x1 y0) (x0 y1) (x1 y1). */
IBL_INLINE void lightmap_taps(float2 uv, const int lm_width, const int lm_height, int *t, float *w)
{
    const float x = uv.x - 0.5f, y = uv.y - 0.5f;
    const float fx0 = floor(x), fy0 = floor(y);
    const float fx = x - fx0, fy = y - fy0;
    const int x0 = clamp((int)fx0, 0, lm_width - 1), x1 = clamp((int)fx0 + 1, 0, lm_width - 1);
    const int y0 = clamp((int)fy0, 0, lm_height - 1), y1 = clamp((int)fy0 + 1, 0, lm_height - 1);
    t[0] = y0 * lm_width + x0; t[1] = y0 * lm_width + x1; t[2] = y1 * lm_width + x0; t[3] = y1 * lm_width + x1;
    w[0] = (1.0f - fy) * (1.0f - fx); w[1] = (1.0f - fy) * fx; w[2] = fy * (1.0f - fx); w[3] = fy * fx;
}

/* The irradiance at UV1 uv (texel units) and shading normal n: the four texels around uv, each
 * evaluated at n, blended bilinearly. */
IBL_INLINE float3 lightmap_irradiance(float2 uv, float3 n, LIGHTMAP_PARAMS)
{
    int t[4];
    float w[4];
    lightmap_taps(uv, lm_width, lm_height, t, w);
    float3 e = (float3)(0.0f);
    for (int k = 0; k < 4; ++k) e += w[k] * lightmap_texel(lm_atlas + LM_ROWS * t[k], n);
    return e;
}

#if defined(LIGHTMAP_SPECULAR) && defined(HAS_BASIS_SPECULAR)
/* The radiance along the warped GGX lobe about d (world frame) of sharpness lam_w at UV1 uv: the
 * four texels' weighted sums (clamped at 0, kernels/bases.h basis_weighted), blended bilinearly.
 * The weights once: every texel's block has the same axes and sharpness. */
IBL_INLINE float3 lightmap_specular(float2 uv, float3 d, float lam_w, __global const float *basis_table,
                                    __global const float4 *lm_spec, const int lm_width, const int lm_height)
{
    int t[4];
    float w[4], s[BASIS_SPECULAR_ROWS];
    lightmap_taps(uv, lm_width, lm_height, t, w);
    basis_specular_weights(lm_spec + LM_SPEC_ROWS * t[0], basis_table, d, lam_w, s);
    float3 li = (float3)(0.0f);
    for (int k = 0; k < 4; ++k) li += w[k] * basis_weighted(lm_spec + LM_SPEC_ROWS * t[k], s);
    return li;
}
#endif

#endif
#endif
