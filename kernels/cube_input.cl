/* A cube map (faces +X -X +Y -Y +Z -Z of s x s, stacked) resampled to an equirect panorama of
 * w x h: each texel the mean of the cube map's box texels over its solid angle, estimated by
 * n x n jittered strata uniform in (u, cos theta), i.e. in solid angle (iblbake/bake/inputs.py
 * cube_to_equirect is the numpy twin; the jitter is the same PCG hash of the sample's index). */
#include "common.h"
#include "sampling.h"

__kernel void cube_to_equirect(__global const float4 *faces, const int s, const int w, const int h, const int n,
                               __global float4 *out)
{
    const int i = get_global_id(0), j = get_global_id(1);
    if (i >= w || j >= h) return;
    const float y0 = cos(IBL_PI * (float)j / (float)h), y1 = cos(IBL_PI * (float)(j + 1) / (float)h);
    const uint base = (uint)(j * w + i) * (uint)(n * n);
    float4 acc = (float4)(0.0f);
    for (int b = 0; b < n; ++b) {
        for (int a = 0; a < n; ++a) {
            const uint k = 2u * (base + (uint)(b * n + a));
            const float u = ((float)i + ((float)a + hash_uniform(k)) / (float)n) / (float)w;
            const float y = clamp(y0 + (y1 - y0) * ((float)b + hash_uniform(k + 1u)) / (float)n, -1.0f, 1.0f);
            /* dir_from_equirect_uv without the acos: y is cos(theta) already */
            float cphi;
            const float sphi = sincos(2.0f * IBL_PI * (0.5f - u), &cphi), st = sqrt(fmax(0.0f, 1.0f - y * y));
            int face;
            const float2 st2 = cube_from_dir((float3)(st * sphi, y, st * cphi), &face);
            const int col = min((int)(st2.x * (float)s), s - 1), row = min((int)(st2.y * (float)s), s - 1);
            acc += faces[(face * s + row) * s + col];
        }
    }
    out[j * w + i] = acc / (float)(n * n);
}
