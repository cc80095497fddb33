/* The scene's geometry on the device: camera rays, ray-primitive tests, a BVH over triangles, the
 * closest hit (trace) and any hit (occluded) along a ray. Buffer layouts: kernels/layout.h.
 * numpy twin: iblbake/render/twin/gbuffer.py (primary, occluded). */
#ifndef IBLBAKE_SCENE_H
#define IBLBAKE_SCENE_H
#include "common.h"
#include "layout.h"
#include "texture.h"

/* The geometry buffers every tracing kernel takes, by name (the host binds them from its table).
 * tri_attr, mat_maps and the textures are read only where a material cuts out (HAS_ALPHA_MASK) or
 * has one side (HAS_SINGLE_SIDED); a scene without either binds placeholders. */
#define GEOMETRY_PARAMS __global const float4 *spheres, const int nspheres, \
                        __global const float4 *planes, const int nplanes, \
                        __global const float4 *bvh, __global const float4 *tris, const int ntris, \
                        __global const float4 *tri_attr, __global const float4 *mat_maps, TEXTURE_PARAMS
#define GEOMETRY_ARGS spheres, nspheres, planes, nplanes, bvh, tris, ntris, tri_attr, mat_maps, TEXTURE_ARGS
/* PROFILE_RAYS (the reference's path profile only, iblbake/render/paths/profile.py): every ray
 * traced is recorded (1) or answered from that record without traversal (2), through two more
 * buffers that every function tracing rays passes on. The host reads the last definitions below
 * (device/programs.py kernel_params): kernels built without it have the signatures they always had. */
#ifdef PROFILE_RAYS
#define SCENE_PARAMS GEOMETRY_PARAMS, __global float4 *prof_rays, __global int *prof_index
#define SCENE_ARGS GEOMETRY_ARGS, prof_rays, prof_index
#else
#define SCENE_PARAMS GEOMETRY_PARAMS
#define SCENE_ARGS GEOMETRY_ARGS
#endif

/* ---------------------------------------------------------------------------- camera, rays */

/* cam[0] origin (w: 1 orthographic, 0 perspective), cam[1] forward, cam[2] right and cam[3] up,
 * scaled to half the view's width and height (at distance 1 for perspective). */
IBL_INLINE void camera_ray(__constant float4 *cam, int width, int height, int px, int py, float2 jitter,
                       float3 *o, float3 *d)
{
    const float sx = 2.0f * ((float)px + jitter.x) / (float)width - 1.0f;
    const float sy = 1.0f - 2.0f * ((float)py + jitter.y) / (float)height;
    if (cam[0].w > 0.5f) {
        *o = cam[0].xyz + sx * cam[2].xyz + sy * cam[3].xyz;
        *d = cam[1].xyz;
    } else {
        *o = cam[0].xyz;
        *d = normalize(cam[1].xyz + sx * cam[2].xyz + sy * cam[3].xyz);
    }
}

/* ---------------------------------------------------------------------------- intersection */

/* Nearest t > tmin of a ray with a sphere; the numerically stable quadratic (Haines et al.,
 * Ray Tracing Gems ch. 7): the discriminant from the perpendicular distance, no cancellation. */
IBL_INLINE float hit_sphere(float3 o, float3 d, float4 s, float tmin, float tmax)
{
    const float3 f = o - s.xyz;
    const float b = -dot(f, d);
    const float3 perp = f + b * d;
    const float disc = s.w * s.w - dot(perp, perp);
    if (disc < 0.0f) return tmax;
    const float q = b + copysign(sqrt(disc), b);
    const float c = dot(f, f) - s.w * s.w;
    float t0 = q != 0.0f ? c / q : 0.0f, t1 = q;
    if (t0 > t1) { float x = t0; t0 = t1; t1 = x; }
    if (t0 > tmin && t0 < tmax) return t0;
    if (t1 > tmin && t1 < tmax) return t1;
    return tmax;
}

/* plane: point.xyz, normal.xyz, tangent.xyz (w: half width), bitangent.xyz (w: half depth), flags */
IBL_INLINE float hit_plane(float3 o, float3 d, __global const float4 *pl, float tmin, float tmax)
{
    const float3 n = pl[1].xyz;
    const float den = dot(d, n);
    if (fabs(den) < 1e-20f) return tmax;
    const float t = dot(pl[0].xyz - o, n) / den;
    if (!(t > tmin && t < tmax)) return tmax;
    const float3 q = o + t * d - pl[0].xyz;
    if (fabs(dot(q, pl[2].xyz)) > pl[2].w || fabs(dot(q, pl[3].xyz)) > pl[3].w) return tmax;
    return t;
}

IBL_INLINE float component(float3 v, int k) { return k == 0 ? v.x : (k == 1 ? v.y : v.z); }

/* Per-ray setup of the watertight ray-triangle test (Woop, Benthin and Wald 2013): the axis
 * where the direction is largest becomes z, and a shear maps the ray onto +z. */
typedef struct { int kx, ky, kz; float sx, sy, sz; } RayShear;

IBL_INLINE RayShear ray_shear(float3 d)
{
    const float3 a = fabs(d);
    RayShear r;
    r.kz = a.x > a.y ? (a.x > a.z ? 0 : 2) : (a.y > a.z ? 1 : 2);
    r.kx = r.kz == 2 ? 0 : r.kz + 1;
    r.ky = r.kx == 2 ? 0 : r.kx + 1;
    const float dz = component(d, r.kz);
    if (dz < 0.0f) { const int t = r.kx; r.kx = r.ky; r.ky = t; }   /* keep the winding */
    r.sx = component(d, r.kx) / dz;
    r.sy = component(d, r.ky) / dz;
    r.sz = 1.0f / dz;
    return r;
}

/* The triangles' and the boxes' tests of the two BVH layouts (scene/bvh.py): the 4-wide tree on a
 * CPU, whose float4 lanes are SIMD there, the binary tree on a GPU, where the wide one's private
 * arrays and lanes cost more than its fewer nodes save (IBL_WIDE_BVH: iblbake/device/programs.py
 * device_options; docs/benchmarks.md "A 4-wide BVH"). FP_CONTRACT OFF keeps a*b - c*d unfused,
 * which the watertight test's exact antisymmetry needs. */
#pragma OPENCL FP_CONTRACT OFF
#ifdef IBL_WIDE_BVH
/* Watertight test on the corners themselves, of a BVH leaf's up to four triangles at once (lf:
 * its record, kernels/layout.h BVH_LEAF, the corners by coordinate, a lane a triangle; okx, oky,
 * okz: the ray's origin on the sheared axes): each edge function depends only on its two corners
 * (bit-identical in the triangles that share them) and flips sign exactly between the two, so a
 * ray through a shared edge hits at least one of the triangles (Moller-Trumbore on per-triangle
 * edge vectors let a few rays through). Returns each lane's t (*in: whether it hits in (tmin, tmax)) and the
 * barycentrics of v1 and v2. A missing triangle's lanes are zero: det 0, no hit. */
IBL_INLINE float4 hit_leaf(__global const float4 *lf, RayShear rs, float okx, float oky, float okz, float tmin,
                           float tmax, float4 *b1, float4 *b2, int4 *in)
{
    const float4 az = lf[rs.kz] - okz, bz = lf[3 + rs.kz] - okz, cz = lf[6 + rs.kz] - okz;
    const float4 ax = (lf[rs.kx] - okx) - rs.sx * az, ay = (lf[rs.ky] - oky) - rs.sy * az;
    const float4 bx = (lf[3 + rs.kx] - okx) - rs.sx * bz, by = (lf[3 + rs.ky] - oky) - rs.sy * bz;
    const float4 cx = (lf[6 + rs.kx] - okx) - rs.sx * cz, cy = (lf[6 + rs.ky] - oky) - rs.sy * cz;
    const float4 u = cx * by - cy * bx, v = ax * cy - ay * cx, w = bx * ay - by * ax;
    const float4 det = u + v + w;
    const float4 t = rs.sz * (u * az + v * bz + w * cz) / det;
    *in = ((u >= 0.0f & v >= 0.0f & w >= 0.0f) | (u <= 0.0f & v <= 0.0f & w <= 0.0f)) & det != 0.0f & t > tmin
          & t < tmax;
    *b1 = v / det;
    *b2 = w / det;
    return t;
}
#else
/* The same watertight test of one triangle (the binary tree's leaves), the same operations in the
 * same order: the two layouts meet the same triangles at the same t, bit for bit. Returns t and
 * the barycentrics of v1 and v2. */
IBL_INLINE float hit_triangle(float3 o, RayShear rs, float3 v0, float3 v1, float3 v2, float tmin, float tmax,
                          float *b1, float *b2)
{
    const float3 A = v0 - o, B = v1 - o, C = v2 - o;
    const float az = component(A, rs.kz), bz = component(B, rs.kz), cz = component(C, rs.kz);
    const float ax = component(A, rs.kx) - rs.sx * az, ay = component(A, rs.ky) - rs.sy * az;
    const float bx = component(B, rs.kx) - rs.sx * bz, by = component(B, rs.ky) - rs.sy * bz;
    const float cx = component(C, rs.kx) - rs.sx * cz, cy = component(C, rs.ky) - rs.sy * cz;
    const float u = cx * by - cy * bx, v = ax * cy - ay * cx, w = bx * ay - by * ax;
    if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return tmax;
    const float det = u + v + w;
    if (det == 0.0f) return tmax;
    const float t = rs.sz * (u * az + v * bz + w * cz) / det;
    if (!(t > tmin && t < tmax)) return tmax;
    *b1 = v / det; *b2 = w / det;
    return t;
}

IBL_INLINE int box_hit(float3 o, float3 inv_d, float3 bmin, float3 bmax, float tmax, float *tnear)
{
    const float3 t0 = (bmin - o) * inv_d, t1 = (bmax - o) * inv_d;
    const float3 lo = fmin(t0, t1), hi = fmax(t0, t1);
    const float a = fmax(fmax(lo.x, lo.y), fmax(lo.z, 0.0f));
    /* far bound widened by 2 gamma(3) (Ize 2013): rounding never drops a box a ray grazes */
    const float b = fmin(fmin(hi.x, hi.y), fmin(hi.z, tmax)) * 1.0000004f;
    *tnear = a;
    return a <= b;
}

/* The binary traversal's next node from its stack of (node, bits of its entry distance), -1 when
 * none is left: a closest-hit ray drops the entries that begin beyond its nearest hit t. */
IBL_INLINE int bvh_pop(const int2 *stack, int *sp, int any_hit, float t)
{
    while (*sp > 0) {
        const int2 e = stack[--*sp];
        if (any_hit || as_float(e.y) <= t * 1.0000004f) return e.x;
    }
    return -1;
}
#endif

typedef struct {
    float t;
    int kind;      /* PRIM_NONE, PRIM_SPHERE, PRIM_PLANE, PRIM_TRIANGLE (layout.h) */
    int index;
    float b1, b2;
} Hit;

/* ---------------------------------------------------------------------------- surface coordinates */

/* A hit's material and geometric normal (unit; a triangle's by its winding, counter-clockwise in
 * front), before any turning towards the viewer. */
IBL_INLINE int hit_material(int kind, int index, float3 p, float3 *ng, SCENE_PARAMS)
{
    if (kind == PRIM_SPHERE) {
        const float4 sp = spheres[SPHERE_FLOAT4S * index];
        *ng = normalize((p - sp.xyz) / sp.w);
        return as_int(spheres[SPHERE_FLOAT4S * index + 1].x);
    }
    if (kind == PRIM_PLANE) {
        *ng = planes[PLANE_FLOAT4S * index + 1].xyz;
        return as_int(planes[PLANE_FLOAT4S * index].w);
    }
    const float3 v0 = tris[TRIANGLE_FLOAT4S * index].xyz;
    *ng = normalize(cross(tris[TRIANGLE_FLOAT4S * index + 1].xyz - v0, tris[TRIANGLE_FLOAT4S * index + 2].xyz - v0));
    return as_int(tris[TRIANGLE_FLOAT4S * index].w);
}

/* The object a hit belongs to (objects.N of the scene) */
IBL_INLINE int hit_object(int kind, int index, SCENE_PARAMS)
{
    if (kind == PRIM_SPHERE) return as_int(spheres[SPHERE_FLOAT4S * index + 1].y);
    if (kind == PRIM_PLANE) return as_int(planes[PLANE_FLOAT4S * index + 1].w);
    return as_int(tris[TRIANGLE_FLOAT4S * index + 1].w);
}

/* A hit's geometric normal (unit; a triangle's by its winding) and shading normal (a triangle's
 * interpolated from its corners, on the geometric normal's side), before any turning towards the
 * viewer; its material and object. The G-buffer's primary hits and the reference's path vertices. */
IBL_INLINE void hit_normals(int kind, int index, float3 p, float b1, float b2, float3 *ng, float3 *ns, int *mat,
                        int *obj, SCENE_PARAMS)
{
    if (kind == PRIM_SPHERE) {
        const float4 sp = spheres[SPHERE_FLOAT4S * index];
        *ng = normalize((p - sp.xyz) / sp.w);
        *ns = *ng;
        *mat = as_int(spheres[SPHERE_FLOAT4S * index + 1].x);
        *obj = as_int(spheres[SPHERE_FLOAT4S * index + 1].y);
    } else if (kind == PRIM_PLANE) {
        *ng = planes[PLANE_FLOAT4S * index + 1].xyz;
        *ns = *ng;
        *mat = as_int(planes[PLANE_FLOAT4S * index].w);
        *obj = as_int(planes[PLANE_FLOAT4S * index + 1].w);
    } else {
        const int k = index;
        const float3 v0 = tris[TRIANGLE_FLOAT4S * k].xyz;
        *ng = normalize(cross(tris[TRIANGLE_FLOAT4S * k + 1].xyz - v0, tris[TRIANGLE_FLOAT4S * k + 2].xyz - v0));
        const float b0 = 1.0f - b1 - b2;
        float3 n = b0 * tris[TRIANGLE_FLOAT4S * k + 3].xyz + b1 * tris[TRIANGLE_FLOAT4S * k + 4].xyz
                   + b2 * tris[TRIANGLE_FLOAT4S * k + 5].xyz;
        const float ln = length(n);
        n = ln > 1e-12f ? n / ln : *ng;
        *ns = dot(n, *ng) < 0.0f ? -n : n;
        *mat = as_int(tris[TRIANGLE_FLOAT4S * k].w);
        *obj = as_int(tris[TRIANGLE_FLOAT4S * k + 1].w);
    }
}

/* Texture coordinates (u0, v0, u1, v1) at a hit, v down the image as glTF's: a triangle's
 * interpolated from its corners; a sphere's the panorama mapping of its normal (docs/conventions.md:
 * u = 0.5 - atan2(x, z) / 2 pi, v = acos(y) / pi); a plane's across its width (tangent) and up its
 * depth (bitangent), [0, 1] over a finite plane, one per unit on an infinite one. Both sets alike
 * on spheres and planes. */
IBL_INLINE float4 hit_texcoords(int kind, int index, float3 p, float b1, float b2, SCENE_PARAMS)
{
    if (kind == PRIM_SPHERE) {
        const float4 sp = spheres[SPHERE_FLOAT4S * index];
        const float3 n = (p - sp.xyz) / sp.w;
        const float2 uv = equirect_uv_from_dir(n);
        return (float4)(uv, uv);
    }
    if (kind == PRIM_PLANE) {
        __global const float4 *pl = planes + PLANE_FLOAT4S * index;
        const float3 q = p - pl[0].xyz;
        const float a = dot(q, pl[2].xyz), b = dot(q, pl[3].xyz);
        const float hw = pl[2].w, hd = pl[3].w;
        const float u = isinf(hw) ? a : 0.5f + 0.5f * a / hw, v = isinf(hd) ? -b : 0.5f - 0.5f * b / hd;
        return (float4)(u, v, u, v);
    }
    __global const float4 *at = tri_attr + TRIANGLE_ATTR_FLOAT4S * index;
    return (1.0f - b1 - b2) * at[0] + b1 * at[1] + b2 * at[2];
}

#ifdef HAS_TEXTURES
/* The hit's tangent (the direction of increasing u in the plane of the shading normal ns, before
 * any turning towards the viewer) and w, the bitangent's side (bitangent = w cross(n, t) points up
 * the image); and 0.5 log2 of each set's UV area per world area there. */
IBL_INLINE float4 hit_tangent(int kind, int index, float3 p, float3 ns, float b1, float b2, float2 *density, SCENE_PARAMS)
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

/* A primitive's SURFACE_FLAGS (layout.h): what its material asks of every hit, and whether it
 * bounds a solid */
IBL_INLINE int surface_flags(int kind, int index, SCENE_PARAMS)
{
    if (kind == PRIM_SPHERE) return as_int(spheres[SPHERE_FLOAT4S * index + 1].z);
    if (kind == PRIM_PLANE) return as_int(planes[PLANE_FLOAT4S * index + 4].x);
    return as_int(tris[TRIANGLE_FLOAT4S * index + 2].w);
}

/* Whether an irradiance probe's ray that meets this hit (geometric normal ng, by the winding) from
 * direction d sees a back face, the probe being inside geometry (docs/conventions.md "Sides"): the
 * inside of a solid (a sphere, a closed mesh: by its volume where double-sided, flipped where
 * wound inwards; by its winding where single-sided). An open surface is a front face from either
 * side where double-sided, and not there from behind where single-sided (the ray passes, as every
 * ray does). */
IBL_INLINE int probe_back_face(int kind, int index, float3 ng, float3 d, SCENE_PARAMS)
{
    const int f = surface_flags(kind, index, SCENE_ARGS);
    const float s = dot(ng, d);
    if (f & SURFACE_SOLID) return (f & SURFACE_SOLID_FLIPPED) ? s < 0.0f : s > 0.0f;
    return (f & SURFACE_SINGLE_SIDED) && s > 0.0f;
}

#if defined(HAS_ALPHA_MASK) || defined(HAS_SINGLE_SIDED)
/* Whether a candidate hit is there at all: a single-sided material's back face is not (cull 1:
 * every ray of the renderer; cull 2: an irradiance probe's, which sees a solid's back faces), nor
 * where a masked material's alpha (its factor times the base map's alpha at level 0, as an any-hit
 * shader reads it) is below its cutoff. */
IBL_INLINE int surface_present(int kind, int index, float3 o, float3 d, float t, float b1, float b2, int cull,
                           SCENE_PARAMS)
{
    const float3 p = o + t * d;
    float3 ng;
    const int m = hit_material(kind, index, p, &ng, SCENE_ARGS);
    __global const float4 *mm = mat_maps + MATERIAL_MAPS_FLOAT4S * m;
#ifdef HAS_SINGLE_SIDED
    if (cull && mm[1].x > 0.5f && dot(ng, d) > 0.0f
        && !(cull == 2 && (surface_flags(kind, index, SCENE_ARGS) & SURFACE_SOLID))) return 0;
#endif
#ifdef HAS_ALPHA_MASK
    const float cutoff = mm[0].y;
    if (cutoff >= 0.0f) {
        float alpha = mm[0].x;
        __global const float4 *slot = map_slot(mat_maps, m, MAP_BASE_COLOR);
        if (map_texture(slot) >= 0)
            alpha *= texture_sample(TEXTURE_ARGS, map_texture(slot),
                                    map_uv(slot, hit_texcoords(kind, index, p, b1, b2, SCENE_ARGS)), 0.0f).w;
        if (alpha < cutoff) return 0;
    }
#endif
    return 1;
}
/* only where the primitive's material asks */
#define PRESENT(kind, index, t, b1, b2) \
    ((surface_flags(kind, index, SCENE_ARGS) & (SURFACE_SINGLE_SIDED | SURFACE_ALPHA_MASK)) == 0 \
     || surface_present(kind, index, o, d, t, b1, b2, cull, SCENE_ARGS))
#define ABSENT(kind, index, t, b1, b2) (!PRESENT(kind, index, t, b1, b2))
#else
#define PRESENT(kind, index, t, b1, b2) 1
#define ABSENT(kind, index, t, b1, b2) 0     /* not !1: clang warns of '&&' with a constant operand */
#endif

/* The nearest hit in (tmin, tmax), or with any_hit the first one found (a shadow ray needs no
 * more): h.kind = PRIM_NONE where there is none. cull 1: single-sided surfaces are not there from
 * behind (every ray of the renderer); 2: but for solids' (an irradiance probe meets a closed
 * single-sided mesh's inside); 0: they are. */
IBL_INLINE Hit trace_range(float3 o, float3 d, float tmin, float tmax, int any_hit, int cull, SCENE_PARAMS)
{
    Hit h;
    h.t = tmax; h.kind = PRIM_NONE; h.index = -1; h.b1 = 0.0f; h.b2 = 0.0f;
#ifdef HAS_SPHERES
    for (int i = 0; i < nspheres; ++i) {
        float t = hit_sphere(o, d, spheres[2 * i], tmin, h.t);
        if (t < h.t && ABSENT(PRIM_SPHERE, i, t, 0.0f, 0.0f)) {    /* cut out or a back face: the far side */
            t = hit_sphere(o, d, spheres[2 * i], t, h.t);
            if (t < h.t && ABSENT(PRIM_SPHERE, i, t, 0.0f, 0.0f)) t = h.t;
        }
        if (t < h.t) { h.t = t; h.kind = PRIM_SPHERE; h.index = i; if (any_hit) return h; }
    }
#endif
#ifdef HAS_PLANES
    for (int i = 0; i < nplanes; ++i) {
        const float t = hit_plane(o, d, planes + PLANE_FLOAT4S * i, tmin, h.t);
        if (t < h.t && PRESENT(PRIM_PLANE, i, t, 0.0f, 0.0f)) { h.t = t; h.kind = PRIM_PLANE; h.index = i; if (any_hit) return h; }
    }
#endif
#ifdef HAS_TRIANGLES
    if (ntris > 0) {
        /* +-inf components of 1/d are fine for the slab test; exact zeros become huge */
        const float3 inv_d = (float3)(1.0f / (d.x != 0.0f ? d.x : 1e-30f), 1.0f / (d.y != 0.0f ? d.y : 1e-30f),
                                      1.0f / (d.z != 0.0f ? d.z : 1e-30f));
        const RayShear rs = ray_shear(d);
#ifdef IBL_WIDE_BVH
        /* A wide node (scene/bvh.py widen) holds four children's boxes a lane each: one float4
         * slab test meets all four (the near plane per axis chosen by the ray's sign, as Embree
         * does: an empty child's (+inf, -inf) box is then missed on every axis). A child is
         * pushed only when the ray meets its box, with its entry distance, nearest last so it is
         * popped first: a shadow ray pops without a second box test (its tmax never shrinks), a
         * closest-hit ray only checks that entry against the nearest hit found since. The far
         * bound is widened by 2 gamma(3) (Ize 2013): rounding never drops a box a ray grazes.
         * The stack holds every tree the builder makes (scene/bvh.py widen bounds its depth). */
        const int nx = inv_d.x >= 0.0f ? 0 : 3, ny = inv_d.y >= 0.0f ? 1 : 4, nz = inv_d.z >= 0.0f ? 2 : 5;
        const float okx = component(o, rs.kx), oky = component(o, rs.ky), okz = component(o, rs.kz);
        int stack[BVH_STACK];
        float near[BVH_STACK];
        stack[0] = 0; near[0] = 0.0f;
        int sp = 1;
        while (sp > 0) {
            --sp;
            if (!any_hit && near[sp] > h.t * 1.0000004f) continue;
            const int code = stack[sp];
            if (code < 0) {
                /* a leaf: its triangles tested a lane each, then taken in order */
                __global const float4 *lf = bvh + (-1 - code);
                float4 b1, b2;
                int4 in;
                const float4 t = hit_leaf(lf, rs, okx, oky, okz, tmin, h.t, &b1, &b2, &in);
                if (!any(in)) continue;
                float tl[4], b1l[4], b2l[4];
                int inl[4];
                vstore4(t, 0, tl); vstore4(b1, 0, b1l); vstore4(b2, 0, b2l); vstore4(in, 0, inl);
                const int first = as_int(lf[9].x), count = as_int(lf[9].y);
                for (int j = 0; j < count; ++j) {
                    if (inl[j] && tl[j] < h.t && PRESENT(PRIM_TRIANGLE, first + j, tl[j], b1l[j], b2l[j])) {
                        h.t = tl[j]; h.kind = PRIM_TRIANGLE; h.index = first + j; h.b1 = b1l[j]; h.b2 = b2l[j];
                        if (any_hit) return h;
                    }
                }
                continue;
            }
            __global const float4 *node = bvh + BVH4_NODE_FLOAT4S * code;
            const float4 t0 = fmax(fmax((node[nx] - o.x) * inv_d.x, (node[ny] - o.y) * inv_d.y),
                                   fmax((node[nz] - o.z) * inv_d.z, (float4)(0.0f)));
            const float4 t1 = fmin(fmin((node[3 - nx] - o.x) * inv_d.x, (node[5 - ny] - o.y) * inv_d.y),
                                   fmin((node[7 - nz] - o.z) * inv_d.z, (float4)(h.t))) * 1.0000004f;
            const int4 met = t0 <= t1;
            const int mask = (met.x & 1) | (met.y & 2) | (met.z & 4) | (met.w & 8);
            if (!mask) continue;
            float tn[4];
            int child[4];
            vstore4(t0, 0, tn);
            vstore4(as_int4(node[6]), 0, child);
            /* insertion: the entries pushed here stay sorted, farthest deepest */
            const int base = sp;
            for (int j = 0; j < 4; ++j) {
                if (!((mask >> j) & 1)) continue;
                const float tj = tn[j];
                int i = sp++;
                while (i > base && near[i - 1] < tj) { stack[i] = stack[i - 1]; near[i] = near[i - 1]; --i; }
                stack[i] = child[j]; near[i] = tj;
            }
        }
#else
        /* A node is pushed only when the ray meets its box, with its entry distance: a shadow ray
         * pops without a second box test (its tmax never shrinks), a closest-hit ray only checks
         * that entry against the nearest hit found since (the same test, as box_hit's near bound
         * is the entry and its far bound the widened min of the slabs' and tmax). Where both
         * children are met the nearer is gone to at once and only the farther pushed: the order
         * is that of pushing both and popping the nearer (so the same hits, bit for bit), one
         * store and load fewer of the private stack a GPU keeps in local memory; an entry is
         * (node, bits of its entry distance), one 8-byte store. Inner nodes are stepped through
         * in a loop of their own, then a leaf's triangles tested ("while-while", Aila and Laine
         * 2009): a warp's threads walk inner nodes together instead of each turn serialising one
         * thread's node and another's leaf: on an H200 the knot 1.10x, the textured torus 1.14x
         * faster (docs/benchmarks.md "While-while on the GPU"). */
        int2 stack[64];
        int sp = 0;
        float tn;
        int ni = box_hit(o, inv_d, bvh[0].xyz, bvh[1].xyz, h.t, &tn) ? 0 : -1;
        while (ni >= 0) {
            float4 a = bvh[2 * ni], b = bvh[2 * ni + 1];
            /* inner nodes, until a leaf is reached or the stack runs out */
            while (as_int(b.w) == 0) {
                const int first = as_int(a.w);
                const float4 la = bvh[2 * first], lb = bvh[2 * first + 1];
                const float4 ra = bvh[2 * first + 2], rb = bvh[2 * first + 3];
                float tl, tr;
                const int hl = box_hit(o, inv_d, la.xyz, lb.xyz, h.t, &tl);
                const int hr = box_hit(o, inv_d, ra.xyz, rb.xyz, h.t, &tr);
                if (hl && hr) {
                    const int near_left = tl <= tr;
                    ni = near_left ? first : first + 1;
                    if (sp < 64) stack[sp++] = near_left ? (int2)(first + 1, as_int(tr)) : (int2)(first, as_int(tl));
                } else ni = hl ? first : (hr ? first + 1 : -1);
                if (ni < 0) ni = bvh_pop(stack, &sp, any_hit, h.t);
                if (ni < 0) break;
                a = bvh[2 * ni]; b = bvh[2 * ni + 1];
            }
            if (ni < 0) break;
            /* a leaf */
            const int count = as_int(b.w), first = as_int(a.w);
            for (int k = first; k < first + count; ++k) {
                float b1, b2;
                const float t = hit_triangle(o, rs, tris[6 * k].xyz, tris[6 * k + 1].xyz, tris[6 * k + 2].xyz,
                                             tmin, h.t, &b1, &b2);
                if (t < h.t && PRESENT(PRIM_TRIANGLE, k, t, b1, b2)) {
                    h.t = t; h.kind = PRIM_TRIANGLE; h.index = k; h.b1 = b1; h.b2 = b2;
                    if (any_hit) return h;
                }
            }
            ni = bvh_pop(stack, &sp, any_hit, h.t);
        }
#endif
    }
#endif
    return h;
}

#ifdef PROFILE_RAYS
/* A ray of the path profile. prof_index holds 8 ints per work item: its first record in
 * prof_rays, the rays it has traced, the records it has room for, the path vertex it is at, and
 * the bits of its first ray's origin (the first vertex's: every ray from there leaves vertex 1;
 * each closest-hit ray moves the path on a vertex). A record is 3 float4: (origin, tmax),
 * (direction, any_hit | hit kind << 1 | vertex << 4), (t, b1, b2, index). PROFILE_RAYS 1 traces
 * and records; 2 answers from the record, the traversal skipped (what remains is the kernel's
 * shading). */
#define PROFILE_INDEX_INTS 8
#define PROFILE_RAY_FLOAT4S 3
IBL_INLINE Hit profiled_trace(float3 o, float3 d, float tmax, int any_hit, SCENE_PARAMS)
{
    __global int *st = prof_index + PROFILE_INDEX_INTS * get_global_id(0);
    const int k = st[1]++;
    __global float4 *r = prof_rays + PROFILE_RAY_FLOAT4S * (st[0] + k);
#if PROFILE_RAYS == 2
    if (k < st[2]) {
        const float4 b = r[2];
        Hit h;
        h.t = b.x; h.b1 = b.y; h.b2 = b.z; h.index = as_int(b.w); h.kind = (as_int(r[1].w) >> 1) & 7;
        return h;
    }
#endif
    const Hit h = trace_range(o, d, 0.0f, tmax, any_hit, 1, SCENE_ARGS);
#if PROFILE_RAYS == 1
    if (k == 0) { st[4] = as_int(o.x); st[5] = as_int(o.y); st[6] = as_int(o.z); }
    const int first_vertex = as_int(o.x) == st[4] && as_int(o.y) == st[5] && as_int(o.z) == st[6];
    const int vertex = first_vertex ? 1 : st[3];
    st[3] = any_hit ? vertex : vertex + 1;
    if (k < st[2]) {
        r[0] = (float4)(o, tmax);
        r[1] = (float4)(d, as_float(any_hit | (h.kind << 1) | (vertex << 4)));
        r[2] = (float4)(h.t, h.b1, h.b2, as_float(h.index));
    }
#endif
    return h;
}
#define TRACE_RANGE(o, d, tmax, any_hit) profiled_trace(o, d, tmax, any_hit, SCENE_ARGS)
#else
#define TRACE_RANGE(o, d, tmax, any_hit) trace_range(o, d, 0.0f, tmax, any_hit, 1, SCENE_ARGS)
#endif

IBL_INLINE Hit trace(float3 o, float3 d, SCENE_PARAMS)
{
    return TRACE_RANGE(o, d, INFINITY, 0);
}

/* Any hit along o + t d, t > 0: the shadow ray of a lighting sample. The origin is the shaded
 * point moved off the surface by ray_offset, so the surface does not shadow itself. */
IBL_INLINE int occluded(float3 o, float3 d, SCENE_PARAMS)
{
    return TRACE_RANGE(o, d, INFINITY, 1).kind != PRIM_NONE;
}

/* Any hit along o + t d, 0 < t < tmax: a shadow ray towards a light at distance tmax. */
IBL_INLINE int occluded_to(float3 o, float3 d, float tmax, SCENE_PARAMS)
{
    return TRACE_RANGE(o, d, tmax, 1).kind != PRIM_NONE;
}

/* Where a secondary ray starts: the hit p of a primary ray of direction d that travelled t, moved
 * towards the viewer's side of the surface, along the shading normal n (bent to face the viewer)
 * and back along d, by a distance relative to the float32 error of p (which grows with |p| and t),
 * so the offset is the same fraction of the scene whatever its units. */
IBL_INLINE float3 ray_offset(float3 p, float3 n, float3 d, float t)
{
    const float3 a = fabs(p);
    const float eps = 1e-5f * (fmax(a.x, fmax(a.y, a.z)) + t);
    return p + eps * (n - d);
}

#endif
