/* The directional bases of the panorama's diffuse light (iblbake/core/bases/: the registry and the
 * float64 twins; render/sources/basis.py binds basis_coeffs). The scene's basis is the one define
 * BASIS_<NAME> set; only its header's code is compiled, and it defines HAS_BASIS and
 *     float3 basis_irradiance(BASIS_SPACE const float4 *basis_coeffs, float3 n)
 * the radiometric irradiance int L max(0, n.w) dw at the environment-frame normal n, clamped at 0. */
#ifndef IBLBAKE_BASES_H
#define IBLBAKE_BASES_H

/* where basis_irradiance reads its coefficients: the distant basis's are __constant; the probes'
 * (kernels/probes.h, PROBES_BASIS) one block per probe in a __global buffer */
#ifndef BASIS_SPACE
#define BASIS_SPACE __constant
#endif

#include "basis_l1_geomerics.h"
#include "basis_zh3.h"
#include "basis_sg.h"
#include "basis_ambient_dice.h"
#include "basis_haar.h"

#endif
