/* What the lighting passes read of a G-buffer sample: its material, view vector and shading
 * normal, and the panorama's rotation. The only reader of the G-buffer's layout (kernels/layout.h):
 * a material from the material table by the sample's index, or with textures (HAS_TEXTURES) the
 * material pass's per-sample record (kernels/material.cl).
 * numpy twin: iblbake/render/twin/surface.py. */
#ifndef IBLBAKE_SURFACE_H
#define IBLBAKE_SURFACE_H
#include "common.h"
#include "layout.h"
#include "brdf.h"

/* The lighting modes (kernels/layout.h ids): each lighting pass computes only its own terms */
#ifndef DIFFUSE_MODE
#define DIFFUSE_MODE DIFFUSE_OFF
#endif
#ifndef SPECULAR_MODE
#define SPECULAR_MODE SPECULAR_OFF
#endif

typedef struct {
    float3 base, emissive, f0, f90;     /* Schlick's F = f0 + (f90 - f0) (1 - VoH)^5 */
    float metallic, roughness, alpha;
    float occlusion;        /* the material's ambient occlusion (its map): the image-based light only */
} Material;

/* materials: MATERIAL_FLOAT4S float4 each, (base_color, metallic), (emissive, roughness), (the
 * dielectric's F0 and F90: KHR_materials_specular, scene/materials.py dielectric_f0); gb_mat the
 * first two rows per sample. A metal's F0 is its base colour and its F90 1. */
IBL_INLINE Material material_from(float4 a, float4 b, float4 c)
{
    Material mt;
    mt.base = a.xyz; mt.metallic = a.w; mt.emissive = b.xyz; mt.roughness = b.w;
    mt.alpha = b.w * b.w;
    mt.f0 = mix(c.xyz, a.xyz, a.w);
    mt.f90 = (float3)(mix(c.w, 1.0f, a.w));
    mt.occlusion = 1.0f;
    return mt;
}

IBL_INLINE Material material_at(__global const float4 *materials, int m)
{
    return material_from(materials[MATERIAL_FLOAT4S * m], materials[MATERIAL_FLOAT4S * m + 1],
                         materials[MATERIAL_FLOAT4S * m + 2]);
}

/* A shading normal facing away from the viewer (interpolated normals at silhouettes) is bent
 * towards it until NoV = 1e-4: the BRDF terms stay finite and the surface stays lit. */
IBL_INLINE float3 facing_normal(float3 n, float3 v)
{
    const float nov = dot(n, v);
    if (nov >= 1e-4f) return n;
    return normalize(n + (1e-4f - nov) * v);
}

/* The buffers a G-buffer sample's surface is read from (gb_mat: a placeholder without textures) */
#define SURFACE_PARAMS __global const float4 *gb_nrm, __global const float4 *gb_dir, \
                       __global const float4 *materials, __global const float4 *gb_mat
#define SURFACE_ARGS gb_nrm, gb_dir, materials, gb_mat

/* What the lighting passes read of a G-buffer sample: its material, the view vector, the
 * shading normal (normal-mapped with textures) bent towards the viewer, and NoV (floored at 1e-4). */
IBL_INLINE float surface_at(SURFACE_PARAMS, int gid, Material *mt, float3 *v, float3 *nrm)
{
    *v = -gb_dir[gid].xyz;
#ifdef HAS_TEXTURES
    *mt = material_from(gb_mat[3 * gid], gb_mat[3 * gid + 1],
                        materials[MATERIAL_FLOAT4S * as_int(gb_nrm[gid].w) + 2]);
    const float4 no = gb_mat[3 * gid + 2];
    mt->occlusion = no.w;
    *nrm = facing_normal(no.xyz, *v);
#else
    const float4 nm = gb_nrm[gid];
    *mt = material_at(materials, as_int(nm.w));
    *nrm = facing_normal(nm.xyz, *v);
#endif
    return fmax(dot(*nrm, *v), 1e-4f);
}

/* World direction -> the panorama's frame: the panorama is rotated by rotation_y about +y. */
IBL_INLINE float3 to_env(float3 d, float2 rot)   /* rot = (cos, sin) of rotation_y */
{
    return (float3)(rot.x * d.x - rot.y * d.z, d.y, rot.y * d.x + rot.x * d.z);
}

IBL_INLINE float3 from_env(float3 e, float2 rot)
{
    return (float3)(rot.x * e.x + rot.y * e.z, e.y, -rot.y * e.x + rot.x * e.z);
}

IBL_INLINE float3 diffuse_weight(const Material mt, float nov)
{
    /* kD = (1 - F_r(NoV)) (1 - metallic) (docs/conventions.md), times albedo / pi */
    return (1.0f - f_schlick_roughness(nov, mt.f0, mt.f90, mt.roughness)) * (1.0f - mt.metallic) * mt.base
           * (1.0f / IBL_PI);
}

#endif
