/* G-buffer pass: the primary hit of every camera sample (pixel x spp, pixel-major), the misses
 * too (the background pass reads their directions). Records: kernels/layout.h. Defines:
 * HAS_SPHERES HAS_PLANES HAS_TRIANGLES (only the primitives the scene has are traced);
 * HAS_TEXTURES: each hit's texture coordinates, tangent frame and footprint too, for the material
 * pass (kernels/material.cl).
 * This file comes first in every frame program (one source of the running passes' files, each
 * header once), so its includes place the headers: the shading math before scene.h, whose
 * FP_CONTRACT OFF then holds for everything after it. Every frame has been built that way. */
#include "common.h"
#include "brdf.h"
#include "sampling.h"
#include "envmap.h"
#include "sh.h"
#include "scene.h"
#include "surface.h"

/* spheres: (centre, radius), (material, object, -, -) as ints
 * planes: 4 float4 (see hit_plane), material/object in the w of point/normal
 * tris: v0 (w: material), v1 (w: object), v2, n0, n1, n2 */
#ifdef HAS_TEXTURES
/* The hit's tangent (the direction of increasing u in the plane of the shading normal ns, before
 * any turning towards the viewer) and w, the bitangent's side (bitangent = w cross(n, t) points up
 * the image); and 0.5 log2 of each set's UV area per world area there. */
inline float4 hit_tangent(int kind, int index, float3 p, float3 ns, float b1, float b2, float2 *density, SCENE_PARAMS)
{
    float3 t;
    float w;
    if (kind == PRIM_SPHERE) {
        /* u grows as atan2(x, z) falls: t = (-z, 0, x) / |.|; up the image is +y, cross(n, t) is -y */
        const float4 sp = spheres[SPHERE_FLOAT4S * index];
        const float3 nl = (p - sp.xyz) / sp.w;
        t = (float3)(-nl.z, 0.0f, nl.x);
        w = -1.0f;
        /* du dv / dA = 1 / (2 pi^2 r^2 sin(theta)) of the panorama mapping */
        const float st = fmax(sqrt(fmax(0.0f, 1.0f - nl.y * nl.y)), 1e-4f);
        const float dens = -0.5f * log2(2.0f * IBL_PI * IBL_PI * sp.w * sp.w * st);
        *density = (float2)(dens, dens);
    } else if (kind == PRIM_PLANE) {
        /* u along the tangent, v down the bitangent; cross(n, t) = -bitangent (plane_frame) */
        __global const float4 *pl = planes + PLANE_FLOAT4S * index;
        t = pl[2].xyz;
        w = -1.0f;
        const float dens = (isinf(pl[2].w) ? 0.0f : -log2(2.0f * pl[2].w)) + (isinf(pl[3].w) ? 0.0f : -log2(2.0f * pl[3].w));
        *density = (float2)(0.5f * dens, 0.5f * dens);
    } else {
        __global const float4 *at = tri_attr + TRIANGLE_ATTR_FLOAT4S * index;
        const float4 tw = (1.0f - b1 - b2) * at[3] + b1 * at[4] + b2 * at[5];
        t = tw.xyz;
        w = at[3].w < 0.0f ? -1.0f : 1.0f;
        *density = at[6].xy;
    }
    t -= ns * dot(ns, t);
    const float lt = length(t);
    if (lt > 1e-12f) t /= lt;
    else {
        float3 b;
        tangent_frame(ns, &t, &b);
    }
    return (float4)(t, w);
}
#endif

__kernel void gbuffer(__constant float4 *cam, const int width, const int height, const int spp,
                      const int pixel0, const int n,
                      __global const float2 *jitter,
                      SCENE_PARAMS,
                      __global float4 *gb_pos, __global float4 *gb_nrm, __global float4 *gb_dir,
                      __global float4 *gb_uv, __global float4 *gb_tan, __global float4 *gb_lod)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    /* a tile's samples: pixel0 is the first pixel of the tile in the frame */
    const int s = gid % spp, pix = pixel0 + gid / spp;
    float3 o, d;
    camera_ray(cam, width, height, pix % width, pix / width, jitter[s], &o, &d);
    const Hit h = trace(o, d, SCENE_ARGS);
    if (h.kind == PRIM_NONE) {
        gb_pos[gid] = (float4)(0.0f, 0.0f, 0.0f, MISS_T);
        gb_nrm[gid] = (float4)(0.0f, 0.0f, 0.0f, as_float(-1));
        gb_dir[gid] = (float4)(d, as_float(-1));
        return;
    }
    const float3 p = o + h.t * d;
    float3 ng, ns;
    int mat = 0, obj = 0;
    if (h.kind == PRIM_SPHERE) {
        const float4 sp = spheres[SPHERE_FLOAT4S * h.index];
        ng = (p - sp.xyz) / sp.w;
        ng = normalize(ng);
        ns = ng;
        mat = as_int(spheres[SPHERE_FLOAT4S * h.index + 1].x);
        obj = as_int(spheres[SPHERE_FLOAT4S * h.index + 1].y);
    } else if (h.kind == PRIM_PLANE) {
        ng = planes[PLANE_FLOAT4S * h.index + 1].xyz;
        ns = ng;
        mat = as_int(planes[PLANE_FLOAT4S * h.index].w);
        obj = as_int(planes[PLANE_FLOAT4S * h.index + 1].w);
    } else {
        const int k = h.index;
        const float3 v0 = tris[TRIANGLE_FLOAT4S * k].xyz;
        ng = normalize(cross(tris[TRIANGLE_FLOAT4S * k + 1].xyz - v0, tris[TRIANGLE_FLOAT4S * k + 2].xyz - v0));
        const float b0 = 1.0f - h.b1 - h.b2;
        ns = b0 * tris[TRIANGLE_FLOAT4S * k + 3].xyz + h.b1 * tris[TRIANGLE_FLOAT4S * k + 4].xyz + h.b2 * tris[TRIANGLE_FLOAT4S * k + 5].xyz;
        const float ln = length(ns);
        ns = ln > 1e-12f ? ns / ln : ng;
        if (dot(ns, ng) < 0.0f) ns = -ns;
        mat = as_int(tris[TRIANGLE_FLOAT4S * k].w);
        obj = as_int(tris[TRIANGLE_FLOAT4S * k + 1].w);
    }
#ifdef HAS_TEXTURES
    float2 density;
    float4 tw = hit_tangent(h.kind, h.index, p, ns, h.b1, h.b2, &density, SCENE_ARGS);     /* the frame: normal maps */
    /* the ray cone's width at the hit (Akenine-Moller et al. 2019): a sample's share of the pixel,
     * spreading with distance for a perspective camera */
    const float pixel = 2.0f * length(cam[3].xyz) / ((float)height * sqrt((float)spp));
    const float cone = cam[0].w > 0.5f ? pixel : pixel * h.t;
    const float foot = log2(cone / fmax(fabs(dot(ng, d)), 1e-6f));
    gb_uv[gid] = hit_texcoords(h.kind, h.index, p, h.b1, h.b2, SCENE_ARGS);
    gb_lod[gid] = (float4)(foot + density.x, foot + density.y, 0.0f, 0.0f);
#endif
    /* two-sided: the geometric normal faces the viewer; the shading normal follows it (a back
     * face's whole tangent frame turns: tangent and w negate, so the bitangent keeps w cross(n, t)) */
    if (dot(ng, d) > 0.0f) {
        ng = -ng; ns = -ns;
#ifdef HAS_TEXTURES
        tw = (float4)(-tw.xyz, -tw.w);
#endif
    }
#ifdef HAS_NORMAL_MAP
    gb_tan[gid] = tw;
#endif
    gb_pos[gid] = (float4)(p, h.t);
    gb_nrm[gid] = (float4)(ns, as_float(mat));
    gb_dir[gid] = (float4)(d, as_float(obj));
}
