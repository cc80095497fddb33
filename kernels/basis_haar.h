/* Haar wavelets of the cube faces, the largest kept (iblbake/core/bases/haar.py, the twin: the
 * transform, the codes and Lambert's formula). basis_coeffs: HAAR_TERMS rows (value rgb, code),
 * code = ((face * 6 + s) * 4 + kind) * 1024 + by * 32 + bx. Irradiance exact for the kept terms:
 * each a signed sum of constant squares of a face, each square's cosine integral by Lambert's
 * formula on the square clipped to the normal's hemisphere. */
#ifndef IBLBAKE_BASIS_HAAR_H
#define IBLBAKE_BASIS_HAAR_H
#include "inline.h"
#ifdef BASIS_HAAR
#define HAS_BASIS 1
#define HAAR_FACE 32

IBL_INLINE float haar_segment(float3 a, float3 b, float3 n)
{
    const float3 c = cross(a, b);
    const float l = length(c);
    return l > 0.0f ? 0.5f * atan2(l, dot(a, b)) * dot(c, n) / l : 0.0f;
}

IBL_INLINE float3 haar_corner(int f, float s, float t)
{
    const float a = 2.0f * s - 1.0f, b = 2.0f * t - 1.0f;
    switch (f) {
    case 0: return (float3)(1.0f, -b, -a);
    case 1: return (float3)(-1.0f, -b, a);
    case 2: return (float3)(a, 1.0f, b);
    case 3: return (float3)(a, -1.0f, -b);
    case 4: return (float3)(a, -b, 1.0f);
    default: return (float3)(-a, -b, -1.0f);
    }
}

/* int over the face square of max(0, n.w) dw */
IBL_INLINE float haar_rect(int f, float s0, float t0, float s1, float t1, float3 n)
{
    float3 v[4] = {haar_corner(f, s0, t0), haar_corner(f, s0, t1), haar_corner(f, s1, t1), haar_corner(f, s1, t0)};
    if (dot(cross(v[1] - v[0], v[2] - v[0]), v[0]) < 0.0f) { const float3 w = v[1]; v[1] = v[3]; v[3] = w; }
    float e = 0.0f;
    float3 xo = (float3)(0.0f), xi = (float3)(0.0f);
    bool above = false, below = false;
    for (int i = 0; i < 4; ++i) {
        const float3 p = v[i], q = v[(i + 1) & 3];
        const float di = dot(n, p), dj = dot(n, q);
        if (di >= 0.0f) above = true; else below = true;
        const float3 x = di != dj ? p + (q - p) * (di / (di - dj)) : p;
        if (di >= 0.0f && dj >= 0.0f) e += haar_segment(p, q, n);
        else if (di >= 0.0f) { e += haar_segment(p, x, n); xo = x; }
        else if (dj >= 0.0f) { e += haar_segment(x, q, n); xi = x; }
    }
    return (above && below) ? e + haar_segment(xo, xi, n) : e;
}

IBL_INLINE float3 basis_irradiance(BASIS_SPACE const float4 *bc, float3 n)
{
    float3 e = (float3)(0.0f);
    for (int k = 0; k < HAAR_TERMS; ++k) {
        const int c = (int)bc[k].w, pos = c % 1024, rest = c / 1024;
        const int kind = rest % 4, fs = rest / 4, s = fs % 6, f = fs / 6, by = pos / 32, bx = pos % 32;
        if (kind == 0) {
            e += bc[k].xyz * (haar_rect(f, 0.0f, 0.0f, 1.0f, 1.0f, n) / (float)HAAR_FACE);
            continue;
        }
        const float w = (float)(1 << s) / (float)HAAR_FACE, h = 0.5f * w, s0 = bx * w, t0 = by * w;
        const float tl = haar_rect(f, s0, t0, s0 + h, t0 + h, n), tr = haar_rect(f, s0 + h, t0, s0 + w, t0 + h, n);
        const float bl = haar_rect(f, s0, t0 + h, s0 + h, t0 + w, n);
        const float br = haar_rect(f, s0 + h, t0 + h, s0 + w, t0 + w, n);
        const float sum = kind == 1 ? tl + tr - bl - br : kind == 2 ? tl - tr + bl - br : tl - tr - bl + br;
        e += bc[k].xyz * (sum / (float)(1 << s));
    }
    return fmax(e, (float3)(0.0f));
}

#endif
#endif
