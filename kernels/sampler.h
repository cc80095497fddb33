/* Random and quasi-random numbers: Hammersley sets, the PCG hash, Owen-scrambled Sobol pairs, and
 * the Sampler that hands a kernel the dimensions of one sample in order. Mirrors
 * iblbake/core/sampling.py. */
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

/* One sample's dimensions, handed out in the order a kernel asks for them, as pbrt-v4's Sampler
 * (Get1D, Get2D) and Mitsuba 3's (next_1d, next_2d) do: no kernel numbers a dimension by hand.
 * `seed` already carries the stream (the reference's seed, AO's seed ^ STREAM_AO, a light's);
 * `gid` the G-buffer sample's number in the frame, `k` the sample's number. Every dimension pair
 * is a pair of Owen-scrambled Sobol points (owen_sobol_pair), one sequence per (seed, gid) with
 * each pair's own scramble, as pbrt-v4's PaddedSobolSampler: the first k samples of a G-buffer
 * sample are stratified in every pair for every k (docs/benchmarks.md "Fewer samples: one
 * sequence per G-buffer sample"). */
typedef struct {
    uint seed, gid, k;
    uint stream;            /* the sequence's own scramble: (seed, G-buffer sample) hashed */
    int dim;
} Sampler;

IBL_INLINE Sampler sampler_start(uint seed, uint gid, uint k)
{
    Sampler s;
    s.seed = seed; s.gid = gid; s.k = k; s.dim = 0;
    s.stream = pcg_hash(seed ^ pcg_hash(gid));
    return s;
}

/* Sample k of an estimate that keeps `replicates` (1 or 2) independent sequences: with 2, even
 * and odd k are samples k / 2 of two streams, whose means' difference is an honest error estimate
 * (render/passes/reference.py reference_noise); a scrambled net's error falls faster than
 * 1 / sqrt(n), so two of n / 2 samples err more than one of n (1.07-1.23x the variance on the
 * Mitsuba scenes at 256), which is why only a frame that stops at a noise target splits them. */
IBL_INLINE Sampler sampler_replicate(uint seed, uint gid, uint k, int replicates)
{
    if (replicates < 2) return sampler_start(seed, gid, k);
    return sampler_start(seed ^ pcg_hash(0x2545F491u + (k & 1u)), gid, k >> 1);
}

/* The dimensions: pairs of Owen-scrambled Sobol points, each pair's
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
    const float2 u = owen_sobol_pair(s->k, s->stream, d >> 1);
    return d & 1 ? u.y : u.x;
}

/* Two dimensions; starting a pair (every kernel's draws do), both coordinates of one scrambled
 * index */
IBL_INLINE float2 sampler_2d(Sampler *s)
{
    if (!(s->dim & 1)) {
        const int d = s->dim;
        s->dim += 2;
        return owen_sobol_pair(s->k, s->stream, d >> 1);
    }
    const float a = sampler_1d(s);
    return (float2)(a, sampler_1d(s));
}

#endif
