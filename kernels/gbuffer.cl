/* G-buffer pass: the primary hit of every camera sample (pixel x spp, pixel-major), the misses
 * too (the background pass reads their directions). Records: kernels/layout.h. Defines:
 * HAS_SPHERES HAS_PLANES HAS_TRIANGLES (only the primitives the scene has are traced). */
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
__kernel void gbuffer(__constant float4 *cam, const int width, const int height, const int spp,
                      const int pixel0, const int n,
                      __global const float2 *jitter,
                      SCENE_PARAMS,
                      __global float4 *gb_pos, __global float4 *gb_nrm, __global float4 *gb_dir)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    /* a tile's samples: pixel0 is the first pixel of the tile in the frame */
    const int s = gid % spp, pix = pixel0 + gid / spp;
    float3 o, d;
    camera_ray(cam, width, height, pix % width, pix / width, jitter[s], &o, &d);
    const Hit h = trace(o, d, SCENE_ARGS);
    if (h.kind == 0) {
        gb_pos[gid] = (float4)(0.0f, 0.0f, 0.0f, MISS_T);
        gb_nrm[gid] = (float4)(0.0f, 0.0f, 0.0f, as_float(-1));
        gb_dir[gid] = (float4)(d, as_float(-1));
        return;
    }
    const float3 p = o + h.t * d;
    float3 ng, ns;
    int mat = 0, obj = 0;
    if (h.kind == 1) {
        const float4 sp = spheres[SPHERE_FLOAT4S * h.index];
        ng = (p - sp.xyz) / sp.w;
        ng = normalize(ng);
        ns = ng;
        mat = as_int(spheres[SPHERE_FLOAT4S * h.index + 1].x);
        obj = as_int(spheres[SPHERE_FLOAT4S * h.index + 1].y);
    } else if (h.kind == 2) {
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
    /* two-sided: the geometric normal faces the viewer; the shading normal follows it */
    if (dot(ng, d) > 0.0f) { ng = -ng; ns = -ns; }
    gb_pos[gid] = (float4)(p, h.t);
    gb_nrm[gid] = (float4)(ns, as_float(mat));
    gb_dir[gid] = (float4)(d, as_float(obj));
}
