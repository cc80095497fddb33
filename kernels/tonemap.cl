/* The tone-mapping pass: linear HDR frame -> 8-bit display frame (see tonemap.h). */
#include "tonemap.h"

__kernel void tonemap_u8(__global const float4 *hdr, const float exposure_scale, const float gamma,
                         const int n, __global uchar4 *out, __global float4 *display)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const float3 y = tonemap_display(hdr[i].xyz, exposure_scale, gamma);
    display[i] = (float4)(y, 1.0f);
    const float3 q = floor(y * 255.0f + 0.5f);
    out[i] = (uchar4)((uchar)q.x, (uchar)q.y, (uchar)q.z, (uchar)255);
}
