/* Shared conventions (docs/conventions.md) in OpenCL C. Mirrors iblbake/core/conventions.py; tested against it
 * (tests/test_conventions.py). +y up; equirect u = 0.5 - atan2(x, z)/(2 pi), v = acos(y)/pi,
 * v = 0 the top row; cube faces +X -X +Y -Y +Z -Z; octahedral with +y at the centre. */
#ifndef IBLBAKE_COMMON_H
#define IBLBAKE_COMMON_H
#include "inline.h"

#include "layout.h"

#define IBL_PI 3.14159265358979323846f

/* Rec. 709 relative luminance of linear RGB (the weights: iblbake/core/metrics.py LUMINANCE,
 * through layout.h) */
IBL_INLINE float luminance(float3 c)
{
    return dot(c, (float3)(LUMINANCE_R, LUMINANCE_G, LUMINANCE_B));
}

/* x / |x| for the non-zero, finite vectors of shading (a half vector, a light direction):
 * PoCL's normalize guards against overflow and underflow and took as long as the rest of the
 * lights pass's shading (0.02 s a 1280x720 frame); rsqrt of the squared length is within an
 * ulp or two of it there. */
IBL_INLINE float3 unit3(float3 x)
{
    return x * rsqrt(dot(x, x));
}

/* x^e for x >= 0 as exp2(e log2 x), 0 for x = 0: PoCL's pow costs more than whole passes (the
 * tone map's encoding, GTAO's power, the specular occlusion) */
IBL_INLINE float pow_fast(float x, float e)
{
    return x > 0.0f ? exp2(e * log2(x)) : 0.0f;
}

IBL_INLINE float3 pow_fast3(float3 x, float e)
{
    return select(exp2(e * log2(x)), (float3)(0.0f), islessequal(x, (float3)(0.0f)));
}

/* atan2pi and acospi: the angles in units of pi, as u and v want them; 2.6x cheaper than atan2 and
 * acos on PoCL (benchmarks/bench_trig.py) */
IBL_INLINE float2 equirect_uv_from_dir(float3 d)
{
    float u = 0.5f - 0.5f * atan2pi(d.x, d.z);
    u = u - floor(u);                     /* the seam (atan2 = -pi) wraps to 0 */
    const float v = acospi(clamp(d.y, -1.0f, 1.0f));
    return (float2)(u, v);
}

/* (cos, sin) of 2 pi t. PoCL's sin and cos reduce any argument the long way (a few percent of a
 * path's time); cospi and sinpi reduce it exactly, 4.4x faster there, and 2t is not rounded as
 * 2 pi t is (benchmarks/bench_trig.py) */
IBL_INLINE float2 cossin_2pi(float t)
{
    return (float2)(cospi(2.0f * t), sinpi(2.0f * t));
}

IBL_INLINE float3 dir_from_equirect_uv(float2 uv)
{
    const float2 cs = cossin_2pi(0.5f - uv.x);          /* phi = 2 pi (0.5 - u), theta = pi v */
    const float st = sinpi(uv.y);
    return (float3)(st * cs.y, cospi(uv.y), st * cs.x);
}

/* Exact solid angle of a texel in row j of a W x H equirect image:
 * (2 pi / W)(cos(pi j/H) - cos(pi (j+1)/H)) = (4 pi / W) sin(pi (j + 1/2)/H) sin(pi / (2H)),
 * with the first sine taken from the nearer pole so float32 keeps its relative precision. */
IBL_INLINE float equirect_row_solid_angle(int j, int width, int height)
{
    float c = fmin((float)j + 0.5f, (float)(height - j) - 0.5f);
    return (4.0f * IBL_PI / (float)width) * sin(IBL_PI * c / (float)height) * sin(0.5f * IBL_PI / (float)height);
}

/* Bilinear lookup in an RGB float image (3 floats a texel): wraps in u, clamps in v. */
IBL_INLINE float3 bilinear_equirect(__global const float *img, int width, int height, float2 uv)
{
    float x = uv.x * (float)width - 0.5f;
    float y = clamp(uv.y * (float)height - 0.5f, 0.0f, (float)(height - 1));
    float fx0 = floor(x), fy0 = floor(y);
    float fx = x - fx0, fy = y - fy0;
    int x0 = (int)fx0 % width; if (x0 < 0) x0 += width;
    int x1 = x0 + 1; if (x1 == width) x1 = 0;
    int y0 = min((int)fy0, height - 1), y1 = min(y0 + 1, height - 1);
    float3 a = mix(vload3(y0 * width + x0, img), vload3(y0 * width + x1, img), fx);
    float3 b = mix(vload3(y1 * width + x0, img), vload3(y1 * width + x1, img), fx);
    return mix(a, b, fy);
}

/* Face coordinates s, t in [0, 1] (t = 0 the top row) of face 0..5 -> unit direction. */
IBL_INLINE float3 dir_from_cube(int face, float s, float t)
{
    float a = 2.0f * s - 1.0f, b = 2.0f * t - 1.0f;
    float3 d;
    switch (face) {
    case 0: d = (float3)(1.0f, -b, -a); break;
    case 1: d = (float3)(-1.0f, -b, a); break;
    case 2: d = (float3)(a, 1.0f, b); break;
    case 3: d = (float3)(a, -1.0f, -b); break;
    case 4: d = (float3)(a, -b, 1.0f); break;
    default: d = (float3)(-a, -b, -1.0f); break;
    }
    return normalize(d);
}

/* The inverse of dir_from_cube: face by the major axis (Vulkan's cube-map face selection, ties
 * to x, then y) and its (s, t) in [0, 1]. */
IBL_INLINE float2 cube_from_dir(float3 d, int *face)
{
    const float ax = fabs(d.x), ay = fabs(d.y), az = fabs(d.z);
    float sc, tc, ma;
    if (ax >= ay && ax >= az) {
        ma = ax; tc = -d.y;
        if (d.x > 0.0f) { *face = 0; sc = -d.z; } else { *face = 1; sc = d.z; }
    } else if (ay >= az) {
        ma = ay; sc = d.x;
        if (d.y > 0.0f) { *face = 2; tc = d.z; } else { *face = 3; tc = -d.z; }
    } else {
        ma = az; tc = -d.y;
        if (d.z > 0.0f) { *face = 4; sc = d.x; } else { *face = 5; sc = -d.x; }
    }
    return (float2)(0.5f * (sc / ma + 1.0f), 0.5f * (tc / ma + 1.0f));
}

IBL_INLINE float3 dir_from_octahedral(float u, float v)
{
    float x = 2.0f * u - 1.0f, z = 2.0f * v - 1.0f;
    float y = 1.0f - fabs(x) - fabs(z);
    if (y < 0.0f) {
        float sx = x >= 0.0f ? 1.0f : -1.0f, sz = z >= 0.0f ? 1.0f : -1.0f;
        float nx = (1.0f - fabs(z)) * sx, nz = (1.0f - fabs(x)) * sz;
        x = nx; z = nz;
    }
    return normalize((float3)(x, y, z));
}

/* Orthonormal t, b with cross(t, b) = n, finite for every unit n (Duff et al. 2017). */
IBL_INLINE void tangent_frame(float3 n, float3 *t, float3 *b)
{
    float sign = copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float c = n.x * n.y * a;
    *t = (float3)(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
    *b = (float3)(c, sign + n.y * n.y * a, -n.y);
}

#endif
