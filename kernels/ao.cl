/* Ambient occlusion pass (effects.ao: raytraced): per G-buffer sample the cosine-weighted
 * fraction of ao_samples rays (Owen-scrambled Sobol points, a sequence per sample) that leave
 * without a hit closer than ao_radius: the visibility the IBL's diffuse term assumes is 1. Written to `ao`; the shade
 * pass multiplies its diffuse term by it, and its specular term by Lagarde's specular occlusion.
 * numpy twin: iblbake/render/twin/ao.py ambient_occlusion(). */
#include "common.h"
#include "sampling.h"
#include "scene.h"
#include "surface.h"

__kernel void ao(__global const float4 *gb_pos, __global const float4 *gb_nrm, __global const float4 *gb_dir,
                 const int n, SCENE_PARAMS, const int pixel0, const int spp, const uint ao_seed,
                 const int ao_samples, const float ao_radius, __global float *ao_buf)
{
    const int gid = get_global_id(0);
    if (gid >= n) return;
    const float4 hitp = gb_pos[gid];
    if (hitp.w == MISS_T) { ao_buf[gid] = 1.0f; return; }
    const uint sid = (uint)(pixel0 * spp + gid);
    const float3 v = -gb_dir[gid].xyz;
    const float3 nrm = facing_normal(gb_nrm[gid].xyz, v);
    const float3 origin = ray_offset(hitp.xyz, nrm, gb_dir[gid].xyz, hitp.w);
    float3 t, b;
    tangent_frame(nrm, &t, &b);
    int open = 0;
    for (int k = 0; k < ao_samples; ++k) {
        Sampler sp = sampler_start(ao_seed ^ STREAM_AO, sid, k);
        const float3 l = sample_cosine_hemisphere(sampler_2d(&sp));
        open += !occluded_to(origin, t * l.x + b * l.y + nrm * l.z, ao_radius, SCENE_ARGS);
    }
    ao_buf[gid] = (float)open / (float)ao_samples;
}
