/* Exposes the header functions one per work-item, so tests compare them with the numpy
 * conventions (tests/test_conventions.py, tests/test_sh.py). Not used by any command. */
#include "common.h"
#include "sh.h"
#include "bases.h"
#include "envmap.h"
#include "probes.h"
#include "bsdf.h"

__kernel void t_equirect_uv(__global const float *d, __global float *uv)
{
    int i = get_global_id(0);
    float2 r = equirect_uv_from_dir(vload3(i, d));
    uv[2 * i] = r.x; uv[2 * i + 1] = r.y;
}

__kernel void t_dir_from_equirect(__global const float *uv, __global float *d)
{
    int i = get_global_id(0);
    vstore3(dir_from_equirect_uv((float2)(uv[2 * i], uv[2 * i + 1])), i, d);
}

__kernel void t_row_solid_angle(const int width, const int height, __global float *out)
{
    int j = get_global_id(0);
    out[j] = equirect_row_solid_angle(j, width, height);
}

__kernel void t_bilinear(__global const float *img, const int width, const int height,
                         __global const float *uv, __global float *out)
{
    int i = get_global_id(0);
    vstore3(bilinear_equirect(img, width, height, (float2)(uv[2 * i], uv[2 * i + 1])), i, out);
}

__kernel void t_cube(__global const float *st, __global float *d)
{
    int i = get_global_id(0);
    vstore3(dir_from_cube((int)st[3 * i], st[3 * i + 1], st[3 * i + 2]), i, d);
}

__kernel void t_octahedral(__global const float *uv, __global float *d)
{
    int i = get_global_id(0);
    vstore3(dir_from_octahedral(uv[2 * i], uv[2 * i + 1]), i, d);
}

__kernel void t_frame(__global const float *n, __global float *tb)
{
    int i = get_global_id(0);
    float3 t, b;
    tangent_frame(vload3(i, n), &t, &b);
    vstore3(t, 2 * i, tb);
    vstore3(b, 2 * i + 1, tb);
}

__kernel void t_sh(__global const float *d, __global float *y)
{
    int i = get_global_id(0);
    float Y[SH_COEFFS];
    sh_eval(vload3(i, d), Y);
    for (int k = 0; k < SH_COEFFS; ++k) y[i * SH_COEFFS + k] = Y[k];
}

__kernel void t_chain_lookup(CHAIN_PARAMS, __global const float *d,
                             __global const float *lod, __global float *out)
{
    int i = get_global_id(0);
    vstore3(chain_lookup(CHAIN_ARGS, vload3(i, d), lod[i]), i, out);
}

/* Warps of sampling.h on given uniforms (tests/test_sampling.py: chi-square against their pdfs).
 * kind 0 cosine hemisphere, 1 uniform cone (param: cos_max), 2 GGX half-vector (param: alpha),
 * 3 GGX visible normals reflected about h (param: alpha, view vl). */
#include "sampling.h"

__kernel void t_warp(const int kind, const float param, const float4 vl, __global const float2 *u,
                     __global float4 *out)
{
    const int i = get_global_id(0);
    float3 d;
    if (kind == 0) d = sample_cosine_hemisphere(u[i]);
    else if (kind == 1) d = sample_uniform_cone(u[i], param);
    else if (kind == 2) d = sample_ggx_half(u[i], param);
    else {
        const float3 h = sample_ggx_vndf(vl.xyz, param, u[i]);
        d = 2.0f * dot(vl.xyz, h) * h - vl.xyz;
    }
    out[i] = (float4)(d, 0.0f);
}

/* bsdf.h per vertex (tests/test_bsdf.py): material rows mat[3i..3i+2] as the material table's,
 * vn[2i] = (v, ps), vn[2i + 1] = (n, 0), lu[2i] = (l, u_lobe), lu[2i + 1] = (u, 0, 0); out[4i] =
 * (bsdf_eval, its pdf), out[4i + 1].x = bsdf_pdf, out[4i + 2] = (bsdf_sample's weight, its pdf),
 * out[4i + 3] = (its direction, specular_probability) */
__kernel void t_bsdf(__global const float4 *mat, __global const float4 *vn, __global const float4 *lu,
                     const int diffuse, const int specular, __global float4 *out)
{
    const int i = get_global_id(0);
    const Material mt = material_from(mat[3 * i], mat[3 * i + 1], mat[3 * i + 2]);
    const float3 v = vn[2 * i].xyz, n = vn[2 * i + 1].xyz, l = lu[2 * i].xyz;
    const float ps = vn[2 * i].w, nov = fmax(dot(n, v), 1e-4f);
    float pdf;
    const float3 f = bsdf_eval(mt, v, n, nov, l, ps, diffuse, specular, &pdf);
    out[4 * i] = (float4)(f, pdf);
    out[4 * i + 1] = (float4)(bsdf_pdf(mt, v, n, nov, l, ps, diffuse, specular), 0.0f, 0.0f, 0.0f);
    float3 t, b, ls;
    tangent_frame(n, &t, &b);
    const float3 w = bsdf_sample(mt, v, n, t, b, nov, ps, diffuse, specular, lu[2 * i].w, lu[2 * i + 1].xy, &ls, &pdf);
    out[4 * i + 2] = (float4)(w, pdf);
    out[4 * i + 3] = (float4)(ls, specular_probability(mt, nov, diffuse, specular));
}

__kernel void t_env(__global const float *marginal, __global const float *conditional, __global const int *guide,
                    const int w, const int h,
                    __global const float4 *u, __global float4 *out)
{
    const int i = get_global_id(0);
    int texel;
    out[i] = (float4)(sample_env(marginal, conditional, guide, w, h, u[i], &texel), (float)texel);
}

/* envmap.h pdf_env of every texel's radiance c (float4: RGB) */
__kernel void t_pdf_env(__global const float4 *c, const float2 env_norm, __global float *out)
{
    const int i = get_global_id(0);
    out[i] = pdf_env(c[i].xyz, env_norm);
}

/* a * b element by element: whether the program flushes subnormal operands and results
 * (docs/conventions.md amendment 15) */
__kernel void t_product(__global const float *a, __global const float *b, __global float *out)
{
    const int i = get_global_id(0);
    out[i] = a[i] * b[i];
}

/* the volume record's fields as probes.h reads them (PROBE_VOLUME_LOCALS): origin | normal bias,
 * spacing | view bias, counts | irradiance texels, distance texels (tests/test_probe_registry.py) */
__kernel void t_probe_volume(PROBE_PARAMS, __global float4 *out)
{
    PROBE_VOLUME_LOCALS;
    out[0] = (float4)(probe_origin, probe_normal_bias);
    out[1] = (float4)(probe_spacing, probe_view_bias);
    out[2] = (float4)(convert_float3(probe_counts), (float)probe_irr_texels);
    out[3] = (float4)((float)probe_dist_texels, 0.0f, 0.0f, 0.0f);
}

/* probes.h at points p, normals n, view vectors v (float4 each); defines PROBES_SH,
 * PROBE_VISIBILITY, PROBE_CLASSIFICATION as the shade pass sets them */
__kernel void t_probes(__global const float4 *p, __global const float4 *n, __global const float4 *v, PROBE_PARAMS,
                       __global float4 *out)
{
    const int i = get_global_id(0);
    out[i] = probe_irradiance(p[i].xyz, n[i].xyz, v[i].xyz, PROBE_ARGS);
}

#if defined(PROBES_BASIS) && defined(HAS_BASIS_SPECULAR)
/* probes.h's specular radiance along the warped lobe (axis d.xyz, sharpness d.w) at points p, normals
 * n, view vectors v: tests/test_probes_specular.py */
__kernel void t_probe_specular(__global const float4 *p, __global const float4 *n, __global const float4 *v,
                               __global const float4 *d, __global const float *basis_table, PROBE_PARAMS,
                               __global float4 *out)
{
    const int i = get_global_id(0);
    float s[BASIS_SPECULAR_ROWS];
    basis_specular_weights(probe_irr, basis_table, d[i].xyz, d[i].w, s);
    out[i] = probe_blend(p[i].xyz, n[i].xyz, v[i].xyz, s, PROBE_ARGS);
}
#endif

/* probes.h probe_contribution of probe index c[i].xyz at p, n, v: (weight, value) with the value
 * set to NaN before the call, so that an unwritten value shows (tests/test_probes.py) */
__kernel void t_probe_contribution(__global const int4 *c, __global const float4 *p, __global const float4 *n,
                                   __global const float4 *v, PROBE_PARAMS, __global float4 *out)
{
    const int i = get_global_id(0);
    float3 value = (float3)(NAN);
    const float3 biased = p[i].xyz + n[i].xyz * PROBE_VOLUME_NORMAL_BIAS(probe_volume)
                          + v[i].xyz * PROBE_VOLUME_VIEW_BIAS(probe_volume);
    const float w = probe_contribution(c[i].xyz, p[i].xyz, biased, n[i].xyz, (float3)(1.0f), (const float *)0, &value,
                                       PROBE_ARGS);
    out[i] = (float4)(value, w);
}

/* sampler.h: dimensions 0 .. ndim - 1 of sample k[i] of G-buffer sample gid[i] as
 * sampler_replicate hands them out in pairs (tests/test_sampling.py, against the twin) */
__kernel void t_sampler(const uint seed, __global const uint *gid, __global const uint *k, const int replicates,
                        const int ndim, __global float *out)
{
    const int i = get_global_id(0);
    Sampler sp = sampler_replicate(seed, gid[i], k[i], replicates);
    for (int d = 0; d + 1 < ndim; d += 2) vstore2(sampler_2d(&sp), 0, out + i * ndim + d);
}

__kernel void t_probe_octahedral(__global const float4 *d, __global float2 *uv)
{
    const int i = get_global_id(0);
    uv[i] = probe_octahedral(d[i].xyz);
}

#ifdef HAS_BASIS
/* the scene's directional basis (BASIS_<NAME>) at normals: tests/test_bases_kernel.py */
__kernel void t_basis_irradiance(BASIS_SPACE const float4 *basis_coeffs, __global const float *n, __global float *e)
{
    int i = get_global_id(0);
    vstore3(basis_irradiance(basis_coeffs, vload3(i, n)), i, e);
}
#ifdef HAS_BASIS_SPECULAR
/* the basis's specular radiance along r (xyz) with warp sharpness from (alpha, n.v) in an:
 * tests/test_bases_specular.py */
__kernel void t_basis_specular(BASIS_SPACE const float4 *basis_coeffs, __global const float *basis_table,
                               __global const float4 *r, __global const float2 *an, __global float *e)
{
    int i = get_global_id(0);
    vstore3(basis_specular_radiance(basis_coeffs, basis_table, r[i].xyz, basis_warp_sharpness(an[i].x, an[i].y)),
            i, e);
}
#endif
#endif

/* the SH irradiance of the shade pass at normals (SH_BANDS bands): benchmarks/bench_bases.py */
__kernel void t_sh_irradiance(__constant float4 *coeffs, __global const float *n, __global float *e)
{
    int i = get_global_id(0);
    vstore3(sh_irradiance(coeffs, vload3(i, n)), i, e);
}
