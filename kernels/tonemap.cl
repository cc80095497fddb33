/* The tone-mapping pass: linear HDR frame -> 8-bit display frame (see tonemap.h).
 * DITHER: add triangular noise of +-1 LSB (a fixed hash of the pixel index, so frames stay
 * bit-identical run to run, and the same in a tiled frame: pixel0 + i) before rounding; twin: iblbake/core/tonemap.py dither_offsets. */
/* Contraction off, as in a frame's one program, where kernels/scene.h (included by the passes
 * before this file) turned it off for the rest of the program: the tone map alone in a sheet's
 * program then rounds as in `iblbake render` (with it on, a*b+c fused into an fma put one pixel
 * one code value off). */
#pragma OPENCL FP_CONTRACT OFF
#include "tonemap.h"
#include "sampler.h"

__kernel void tonemap_u8(__global const float4 *hdr, const float exposure_scale, const float gamma,
                         const int n, const int pixel0, __global uchar4 *png_u8, __global float4 *display)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const float3 y = tonemap_display(hdr[i].xyz, exposure_scale, gamma);
    display[i] = (float4)(y, 1.0f);
#ifdef DITHER
    const uint h1 = pcg_hash((uint)(pixel0 + i)), h2 = pcg_hash(h1);
    const float tri = (float)(h1 >> 8) * (1.0f / 16777216.0f) + (float)(h2 >> 8) * (1.0f / 16777216.0f) - 1.0f;
    const float3 q = clamp(floor(y * 255.0f + 0.5f + tri), 0.0f, 255.0f);
#else
    const float3 q = floor(y * 255.0f + 0.5f);
#endif
    png_u8[i] = (uchar4)((uchar)q.x, (uchar)q.y, (uchar)q.z, (uchar)255);
}
