/* What the lighting passes read of a G-buffer sample: its material, view vector and shading
 * normal, and the panorama's rotation. The only reader of the G-buffer's layout (kernels/layout.h).
 * numpy twin: iblbake/render/twin.py (surface, diffuse_weight, to_env). */
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
    float3 base, emissive, f0;
    float metallic, roughness, alpha;
} Material;

/* materials: MATERIAL_FLOAT4S float4 each, (base_color, metallic), (emissive, roughness) */
inline Material material_at(__global const float4 *materials, int m)
{
    Material mt;
    const float4 a = materials[MATERIAL_FLOAT4S * m], b = materials[MATERIAL_FLOAT4S * m + 1];
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
    /* kD = (1 - F_r(NoV)) (1 - metallic) (docs/conventions.md), times albedo / pi */
    return (1.0f - f_schlick_roughness(nov, mt.f0, mt.roughness)) * (1.0f - mt.metallic) * mt.base
           * (1.0f / IBL_PI);
}

#endif
