/* The directional bases of the panorama's diffuse light (iblbake/core/bases/: the registry and the
 * float64 twins; render/sources/basis.py binds basis_coeffs). The scene's basis is the one define
 * BASIS_<NAME> set; only its header's code is compiled, and it defines HAS_BASIS and
 *     float3 basis_irradiance(BASIS_SPACE const float4 *basis_coeffs, float3 n)
 * the radiometric irradiance int L max(0, n.w) dw at the environment-frame normal n, clamped at 0.
 * A basis that carries a specular lobe (core/bases SPECULAR) also defines HAS_BASIS_SPECULAR,
 * BASIS_SPECULAR_ROWS and
 *     void basis_specular_weights(BASIS_SPACE const float4 *basis_coeffs,
 *                                 __global const float *basis_table, float3 r, float lam_w, float *s)
 * s[k] such that the radiance along the warped GGX lobe about r of sharpness lam_w is
 * sum_k s[k] c_k (linear in the coefficients, so the probes weigh it once a point, not a probe). */
#ifndef IBLBAKE_BASES_H
#define IBLBAKE_BASES_H
#include "inline.h"

/* where basis_irradiance reads its coefficients: the distant basis's are __constant; the probes'
 * (kernels/probes.h, PROBES_BASIS) one block per probe in a __global buffer */
#ifndef BASIS_SPACE
#define BASIS_SPACE __constant
#endif

/* each basis's header (generated from core/bases: make docs) */
#include "basis_headers.h"

#ifdef HAS_BASIS_SPECULAR
/* the warped lobe's sharpness at alpha = roughness^2 and n.v (core/bases/common.py warp_sharpness) */
IBL_INLINE float basis_warp_sharpness(float alpha, float nov)
{
    return 2.0f / fmax(alpha * alpha, 1e-8f) / (4.0f * fmax(nov, 1e-4f));
}

/* sum_k s[k] c_k of one coefficient block, clamped at 0 (core/bases specular_radiance) */
IBL_INLINE float3 basis_weighted(BASIS_SPACE const float4 *bc, const float *s)
{
    float3 e = (float3)(0.0f);
    for (int k = 0; k < BASIS_SPECULAR_ROWS; ++k) e += bc[k].xyz * s[k];
    return fmax(e, (float3)(0.0f));
}

IBL_INLINE float3 basis_specular_radiance(BASIS_SPACE const float4 *bc, __global const float *basis_table, float3 r,
                                      float lam_w)
{
    float s[BASIS_SPECULAR_ROWS];
    basis_specular_weights(bc, basis_table, r, lam_w, s);
    return basis_weighted(bc, s);
}
#endif

#endif
