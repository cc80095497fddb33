/* Hammersley points and the GGX half-vector warp. Mirrors iblbake/sampling.py. */
#ifndef IBLBAKE_SAMPLING_H
#define IBLBAKE_SAMPLING_H

inline float radical_inverse_vdc(uint b)
{
    b = (b << 16) | (b >> 16);
    b = ((b & 0x55555555u) << 1) | ((b & 0xAAAAAAAAu) >> 1);
    b = ((b & 0x33333333u) << 2) | ((b & 0xCCCCCCCCu) >> 2);
    b = ((b & 0x0F0F0F0Fu) << 4) | ((b & 0xF0F0F0F0u) >> 4);
    b = ((b & 0x00FF00FFu) << 8) | ((b & 0xFF00FF00u) >> 8);
    return (float)b * 2.3283064365386963e-10f;
}

inline float2 hammersley(uint i, uint n)
{
    return (float2)((float)i / (float)n, radical_inverse_vdc(i));
}

/* GGX half-vector, local frame (z = normal). theta = atan2(alpha sqrt(u1), sqrt(1 - u1));
 * pdf over half-vectors = D(h) cos(theta_h). */
inline float3 sample_ggx_half(float2 u, float alpha)
{
    float phi = 2.0f * 3.14159265358979323846f * u.x;
    float theta = atan2(alpha * sqrt(u.y), sqrt(fmax(0.0f, 1.0f - u.y)));
    float st = sin(theta);
    return (float3)(st * cos(phi), st * sin(phi), cos(theta));
}

/* The same warp without trigonometry, for per-pixel loops: the host uploads (cos phi, sin phi, u1)
 * per Hammersley point; cos theta = sqrt((1 - u1) / (1 - u1 + alpha^2 u1)) is the atan2 form's cosine. */
inline float3 sample_ggx_half_cs(float4 pt, float alpha)
{
    const float a2u = alpha * alpha * pt.z;
    const float den = (1.0f - pt.z) + a2u;
    const float ct = den > 0.0f ? sqrt((1.0f - pt.z) / den) : 1.0f;
    const float st = den > 0.0f ? sqrt(a2u / den) : 0.0f;
    return (float3)(st * pt.x, st * pt.y, ct);
}

#endif
