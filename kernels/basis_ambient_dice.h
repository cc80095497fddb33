/* Ambient dice, RBF variant (iblbake/core/bases/ambient_dice.py, the twin): 12 icosahedron lobes,
 * each lobe's irradiance the exact degree-4 polynomial c0 + c1 t + c2 t^2 + c4 t^4 in t = v.n.
 * basis_coeffs: 12 rows (value rgb), 12 rows (vertex xyz), then (c0, c1, c2, c4). */
#ifndef IBLBAKE_BASIS_AMBIENT_DICE_H
#define IBLBAKE_BASIS_AMBIENT_DICE_H
#ifdef BASIS_AMBIENT_DICE
#define HAS_BASIS 1

inline float3 basis_irradiance(BASIS_SPACE const float4 *bc, float3 n)
{
    const float4 c = bc[24];
    float3 e = (float3)(0.0f);
    for (int i = 0; i < 12; ++i) {
        const float t = dot(bc[12 + i].xyz, n), t2 = t * t;
        e += bc[i].xyz * (c.x + c.y * t + c.z * t2 + c.w * t2 * t2);
    }
    return fmax(e, (float3)(0.0f));
}

#endif
#endif
