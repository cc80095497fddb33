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

/* Dimension d of sample j of replicate `rep` for G-buffer sample gid: Halton in base
 * HALTON_BASES[d], shifted by a random rotation per (seed, gid, replicate, dimension)
 * (Cranley-Patterson). Two replicates (even and odd sample numbers) with independent rotations
 * give an honest error estimate (their difference); a variance of QMC samples would not. */
__constant uint HALTON_BASES[8] = {2u, 3u, 5u, 7u, 11u, 13u, 17u, 19u};

IBL_INLINE float qmc(uint seed, uint gid, uint k, int d)
{
    const uint rep = k & 1u, j = k >> 1;
    const float shift = hash_uniform(seed ^ pcg_hash(gid * 16u + rep * 8u + (uint)d));
    const float x = radical_inverse(j, HALTON_BASES[d]) + shift;
    return x >= 1.0f ? x - 1.0f : x;
}

/* One sample's dimensions, handed out in the order a kernel asks for them, as pbrt-v4's Sampler
 * (Get1D, Get2D) and Mitsuba 3's (next_1d, next_2d) do: no kernel numbers a dimension by hand.
 * `seed` already carries the stream (the reference's seed, AO's seed ^ STREAM_AO, a light's);
 * `gid` the G-buffer sample's number in the frame, `k` the sample's number. The first 8 dimensions
 * are Halton's (HALTON_BASES), a path's later ones Owen-scrambled Sobol pairs (owen_sobol). */
typedef struct {
    uint seed, gid, k;
    int dim;
} Sampler;

IBL_INLINE Sampler sampler_start(uint seed, uint gid, uint k)
{
    Sampler s;
    s.seed = seed; s.gid = gid; s.k = k; s.dim = 0;
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

/* Sobol's second dimension (direction numbers v0 = 2^31, v_k = v_{k-1} ^ (v_{k-1} >> 1)); its
 * first is the van der Corput sequence, reverse_bits32(i) */
IBL_INLINE uint sobol_dim1(uint i)
{
    uint r = 0u, v = 0x80000000u;
    for (; i != 0u; i >>= 1, v ^= v >> 1)
        if (i & 1u) r ^= v;
    return r;
}

/* Coordinate c (0, 1) of pair p of sample j of one stream (seed: the sample's stream, G-buffer
 * sample and replicate hashed) */
IBL_INLINE float owen_sobol(uint j, uint seed, int p, int c)
{
    const uint s = pcg_hash(seed ^ pcg_hash((uint)p + 0x51ED27u));
    const uint i = nested_uniform_scramble(j, s);
    const uint x = c == 0 ? reverse_bits32(i) : sobol_dim1(i);
    return (float)(nested_uniform_scramble(x, pcg_hash(s + (uint)c + 1u)) >> 8) * (1.0f / 16777216.0f);
}

IBL_INLINE float sampler_1d(Sampler *s)
{
    const int d = s->dim++;
    if (d < 8) return qmc(s->seed, s->gid, s->k, d);
    /* a path's: its own stream per (seed, G-buffer sample, replicate), sample k >> 1 of it */
    const uint stream = pcg_hash(s->seed ^ pcg_hash(s->gid * 2u + (s->k & 1u)));
    return owen_sobol(s->k >> 1, stream, (d - 8) >> 1, (d - 8) & 1);
}

IBL_INLINE float2 sampler_2d(Sampler *s)
{
    const float a = sampler_1d(s);
    return (float2)(a, sampler_1d(s));
}

#endif
