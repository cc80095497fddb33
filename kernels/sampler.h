/* Random and quasi-random numbers: Hammersley sets, the PCG hash, Halton points with
 * Cranley-Patterson rotations (qmc), and the Sampler that hands a kernel the dimensions of one
 * sample in order. Mirrors iblbake/core/sampling.py. */
#ifndef IBLBAKE_SAMPLER_H
#define IBLBAKE_SAMPLER_H
#include "inline.h"

IBL_INLINE uint reverse_bits32(uint x)
{
    x = (x << 16) | (x >> 16);
    x = ((x & 0x00FF00FFu) << 8) | ((x & 0xFF00FF00u) >> 8);
    x = ((x & 0x0F0F0F0Fu) << 4) | ((x & 0xF0F0F0F0u) >> 4);
    x = ((x & 0x33333333u) << 2) | ((x & 0xCCCCCCCCu) >> 2);
    return ((x & 0x55555555u) << 1) | ((x & 0xAAAAAAAAu) >> 1);
}

/* Van der Corput's radical inverse in base 2: the index's bits mirrored about the point */
IBL_INLINE float radical_inverse_vdc(uint b)
{
    return (float)reverse_bits32(b) * 2.3283064365386963e-10f;
}

IBL_INLINE float2 hammersley(uint i, uint n)
{
    return (float2)((float)i / (float)n, radical_inverse_vdc(i));
}

/* PCG hash (Jarzynski and Olano 2020, "Hash Functions for GPU Rendering"): one 32-bit state step
 * of PCG plus its output permutation. */
IBL_INLINE uint pcg_hash(uint x)
{
    uint state = x * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

IBL_INLINE float hash_uniform(uint x)
{
    return (float)(pcg_hash(x) >> 8) * (1.0f / 16777216.0f);
}

/* Radical inverse of j in base b: Halton points, a quasi-random sequence that stays uniform at
 * every prefix, so a frame converges faster than with independent random numbers. */
IBL_INLINE float radical_inverse(uint j, uint b)
{
    const float inv_b = 1.0f / (float)b;
    float f = inv_b, r = 0.0f;
    while (j > 0u) {
        r += f * (float)(j % b);
        j /= b;
        f *= inv_b;
    }
    return fmin(r, 0x1.fffffep-1f);
}

/* Dimension d of sample j of replicate `rep` for G-buffer sample gid: Halton in base 2, 3, 5,
 * 7, 11, 13, 17, 19 (the twin's HALTON_BASES), shifted by a random rotation per (seed, gid,
 * replicate, dimension) (Cranley-Patterson). Two replicates (even and odd sample numbers) with independent rotations
 * give an honest error estimate (their difference); a variance of QMC samples would not. */
IBL_INLINE float qmc(uint seed, uint gid, uint k, int d)
{
    const uint rep = k & 1u, j = k >> 1;
    const float shift = hash_uniform(seed ^ pcg_hash(gid * 16u + rep * 8u + (uint)d));
    float r;
    switch (d) {            /* each base a constant: its divisions become multiplications */
    case 0: r = radical_inverse(j, 2u); break;
    case 1: r = radical_inverse(j, 3u); break;
    case 2: r = radical_inverse(j, 5u); break;
    case 3: r = radical_inverse(j, 7u); break;
    case 4: r = radical_inverse(j, 11u); break;
    case 5: r = radical_inverse(j, 13u); break;
    case 6: r = radical_inverse(j, 17u); break;
    default: r = radical_inverse(j, 19u); break;
    }
    const float x = r + shift;
    return x >= 1.0f ? x - 1.0f : x;
}

/* One sample's dimensions, handed out in the order a kernel asks for them, as pbrt-v4's Sampler
 * (Get1D, Get2D) and Mitsuba 3's (next_1d, next_2d) do: no kernel numbers a dimension by hand.
 * `seed` already carries the stream (the reference's seed, AO's seed ^ STREAM_AO, a light's);
 * `gid` the G-buffer sample's number in the frame, `k` the sample's number. The first 8 dimensions
 * are Halton's (HALTON_BASES), a path's later ones Owen-scrambled Sobol pairs (owen_sobol_pair). */
typedef struct {
    uint seed, gid, k;
    uint stream;            /* a path's own stream past the first 8: (seed, G-buffer sample, replicate) */
    int dim;
} Sampler;

IBL_INLINE Sampler sampler_start(uint seed, uint gid, uint k)
{
    Sampler s;
    s.seed = seed; s.gid = gid; s.k = k; s.dim = 0;
    s.stream = pcg_hash(seed ^ pcg_hash(gid * 2u + (k & 1u)));
    return s;
}

/* A path's dimensions past the first 8: pairs of Owen-scrambled Sobol points, each pair's
 * sequence shuffled by its own nested uniform scramble of the index (Burley 2020, "Practical
 * Hash-based Owen Scrambling", JCGT 9(4)): stratified in every pair at every sample count, each
 * pair independent of the others. */

IBL_INLINE uint laine_karras_permutation(uint x, uint seed)
{
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}

IBL_INLINE uint nested_uniform_scramble(uint x, uint seed)
{
    return reverse_bits32(laine_karras_permutation(reverse_bits32(x), seed));
}

/* Sobol's second dimension (direction numbers v0 = 2^31, v_k = v_{k-1} ^ (v_{k-1} >> 1): row k of
 * Pascal's triangle mod 2, whose bit q from the top is set where q is a subset of k's bits, by
 * Lucas's theorem), bit-reversed: bit q of the result is the parity of i's bits k over every k
 * whose bits hold q's, a superset-sum (zeta) transform over the 5 bits of a bit position, done on
 * the word in 5 shift-and-xor steps instead of a loop over i's 32 bits. Its first dimension,
 * bit-reversed, is i itself (van der Corput). */
IBL_INLINE uint sobol_dim1_reversed(uint i)
{
    i ^= (i >> 1) & 0x55555555u;
    i ^= (i >> 2) & 0x33333333u;
    i ^= (i >> 4) & 0x0F0F0F0Fu;
    i ^= (i >> 8) & 0x00FF00FFu;
    i ^= (i >> 16) & 0x0000FFFFu;
    return i;
}

/* Pair p of sample j of one stream (its seed: the sample's stream, G-buffer sample and replicate
 * hashed): the index shuffled by the pair's own scramble, then each coordinate's Owen scramble.
 * nested_uniform_scramble(x) = reverse(permutation(reverse(x))), and the two coordinates before
 * it are reverse(i) and reverse(sobol_dim1_reversed(i)): the reversals cancel. */
IBL_INLINE float2 owen_sobol_pair(uint j, uint stream, int p)
{
    const uint s = pcg_hash(stream ^ pcg_hash((uint)p + 0x51ED27u));
    const uint i = nested_uniform_scramble(j, s);
    const uint x = reverse_bits32(laine_karras_permutation(i, pcg_hash(s + 1u)));
    const uint y = reverse_bits32(laine_karras_permutation(sobol_dim1_reversed(i), pcg_hash(s + 2u)));
    return (float2)((float)(x >> 8), (float)(y >> 8)) * (1.0f / 16777216.0f);
}

IBL_INLINE float sampler_1d(Sampler *s)
{
    const int d = s->dim++;
    if (d < 8) return qmc(s->seed, s->gid, s->k, d);
    const float2 u = owen_sobol_pair(s->k >> 1, s->stream, (d - 8) >> 1);
    return (d - 8) & 1 ? u.y : u.x;
}

/* Two dimensions; past the first 8 and starting a pair (a path vertex's draws all do), both
 * coordinates of one scrambled index */
IBL_INLINE float2 sampler_2d(Sampler *s)
{
    if (s->dim >= 8 && !((s->dim - 8) & 1)) {
        const int d = s->dim;
        s->dim += 2;
        return owen_sobol_pair(s->k >> 1, s->stream, (d - 8) >> 1);
    }
    const float a = sampler_1d(s);
    return (float2)(a, sampler_1d(s));
}

#endif
