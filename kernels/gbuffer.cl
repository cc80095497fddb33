/* G-buffer pass: the primary hit of every camera sample (pixel x spp, pixel-major), the misses
 * too (the background pass reads their directions). Records: kernels/layout.h. Defines:
 * HAS_SPHERES HAS_PLANES HAS_TRIANGLES (only the primitives the scene has are traced);
 * HAS_TEXTURES: each hit's texture coordinates, tangent frame and footprint too, for the material
 * pass (kernels/material.cl); HAS_LIGHTMAP: each hit's place in the lightmap's atlas (gb_lm, kernels/lightmap.h).
 * This file comes first in every frame program (one source of the running passes' files, each
 * header once), so its includes place the headers: the shading math before scene.h, whose
 * FP_CONTRACT OFF then holds for everything after it. Every frame has been built that way. */
#include "common.h"
#include "brdf.h"
#include "sampling.h"
#include "envmap.h"
#include "sh.h"
#include "lightmap.h"
#include "scene.h"
#include "surface.h"

/* spheres: (centre, radius), (material, object, -, -) as ints
 * planes: 4 float4 (see hit_plane), material/object in the w of point/normal
 * tris: v0 (w: material), v1 (w: object), v2, n0, n1, n2 */

__kernel void gbuffer(__constant float4 *cam, const int width, const int height, const int spp,
                      const int pixel0, const int n,
                      __global const float2 *jitter,
                      SCENE_PARAMS,
                      __global float4 *gb_pos, __global float4 *gb_nrm, __global float4 *gb_dir,
                      __global float4 *gb_uv, __global float4 *gb_tan, __global float4 *gb_lod,
                      LIGHTMAP_UV_PARAMS, __global float4 *gb_lm)
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
#ifdef HAS_LIGHTMAP
        gb_lm[gid] = (float4)(0.0f);
#endif
        return;
    }
    const float3 p = o + h.t * d;
    float3 ng, ns;
    int mat, obj;
    hit_normals(h.kind, h.index, p, h.b1, h.b2, &ng, &ns, &mat, &obj, SCENE_ARGS);
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
#ifdef HAS_LIGHTMAP
    gb_lm[gid] = lightmap_uv(h.kind, h.index, p, ng, nspheres, nplanes, spheres, LIGHTMAP_UV_ARGS);
#endif
    gb_pos[gid] = (float4)(p, h.t);
    gb_nrm[gid] = (float4)(ns, as_float(mat));
    gb_dir[gid] = (float4)(d, as_float(obj));
}
