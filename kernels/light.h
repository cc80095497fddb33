/* An analytic light seen from a point: its records (kernels/layout.h LIGHT_FLOAT4S, packed by
 * iblbake/scene/pack.py light_records) in the units of glTF's KHR_lights_punctual (lux for a
 * directional light, candela for point and spot lights, the spec's range window and spot
 * falloff), for the lights pass (kernels/lights.cl) and the reference's path vertices
 * (kernels/paths/reference.cl). numpy twin: iblbake/render/twin/lights.py. */
#ifndef IBLBAKE_LIGHT_H
#define IBLBAKE_LIGHT_H
#include "common.h"
#include "layout.h"

/* Light j seen from p: the direction towards its centre (*wc), the distance a shadow ray may
 * travel (*dist, to the sphere's surface; infinite for a directional light), the sine of the
 * angular radius it fills (*sin_max; 0 for a point), and the irradiance it gives a surface facing
 * it (range window and spot falloff applied). */
IBL_INLINE float3 light_toward(__global const float4 *lights, int j, float3 p, float3 *wc, float *dist, float *sin_max)
{
    const float4 r0 = lights[LIGHT_FLOAT4S * j], r1 = lights[LIGHT_FLOAT4S * j + 1];
    const float4 r2 = lights[LIGHT_FLOAT4S * j + 2], r3 = lights[LIGHT_FLOAT4S * j + 3];
    const int kind = (int)r0.w;
    float3 e = r1.xyz;
    *dist = INFINITY;
    if (kind == LIGHT_DIRECTIONAL) {
        *wc = r0.xyz;
        *sin_max = r2.w;                 /* the sine of its angular radius */
    } else {
        const float3 dv = r0.xyz - p;
        const float d = length(dv);
        *wc = dv / d;
        float win = 1.0f / (d * d);
        if (r3.z > 0.0f) {           /* KHR: clamp(1 - (d / range)^4, 0, 1)^2 / d^2 */
            float q = d / r3.z;
            q = q * q;
            const float c = clamp(1.0f - q * q, 0.0f, 1.0f);
            win *= c * c;
        }
        const float a = clamp(dot(r2.xyz, -*wc) * r3.x + r3.y, 0.0f, 1.0f);   /* spot (1 for a point) */
        e *= win * a * a;
        *sin_max = fmin(r2.w / d, 1.0f);
        *dist = fmax(d - r2.w, 0.0f);
    }
    return e;
}

/* 1 - cos of the cone a light of angular radius asin(sin_max) fills, without cancellation */
IBL_INLINE float light_omc(float sin_max)
{
    return sin_max * sin_max / (1.0f + sqrt(fmax(0.0f, 1.0f - sin_max * sin_max)));
}

/* Uniform in the cone around axis a whose 1 - cos(half angle) is omc (kept apart: the sun's is
 * 1e-5, which 1 - cos in float32 would round); pdf 1 / (2 pi omc). */
IBL_INLINE float3 cone_direction(float3 a, float omc, float2 u)
{
    const float x = u.x * omc;
    const float ct = 1.0f - x, st = sqrt(fmax(0.0f, x * (2.0f - x)));
    const float2 cs = cossin_2pi(u.y);
    float3 t, b;
    tangent_frame(a, &t, &b);
    return normalize(t * (st * cs.x) + b * (st * cs.y) + a * ct);
}

#endif
