/* Importance pass (IMPORTANCE_ACCEPTED, FORCE_MIP0): the importance-sampled specular integral
 * split around Schlick's Fresnel into two sums per sample, which the shade pass (kernels/shade.cl)
 * combines with f0. numpy twin: iblbake/render/twin/shade.py shade(). */
#include "common.h"
#include "brdf.h"
#include "sampling.h"
#include "envmap.h"
/* contraction off from here, as in the frame's other kernels (scene.h turns it off before
 * surface.h in each): the same float results in every program this file is built into */
#pragma OPENCL FP_CONTRACT OFF
#include "surface.h"

/* The importance-sampled specular integral split around Schlick's Fresnel. With
 * F = f0 (1 - c) + f90 c, c = (1 - VoH)^5, the estimate sum L F w (w = V 4 NoL VoH / NoH: f NoL / pdf
 * without F) is f0 sum L w (1 - c) + f90 sum L w c, the split Karis (2013, "Real Shading in Unreal
 * Engine 4") makes for the DFG table, here per sample. The two sums depend on the surface, its
 * roughness and the panorama but not on f0 or f90: frames that change only base colour, metallic
 * or the specular factors (a sheet's metallic axis) reuse them, and shade adds f0 A + f90 B. N Hammersley points, GGX
 * half-vector warp, mip level from the pdf (filtered importance sampling: Colbert and Krivanek,
 * GPU Gems 3 ch. 20, 2007). */
__kernel void importance(__global const float4 *gb_pos, SURFACE_PARAMS, const int n, const float2 env_rot,
                         CHAIN_PARAMS, __global const float4 *hammersley_pts, const int nsamples,
                         const float mip_bias, __global float4 *spec_sums)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    if (gb_pos[gid].w == MISS_T) return;
    Material mt;
    float3 v, nrm;
    const float nov = surface_at(SURFACE_ARGS, gid, &mt, &v, &nrm);
    float3 t, b;
    tangent_frame(nrm, &t, &b);
    const int w0 = lw[0], h0 = lh[0];
    float3 sa = (float3)(0.0f), sb = (float3)(0.0f);
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
#ifndef FORCE_MIP0
        /* solid angle of this sample, 1 / (N pdf(l)), pdf(l) = D(h) NoH / (4 VoH) */
        const float pdf = d_ggx(noh, mt.alpha) * noh / (4.0f * voh);
        const float3 le = to_env(l, env_rot);
        const float lod = -0.5f * log2((float)nsamples * pdf * texel_solid_angle(le, w0, h0)) + mip_bias;
        const float3 li = chain_lookup(CHAIN_ARGS, le, lod);
#else
        const float3 li = chain_lookup(CHAIN_ARGS, to_env(l, env_rot), 0.0f);
#endif
        /* f NoL / pdf = F V 4 NoL VoH / NoH  (D cancels) */
        const float3 lwt = li * (v_smith_ggx_correlated(nov, nol, mt.alpha) * 4.0f * nol * voh / noh);
        const float c = schlick_weight(voh);
        sa += lwt * (1.0f - c);
        sb += lwt * c;
    }
#ifdef IMPORTANCE_ACCEPTED
    const float norm = 1.0f / (float)max(accepted, 1);
#else
    const float norm = 1.0f / (float)nsamples;
#endif
    spec_sums[2 * gid] = (float4)(sa * norm, 0.0f);
    spec_sums[2 * gid + 1] = (float4)(sb * norm, 0.0f);
}
