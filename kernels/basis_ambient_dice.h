/* Ambient dice, RBF variant (iblbake/core/bases/ambient_dice.py, the twin): 12 icosahedron lobes,
 * each lobe's irradiance the exact degree-4 polynomial c0 + c1 t + c2 t^2 + c4 t^4 in t = v.n.
 * basis_coeffs: 12 rows (value rgb), 12 rows (vertex xyz), then (c0, c1, c2, c4).
 * Specular: each lobe averaged over the warped GGX lobe, h(v_i . r, lam_w), read from basis_table
 * (ambient_dice.py specular_table: AD_TABLE_ROWS rows of log2 lambda, AD_TABLE_COLS of v_i . r). */
#ifndef IBLBAKE_BASIS_AMBIENT_DICE_H
#define IBLBAKE_BASIS_AMBIENT_DICE_H
#include "inline.h"
#ifdef BASIS_AMBIENT_DICE
#define HAS_BASIS 1

IBL_INLINE float3 basis_irradiance(BASIS_SPACE const float4 *bc, float3 n)
{
    const float4 c = bc[24];
    float3 e = (float3)(0.0f);
    for (int i = 0; i < 12; ++i) {
        const float t = dot(bc[12 + i].xyz, n), t2 = t * t;
        e += bc[i].xyz * (c.x + c.y * t + c.z * t2 + c.w * t2 * t2);
    }
    return fmax(e, (float3)(0.0f));
}

#define HAS_BASIS_SPECULAR 1
#define BASIS_SPECULAR_ROWS 12
IBL_INLINE void basis_specular_weights(BASIS_SPACE const float4 *bc, __global const float *basis_table, float3 r,
                                   float lam_w, float *s)
{
    const float x = clamp((log2(fmax(lam_w, 1e-30f)) - AD_TABLE_LOG2_LO) / AD_TABLE_STEP, 0.0f,
                          (float)(AD_TABLE_ROWS - 1));
    const int x0 = min((int)x, AD_TABLE_ROWS - 2);
    const float fx = x - (float)x0;
    __global const float *row0 = basis_table + x0 * AD_TABLE_COLS, *row1 = row0 + AD_TABLE_COLS;
    float sum = 0.0f;
    for (int i = 0; i < 12; ++i) {
        const float y = (clamp(dot(bc[12 + i].xyz, r), -1.0f, 1.0f) + 1.0f) * 0.5f * (float)(AD_TABLE_COLS - 1);
        const int y0 = min((int)y, AD_TABLE_COLS - 2);
        const float fy = y - (float)y0;
        s[i] = mix(mix(row0[y0], row0[y0 + 1], fy), mix(row1[y0], row1[y0 + 1], fy), fx);
        sum += s[i];
    }
    for (int i = 0; i < 12; ++i) s[i] /= sum;      /* the exact h sum to 1: a uniform sky is exact */
}

#endif
#endif
