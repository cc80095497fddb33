/* `iblbake render`: a deferred renderer, one work-item per primary sample (pixel x spp).
 *   gbuffer     primary hit per sample: position + distance, shading normal + material,
 *               ray direction + object id (spheres, planes, BVH over triangles)
 *   shade       the lighting terms asked for: SH diffuse, importance or prefiltered specular, emission
 *   reference   progressive Monte Carlo of the exact integral (MIS: environment x BRDF sampling)
 *   background  samples that hit nothing
 *   resolve     mean over a pixel's samples (+ coverage alpha, + AOVs)
 * The numpy twin is iblbake/render/twin.py; tests compare them.
 *
 * Compile-time effect set (defines; a term not asked for is not compiled):
 *   DIFFUSE_MODE  0 off, 1 sh, 2 reference          SH_BANDS
 *   SPECULAR_MODE 0 off, 1 importance, 2 prefiltered, 3 reference
 *   IMPORTANCE_ACCEPTED  divide by accepted samples (seed 000) instead of N
 *   FORCE_MIP0    importance reads level 0 only     HAS_EMISSIVE
 *   HAS_SPHERES HAS_PLANES HAS_TRIANGLES           BACKGROUND 0 hide, 1 show, 2 color, 3 blur
 *   WRITE_AOVS */
#include "common.h"
#include "brdf.h"
#include "sampling.h"
#include "envmap.h"
#include "sh.h"

#ifndef DIFFUSE_MODE
#define DIFFUSE_MODE 0
#endif
#ifndef SPECULAR_MODE
#define SPECULAR_MODE 0
#endif
#ifndef BACKGROUND
#define BACKGROUND 0
#endif

#define MISS_T (-1.0f)

/* ---------------------------------------------------------------------------- camera, rays */

/* cam[0] origin (w: 1 orthographic, 0 perspective), cam[1] forward, cam[2] right and cam[3] up,
 * scaled to half the view's width and height (at distance 1 for perspective). */
inline void camera_ray(__constant float4 *cam, int width, int height, int px, int py, float2 jitter,
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
inline float hit_sphere(float3 o, float3 d, float4 s, float tmin, float tmax)
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

/* plane: point.xyz, normal.xyz, tangent.xyz (w: half width), bitangent.xyz (w: half depth) */
inline float hit_plane(float3 o, float3 d, __global const float4 *pl, float tmin, float tmax)
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

inline float component(float3 v, int k) { return k == 0 ? v.x : (k == 1 ? v.y : v.z); }

/* Per-ray setup of the watertight ray-triangle test (Woop, Benthin and Wald 2013): the axis
 * where the direction is largest becomes z, and a shear maps the ray onto +z. */
typedef struct { int kx, ky, kz; float sx, sy, sz; } RayShear;

inline RayShear ray_shear(float3 d)
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

/* Watertight test on the corners themselves: each edge function depends only on its two
 * corners (bit-identical in the triangles that share them) and flips sign exactly between the
 * two, so a ray through a shared edge hits at least one of the triangles (Moller-Trumbore on
 * per-triangle edge vectors let a few rays through). FP_CONTRACT OFF keeps a*b - c*d unfused,
 * which that exact antisymmetry needs. Returns t and the barycentrics of v1 and v2. */
#pragma OPENCL FP_CONTRACT OFF
inline float hit_triangle(float3 o, RayShear rs, float3 v0, float3 v1, float3 v2, float tmin, float tmax,
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

inline int box_hit(float3 o, float3 inv_d, float3 bmin, float3 bmax, float tmax, float *tnear)
{
    const float3 t0 = (bmin - o) * inv_d, t1 = (bmax - o) * inv_d;
    const float3 lo = fmin(t0, t1), hi = fmax(t0, t1);
    const float a = fmax(fmax(lo.x, lo.y), fmax(lo.z, 0.0f));
    /* far bound widened by 2 gamma(3) (Ize 2013): rounding never drops a box a ray grazes */
    const float b = fmin(fmin(hi.x, hi.y), fmin(hi.z, tmax)) * 1.0000004f;
    *tnear = a;
    return a <= b;
}

typedef struct {
    float t;
    int kind;      /* 0 none, 1 sphere, 2 plane, 3 triangle */
    int index;
    float b1, b2;
} Hit;

inline Hit trace(float3 o, float3 d,
                 __global const float4 *spheres, const int nspheres,
                 __global const float4 *planes, const int nplanes,
                 __global const float4 *bvh, __global const float4 *tris, const int ntris)
{
    Hit h;
    h.t = INFINITY; h.kind = 0; h.index = -1; h.b1 = 0.0f; h.b2 = 0.0f;
    const float tmin = 0.0f;
#ifdef HAS_SPHERES
    for (int i = 0; i < nspheres; ++i) {
        const float t = hit_sphere(o, d, spheres[2 * i], tmin, h.t);
        if (t < h.t) { h.t = t; h.kind = 1; h.index = i; }
    }
#endif
#ifdef HAS_PLANES
    for (int i = 0; i < nplanes; ++i) {
        const float t = hit_plane(o, d, planes + 4 * i, tmin, h.t);
        if (t < h.t) { h.t = t; h.kind = 2; h.index = i; }
    }
#endif
#ifdef HAS_TRIANGLES
    if (ntris > 0) {
        /* +-inf components of 1/d are fine for the slab test; exact zeros become huge */
        const float3 inv_d = (float3)(1.0f / (d.x != 0.0f ? d.x : 1e-30f), 1.0f / (d.y != 0.0f ? d.y : 1e-30f),
                                      1.0f / (d.z != 0.0f ? d.z : 1e-30f));
        const RayShear rs = ray_shear(d);
        int stack[64];
        int sp = 0;
        stack[sp++] = 0;
        while (sp > 0) {
            const int ni = stack[--sp];
            const float4 a = bvh[2 * ni], b = bvh[2 * ni + 1];
            float tn;
            if (!box_hit(o, inv_d, a.xyz, b.xyz, h.t, &tn)) continue;
            const int count = as_int(b.w), first = as_int(a.w);
            if (count > 0) {
                for (int k = first; k < first + count; ++k) {
                    float b1, b2;
                    const float t = hit_triangle(o, rs, tris[6 * k].xyz, tris[6 * k + 1].xyz, tris[6 * k + 2].xyz,
                                                 tmin, h.t, &b1, &b2);
                    if (t < h.t) { h.t = t; h.kind = 3; h.index = k; h.b1 = b1; h.b2 = b2; }
                }
            } else if (sp < 62) {
                /* nearer child last so it is popped first */
                const float4 la = bvh[2 * first], lb = bvh[2 * first + 1];
                const float4 ra = bvh[2 * first + 2], rb = bvh[2 * first + 3];
                float tl, tr;
                const int hl = box_hit(o, inv_d, la.xyz, lb.xyz, h.t, &tl);
                const int hr = box_hit(o, inv_d, ra.xyz, rb.xyz, h.t, &tr);
                if (hl && hr) {
                    if (tl <= tr) { stack[sp++] = first + 1; stack[sp++] = first; }
                    else { stack[sp++] = first; stack[sp++] = first + 1; }
                } else if (hl) stack[sp++] = first;
                else if (hr) stack[sp++] = first + 1;
            }
        }
    }
#endif
    return h;
}

/* ---------------------------------------------------------------------------- G-buffer pass */

/* spheres: (centre, radius), (material, object, -, -) as ints
 * planes: 4 float4 (see hit_plane), material/object in the w of point/normal
 * tris: v0 (w: material), v1 (w: object), v2, n0, n1, n2 */
__kernel void gbuffer(__constant float4 *cam, const int width, const int height, const int spp,
                      __global const float2 *jitter,
                      __global const float4 *spheres, const int nspheres,
                      __global const float4 *planes, const int nplanes,
                      __global const float4 *bvh, __global const float4 *tris, const int ntris,
                      __global float4 *gb_pos, __global float4 *gb_nrm, __global float4 *gb_dir)
{
    const int gid = get_global_id(0);
    const int n = width * height * spp;
    if (gid >= n) return;
    const int s = gid % spp, pix = gid / spp;
    float3 o, d;
    camera_ray(cam, width, height, pix % width, pix / width, jitter[s], &o, &d);
    const Hit h = trace(o, d, spheres, nspheres, planes, nplanes, bvh, tris, ntris);
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
        const float4 sp = spheres[2 * h.index];
        ng = (p - sp.xyz) / sp.w;
        ng = normalize(ng);
        ns = ng;
        mat = as_int(spheres[2 * h.index + 1].x);
        obj = as_int(spheres[2 * h.index + 1].y);
    } else if (h.kind == 2) {
        ng = planes[4 * h.index + 1].xyz;
        ns = ng;
        mat = as_int(planes[4 * h.index].w);
        obj = as_int(planes[4 * h.index + 1].w);
    } else {
        const int k = h.index;
        const float3 v0 = tris[6 * k].xyz;
        ng = normalize(cross(tris[6 * k + 1].xyz - v0, tris[6 * k + 2].xyz - v0));
        const float b0 = 1.0f - h.b1 - h.b2;
        ns = b0 * tris[6 * k + 3].xyz + h.b1 * tris[6 * k + 4].xyz + h.b2 * tris[6 * k + 5].xyz;
        const float ln = length(ns);
        ns = ln > 1e-12f ? ns / ln : ng;
        if (dot(ns, ng) < 0.0f) ns = -ns;
        mat = as_int(tris[6 * k].w);
        obj = as_int(tris[6 * k + 1].w);
    }
    /* two-sided: the geometric normal faces the viewer; the shading normal follows it */
    if (dot(ng, d) > 0.0f) { ng = -ng; ns = -ns; }
    gb_pos[gid] = (float4)(p, h.t);
    gb_nrm[gid] = (float4)(ns, as_float(mat));
    gb_dir[gid] = (float4)(d, as_float(obj));
}

/* ---------------------------------------------------------------------------- shading */

typedef struct {
    float3 base, emissive, f0;
    float metallic, roughness, alpha;
} Material;

/* materials: (base_color, metallic), (emissive, roughness) */
inline Material material_at(__global const float4 *materials, int m)
{
    Material mt;
    const float4 a = materials[2 * m], b = materials[2 * m + 1];
    mt.base = a.xyz; mt.metallic = a.w; mt.emissive = b.xyz; mt.roughness = b.w;
    mt.alpha = b.w * b.w;
    mt.f0 = mix((float3)(0.04f), a.xyz, a.w);
    return mt;
}

/* A shading normal facing away from the viewer (interpolated normals at silhouettes) is bent
 * towards it until NoV = 1e-4: the BRDF terms stay finite and the surface stays lit. */
inline float3 facing_normal(float3 n, float3 v)
{
    const float nov = dot(n, v);
    if (nov >= 1e-4f) return n;
    return normalize(n + (1e-4f - nov) * v);
}

/* What the lighting passes read of a G-buffer sample: its material, the view vector, the
 * shading normal bent towards the viewer, and NoV (floored at 1e-4). */
inline float surface_at(__global const float4 *gb_nrm, __global const float4 *gb_dir,
                        __global const float4 *materials, int gid, Material *mt, float3 *v, float3 *nrm)
{
    const float4 nm = gb_nrm[gid];
    *mt = material_at(materials, as_int(nm.w));
    *v = -gb_dir[gid].xyz;
    *nrm = facing_normal(nm.xyz, *v);
    return fmax(dot(*nrm, *v), 1e-4f);
}

/* World direction -> the panorama's frame: the panorama is rotated by rotation_y about +y. */
inline float3 to_env(float3 d, float2 rot)   /* rot = (cos, sin) of rotation_y */
{
    return (float3)(rot.x * d.x - rot.y * d.z, d.y, rot.y * d.x + rot.x * d.z);
}

inline float3 from_env(float3 e, float2 rot)
{
    return (float3)(rot.x * e.x + rot.y * e.z, e.y, -rot.y * e.x + rot.x * e.z);
}

inline float3 diffuse_weight(const Material mt, float nov)
{
    /* kD = (1 - F_r(NoV)) (1 - metallic), DESIGN.md, times albedo / pi */
    return (1.0f - f_schlick_roughness(nov, mt.f0, mt.roughness)) * (1.0f - mt.metallic) * mt.base
           * (1.0f / IBL_PI);
}

#if DIFFUSE_MODE == 1
inline float3 sh_irradiance(__constant float4 *coeffs, float3 n)
{
    float Y[SH_COEFFS];
    sh_eval(n, Y);
    float3 e = (float3)(0.0f);
    for (int k = 0; k < SH_COEFFS; ++k) e += coeffs[k].xyz * Y[k];
    return fmax(e, (float3)(0.0f));
}
#endif

/* Where a rough lobe really points: between N and R (Lagarde and de Rousiers 2014, Frostbite,
 * getSpecularDominantDir with their alpha). The split sum reads its prefiltered chain there. */
inline float3 dominant_direction(float3 n, float3 r, float a)
{
    const float s = clamp(1.0f - a, 0.0f, 1.0f);
    return normalize(mix(n, r, s * (sqrt(s) + a)));
}

__kernel void shade(__global const float4 *gb_pos, __global const float4 *gb_nrm, __global const float4 *gb_dir,
                    const int n, __global const float4 *materials, const float2 env_rot, const float env_scale,
                    __constant float4 *sh_coeffs,
                    __global const float4 *chain, __constant int *off, __constant int *lw, __constant int *lh,
                    const int nlev,
                    __global const float4 *hammersley_pts, const int nsamples, const float mip_bias,
                    __global const float2 *dfg, const int dfg_size,
                    __global float4 *out)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    if (gb_pos[gid].w == MISS_T) { out[gid] = (float4)(0.0f); return; }
    Material mt;
    float3 v, nrm;
    const float nov = surface_at(gb_nrm, gb_dir, materials, gid, &mt, &v, &nrm);
    float3 color = (float3)(0.0f);
#ifdef HAS_EMISSIVE
    color += mt.emissive;
#endif
#if DIFFUSE_MODE == 1
    color += diffuse_weight(mt, nov) * env_scale * sh_irradiance(sh_coeffs, to_env(nrm, env_rot));
#endif
#if SPECULAR_MODE == 1
    {
        /* seed 000: N Hammersley points, GGX half-vector warp, mip level from the pdf */
        float3 t, b;
        tangent_frame(nrm, &t, &b);
        const int w0 = lw[0], h0 = lh[0];
        float3 acc = (float3)(0.0f);
        int accepted = 0;
        for (int i = 0; i < nsamples; ++i) {
            const float3 hl = sample_ggx_half_cs(hammersley_pts[i], mt.alpha);
            const float3 h = t * hl.x + b * hl.y + nrm * hl.z;
            const float voh = dot(v, h);
            const float3 l = 2.0f * voh * h - v;
            const float nol = dot(nrm, l);
            if (nol <= 0.0f || voh <= 0.0f) continue;
            ++accepted;
            const float noh = fmax(hl.z, 1e-7f);
            float lod = 0.0f;
#ifndef FORCE_MIP0
            /* solid angle of this sample, 1 / (N pdf(l)), pdf(l) = D(h) NoH / (4 VoH) */
            const float pdf = d_ggx(noh, mt.alpha) * noh / (4.0f * voh);
            const float3 le = to_env(l, env_rot);
            lod = -0.5f * log2((float)nsamples * pdf * texel_solid_angle(le, w0, h0)) + mip_bias;
            const float3 li = chain_lookup(chain, off, lw, lh, nlev, le, lod);
#else
            const float3 li = chain_lookup(chain, off, lw, lh, nlev, to_env(l, env_rot), 0.0f);
#endif
            /* f NoL / pdf = F V 4 NoL VoH / NoH  (D cancels) */
            acc += li * f_schlick(voh, mt.f0) * (v_smith_ggx_correlated(nov, nol, mt.alpha) * 4.0f * nol * voh / noh);
        }
#ifdef IMPORTANCE_ACCEPTED
        color += env_scale * acc / (float)max(accepted, 1);
#else
        color += env_scale * acc / (float)nsamples;
#endif
    }
#elif SPECULAR_MODE == 2
    {
        /* split sum: prefiltered chain at R (level = roughness (K-1)) x (F0 A + B) */
#ifdef DOMINANT_DIRECTION
        const float3 r = dominant_direction(nrm, 2.0f * dot(nrm, v) * nrm - v, mt.alpha);
#else
        const float3 r = 2.0f * dot(nrm, v) * nrm - v;
#endif
        const float3 pre = chain_lookup(chain, off, lw, lh, nlev, to_env(r, env_rot),
                                        mt.roughness * (float)(nlev - 1));
        const float x = clamp(nov, 0.0f, 1.0f) * (dfg_size - 1), y = mt.roughness * (dfg_size - 1);
        const int x0 = min((int)x, dfg_size - 2), y0 = min((int)y, dfg_size - 2);
        const float fx = x - x0, fy = y - y0;
        const float2 ab = mix(mix(dfg[y0 * dfg_size + x0], dfg[y0 * dfg_size + x0 + 1], fx),
                              mix(dfg[(y0 + 1) * dfg_size + x0], dfg[(y0 + 1) * dfg_size + x0 + 1], fx), fy);
        color += env_scale * pre * (mt.f0 * ab.x + ab.y);
    }
#endif
    out[gid] = (float4)(color, 0.0f);
}

/* ---------------------------------------------------------------------------- reference */

#if DIFFUSE_MODE == 2 || SPECULAR_MODE == 3

inline uint pcg_hash(uint x)
{
    uint state = x * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

inline float hash_uniform(uint x)
{
    return (float)(pcg_hash(x) >> 8) * (1.0f / 16777216.0f);
}

/* Radical inverse of j in base b: Halton points, a quasi-random sequence that stays uniform at
 * every prefix, so the frame converges faster than with independent random numbers. */
inline float radical_inverse(uint j, uint b)
{
    const float inv_b = 1.0f / (float)b;
    float f = inv_b, r = 0.0f;
    while (j > 0u) {
        r += f * (float)(j % b);
        j /= b;
        f *= inv_b;
    }
    return fmin(r, 0x1.fffffep-1f);
}

/* Dimension d of sample j of replicate `rep` for G-buffer sample gid: Halton in base
 * HALTON_BASES[d], shifted by a random rotation per (seed, gid, replicate, dimension)
 * (Cranley-Patterson). Two replicates (even and odd sample numbers) with independent rotations
 * give an honest error estimate (their difference); a variance of QMC samples would not. */
__constant uint HALTON_BASES[8] = {2u, 3u, 5u, 7u, 11u, 13u, 17u, 19u};
#define DIM_ENV 0
#define DIM_BRDF 2
#define DIM_COSINE 4
#define DIM_JITTER 6

inline float qmc(uint seed, uint gid, uint k, int d)
{
    const uint rep = k & 1u, j = k >> 1;
    const float shift = hash_uniform(seed ^ pcg_hash(gid * 16u + rep * 8u + (uint)d));
    const float x = radical_inverse(j, HALTON_BASES[d]) + shift;
    return x >= 1.0f ? x - 1.0f : x;
}

/* Environment sampling, piecewise constant over texels (the full-resolution panorama):
 * row from the marginal CDF, column from the row's CDF, uniform in (phi, cos theta) inside
 * the texel, so the pdf over solid angle is p_texel / Omega_texel (pdf table). */
inline int cdf_search(__global const float *cdf, int n, float u)
{
    int lo = 0, hi = n - 1;                 /* cdf[0..n], cdf[0] = 0, cdf[n] = 1 */
    while (lo < hi) {
        const int mid = (lo + hi) >> 1;
        if (cdf[mid + 1] <= u) lo = mid + 1; else hi = mid;
    }
    return lo;
}

inline float3 env_texel(__global const float4 *img, int w, int h, float3 e, __global const float *pdf, float *p)
{
    const float2 uv = equirect_uv_from_dir(e);
    const int i = min((int)(uv.x * w), w - 1), j = min((int)(uv.y * h), h - 1);
    *p = pdf[j * w + i];
    return img[j * w + i].xyz;
}

#define DELTA_ALPHA 1e-4f

inline float g1_smith(float nov, float alpha)
{
    const float a2 = alpha * alpha;
    return 2.0f * nov / (nov + sqrt(a2 + (1.0f - a2) * nov * nov));
}

/* Visible-normal sampling of GGX (Heitz 2018), local frame z = n. */
inline float3 sample_vndf(float3 vl, float alpha, float u1, float u2)
{
    const float3 vh = normalize((float3)(alpha * vl.x, alpha * vl.y, vl.z));
    const float lensq = vh.x * vh.x + vh.y * vh.y;
    const float3 t1 = lensq > 0.0f ? (float3)(-vh.y, vh.x, 0.0f) * rsqrt(lensq) : (float3)(1.0f, 0.0f, 0.0f);
    const float3 t2 = cross(vh, t1);
    const float r = sqrt(u1), phi = 2.0f * IBL_PI * u2;
    const float p1 = r * cos(phi);
    float p2 = r * sin(phi);
    const float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * sqrt(fmax(0.0f, 1.0f - p1 * p1)) + s * p2;
    const float3 nh = p1 * t1 + p2 * t2 + sqrt(fmax(0.0f, 1.0f - p1 * p1 - p2 * p2)) * vh;
    return normalize((float3)(alpha * nh.x, alpha * nh.y, fmax(1e-7f, nh.z)));
}

/* Power heuristic a^2 / (a^2 + b^2), written so that an infinite or huge pdf (a near-mirror
 * lobe) gives 1 or 0 instead of inf / inf. */
inline float power_weight(float a, float b)
{
    if (!(a > 0.0f)) return 0.0f;
    const float r = b / a;
    return 1.0f / (1.0f + r * r);
}

/* One batch of `batch` samples per G-buffer sample: out = (sum of estimates, sum of the odd-numbered
 * samples' luminance). Samples are numbered globally (first + k), so the frame is the same
 * whatever the batching and wherever the run stops. */
__kernel void reference(__global const float4 *gb_pos, __global const float4 *gb_nrm,
                        __global const float4 *gb_dir, const int n,
                        __global const float4 *materials, const float2 env_rot, const float env_scale,
                        __global const float4 *img, const int w, const int h,
                        __global const float *marginal, __global const float *conditional,
                        __global const float *pdf_table,
                        const uint seed, const int first, const int batch, __global float4 *out)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    if (gb_pos[gid].w == MISS_T) { out[gid] = (float4)(0.0f); return; }
    Material mt;
    float3 v, nrm;
    const float nov = surface_at(gb_nrm, gb_dir, materials, gid, &mt, &v, &nrm);
    float3 t, b;
    tangent_frame(nrm, &t, &b);
    const float3 vl = (float3)(dot(v, t), dot(v, b), nov);
#if SPECULAR_MODE == 3
    const int delta = mt.alpha < DELTA_ALPHA;
#endif
#if DIFFUSE_MODE == 2
    const float3 kd = diffuse_weight(mt, nov);
#endif
    float3 sum = (float3)(0.0f);
    float odd = 0.0f;
    for (int k = 0; k < batch; ++k) {
        const uint sk = (uint)(first + k);
        float3 est = (float3)(0.0f);
        /* strategy 1: the environment */
        {
            const int j = cdf_search(marginal, h, qmc(seed, gid, sk, DIM_ENV));
            const int i = cdf_search(conditional + j * (w + 1), w, qmc(seed, gid, sk, DIM_ENV + 1));
            const float u = ((float)i + qmc(seed, gid, sk, DIM_JITTER)) / (float)w;
            const float c0 = cospi((float)j / h), c1 = cospi((float)(j + 1) / h);
            const float ct = mix(c0, c1, qmc(seed, gid, sk, DIM_JITTER + 1));
            const float stt = sqrt(fmax(0.0f, 1.0f - ct * ct)), phi = 2.0f * IBL_PI * (0.5f - u);
            const float3 e = (float3)(stt * sin(phi), ct, stt * cos(phi));
            const float pe = pdf_table[j * w + i];
            const float3 l = from_env(e, env_rot);
            const float nol = dot(nrm, l);
            if (nol > 0.0f && pe > 0.0f) {
                const float3 li = img[j * w + i].xyz;
#if DIFFUSE_MODE == 2
                est += li * kd * (nol / pe) * power_weight(pe, nol / IBL_PI);
#endif
#if SPECULAR_MODE == 3
                if (!delta) {
                    const float3 hv = normalize(v + l);
                    const float3 cx = cross(nrm, hv);
                    const float noh = fmax(dot(nrm, hv), 0.0f), voh = fmax(dot(v, hv), 0.0f);
                    const float dd = d_ggx_sc(dot(cx, cx), noh * noh, mt.alpha);
                    const float pb = g1_smith(nov, mt.alpha) * dd / (4.0f * nov);
                    est += li * f_schlick(voh, mt.f0) * (dd * v_smith_ggx_correlated(nov, nol, mt.alpha) * nol / pe)
                           * power_weight(pe, pb);
                }
#endif
            }
        }
#if DIFFUSE_MODE == 2
        /* strategy 2a: cosine-weighted hemisphere */
        {
            const float r = sqrt(qmc(seed, gid, sk, DIM_COSINE)), phi = 2.0f * IBL_PI * qmc(seed, gid, sk, DIM_COSINE + 1);
            const float z = sqrt(fmax(0.0f, 1.0f - r * r));
            const float3 l = t * (r * cos(phi)) + b * (r * sin(phi)) + nrm * z;
            float pe;
            const float3 li = env_texel(img, w, h, to_env(l, env_rot), pdf_table, &pe);
            const float pc = z / IBL_PI;
            if (pc > 0.0f) est += li * kd * IBL_PI * power_weight(pc, pe);
        }
#endif
#if SPECULAR_MODE == 3
        /* strategy 2b: GGX visible normals; f NoL / pdf = F G2 / G1(V). A lobe narrower than
         * float32 can resolve (alpha < DELTA_ALPHA) is a mirror: this strategy alone, weight F. */
        if (delta) {
            const float3 l = 2.0f * nov * nrm - v;
            float pe;
            est += env_texel(img, w, h, to_env(l, env_rot), pdf_table, &pe) * f_schlick(nov, mt.f0);
        } else {
            const float u1 = qmc(seed, gid, sk, DIM_BRDF), u2 = qmc(seed, gid, sk, DIM_BRDF + 1);
            const float3 hl = sample_vndf(vl, mt.alpha, u1, u2);
            const float3 hs = t * hl.x + b * hl.y + nrm * hl.z;
            const float3 l = 2.0f * dot(v, hs) * hs - v;
            const float nol = dot(nrm, l);
            if (nol > 0.0f && dot(v, hs) > 0.0f) {
                /* the pdf from h = normalize(v + l), computed exactly as strategy 1 does, so the
                 * two MIS weights of any direction sum to 1 */
                const float3 hv = normalize(v + l);
                const float3 cx = cross(nrm, hv);
                const float noh = fmax(dot(nrm, hv), 0.0f), voh = fmax(dot(v, hv), 0.0f);
                float pe;
                const float3 li = env_texel(img, w, h, to_env(l, env_rot), pdf_table, &pe);
                const float g1 = g1_smith(nov, mt.alpha);
                const float pb = g1 * d_ggx_sc(dot(cx, cx), noh * noh, mt.alpha) / (4.0f * nov);
                const float g2 = v_smith_ggx_correlated(nov, nol, mt.alpha) * 4.0f * nov * nol;
                est += li * f_schlick(voh, mt.f0) * (g2 / g1) * power_weight(pb, pe);
            }
        }
#endif
        est *= env_scale;
        sum += est;
        if (sk & 1u) odd += dot(est, (float3)(0.2126f, 0.7152f, 0.0722f));
    }
    out[gid] = (float4)(sum, odd);
}
#endif

/* ---------------------------------------------------------------------------- background */

__kernel void background(__global const float4 *gb_pos, __global const float4 *gb_dir, const int n,
                         const float2 env_rot, const float env_scale, const float4 color,
                         __global const float4 *chain, __constant int *off, __constant int *lw,
                         __constant int *lh, const int nlev, const float lod, __global float4 *out)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    if (gb_pos[gid].w != MISS_T) return;
#if BACKGROUND == 1 || BACKGROUND == 3
    out[gid] = (float4)(env_scale * chain_lookup(chain, off, lw, lh, nlev, to_env(gb_dir[gid].xyz, env_rot), lod), 0.0f);
#elif BACKGROUND == 2
    out[gid] = (float4)(color.xyz, 0.0f);
#else
    out[gid] = (float4)(0.0f);
#endif
}

/* ---------------------------------------------------------------------------- resolve */

/* Pixel = mean of its samples' radiance (shade + reference mean); alpha = coverage.
 * ref_scale = 1 / samples taken so far (0 when no reference term). */
__kernel void resolve(__global const float4 *radiance, __global const float4 *ref_sum, const float ref_scale,
                      __global const float4 *gb_pos, __global const float4 *gb_nrm,
                      __global const float4 *materials, const int spp, const int npix,
                      __global float4 *hdr, __global float4 *aov_normal, __global float4 *aov_albedo,
                      __global float *aov_depth)
{
    const int px = get_global_id(0);
    if (px >= npix) return;
    float3 c = (float3)(0.0f);
    float cover = 0.0f;
#ifdef WRITE_AOVS
    float3 nsum = (float3)(0.0f), asum = (float3)(0.0f);
    float dsum = 0.0f;
#endif
    for (int s = 0; s < spp; ++s) {
        const int g = px * spp + s;
        float3 x = radiance[g].xyz;
        if (ref_scale > 0.0f) x += ref_sum[g].xyz * ref_scale;
        c += x;
        const float4 p = gb_pos[g];
        if (p.w != MISS_T) {
            cover += 1.0f;
#ifdef WRITE_AOVS
            const float4 nm = gb_nrm[g];
            nsum += nm.xyz;
            asum += materials[2 * as_int(nm.w)].xyz;
            dsum += p.w;
#endif
        }
    }
    const float inv = 1.0f / (float)spp;
    hdr[px] = (float4)(c * inv, cover * inv);
#ifdef WRITE_AOVS
    aov_normal[px] = (float4)(nsum * inv, cover * inv);
    aov_albedo[px] = (float4)(asum * inv, cover * inv);
    aov_depth[px] = cover > 0.0f ? dsum / cover : 0.0f;
#endif
}
