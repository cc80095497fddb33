/* Warps of the hemisphere and cones, each a pair sample_x / pdf_x (pbrt-v4's habit), and the
 * MIS weight. GGX's warps are in ggx.h, the environment's in envmap.h, the random numbers in
 * sampler.h. Mirrors iblbake/core/sampling.py; tests/test_sampling.py checks every warp against
 * its own pdf with a chi-square test on both sides (Mitsuba 3's ChiSquareTest). */
#ifndef IBLBAKE_SAMPLING_H
#define IBLBAKE_SAMPLING_H
#include "common.h"
#include "ggx.h"
#include "sampler.h"

/* Local frame z = normal. */

/* Cosine-weighted hemisphere (Malley's method: a uniform disk point lifted to the hemisphere);
 * pdf = cos(theta) / pi. */
IBL_INLINE float3 sample_cosine_hemisphere(float2 u)
{
    const float r = sqrt(u.x);
    const float2 cs = cossin_2pi(u.y);
    return (float3)(r * cs.x, r * cs.y, sqrt(fmax(0.0f, 1.0f - u.x)));
}

IBL_INLINE float pdf_cosine_hemisphere(float cos_theta)
{
    return fmax(cos_theta, 0.0f) * (1.0f / IBL_PI);
}

/* Uniform in the cone cos(theta) >= cos_max (a sphere light or the sun seen from a point):
 * cos(theta) = 1 - u (1 - cos_max); pdf = 1 / (2 pi (1 - cos_max)). */
IBL_INLINE float3 sample_uniform_cone(float2 u, float cos_max)
{
    const float ct = 1.0f - u.x * (1.0f - cos_max);
    const float st = sqrt(fmax(0.0f, 1.0f - ct * ct));
    const float2 cs = cossin_2pi(u.y);
    return (float3)(st * cs.x, st * cs.y, ct);
}

IBL_INLINE float pdf_uniform_cone(float cos_max)
{
    return 1.0f / (2.0f * IBL_PI * (1.0f - cos_max));
}

/* ---- multiple importance sampling */

/* Power heuristic a^2 / (a^2 + b^2) (Veach 1997), written so that an infinite or huge pdf (a
 * near-mirror lobe) gives 1 or 0 instead of inf / inf. */
IBL_INLINE float power_heuristic(float a, float b)
{
    if (!(a > 0.0f)) return 0.0f;
    const float r = b / a;
    return 1.0f / (1.0f + r * r);
}

#endif
