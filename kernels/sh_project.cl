/* SH projection, the bandwidth-bound half (see iblbake/core/sh.py, "exact texel integration"):
 *   S[j][x][t*3 + c] = sum over the columns i of chunk x of L_c(i, j) * T_t(phi_i)
 * T is the equirect azimuth basis (1, sqrt2 cos m phi, sqrt2 sin m phi), trig[t][i], NT terms
 * (2*bands - 1 padded with zero rows to a multiple of TG, the terms per pass). The host sums the chunks and
 * contracts rows in float64.
 *
 * Written for CPU SIMD (PoCL): a row is a flat float array R G B R G B ...; 16 pixels are three
 * float16 loads ("phases"), and the 16 azimuth values of those pixels are spread over the three
 * phases' lanes with shuffles (so the table costs a third of the image's bytes, not 3x); the
 * channels are separated once per chunk. TG terms at a time keep the accumulators in registers;
 * the chunk stays in L1 across the groups. Pixels past the last multiple of 16 go one by one.
 * Measured alternatives (benchmarks/bench_sh.py era): a scalar loop ran at ~6 GFMA/s (not
 * vectorised by PoCL); a table expanded per float or cos/sin rotation recurrences were slower. */
#ifndef NT
#define NT 5
#endif
#ifndef TG
#define TG 5
#endif
__kernel void sh_row_sums(__global const float *image, const int width, __global const float *trig,
                          const int chunk, __global float *out)
{
    const int x = get_global_id(0), nx = get_global_size(0), j = get_global_id(1);
    const int i0 = x * chunk, i1 = min(width, i0 + chunk);
    const int n3 = 3 * width;
    __global const float *row = image + (size_t)j * n3;
    const int iv = i0 + ((i1 - i0) / 16) * 16;
    /* phase p, lane l holds float 16p + l of the step, i.e. pixel (16p + l) / 3 */
    const uint16 m0 = (uint16)(0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4, 5);
    const uint16 m1 = (uint16)(5, 5, 6, 6, 6, 7, 7, 7, 8, 8, 8, 9, 9, 9, 10, 10);
    const uint16 m2 = (uint16)(10, 11, 11, 11, 12, 12, 12, 13, 13, 13, 14, 14, 14, 15, 15, 15);
    __global float *o = out + ((size_t)j * nx + x) * (NT * 3);
    for (int t0 = 0; t0 < NT; t0 += TG) {
        float16 a0[TG], a1[TG], a2[TG];
        for (int t = 0; t < TG; ++t) { a0[t] = (float16)(0.0f); a1[t] = (float16)(0.0f); a2[t] = (float16)(0.0f); }
        for (int i = i0; i < iv; i += 16) {
            const float16 v0 = vload16(0, row + 3 * i), v1 = vload16(0, row + 3 * i + 16), v2 = vload16(0, row + 3 * i + 32);
            for (int t = 0; t < TG; ++t) {
                const float16 w = vload16(0, trig + (size_t)(t0 + t) * width + i);
                a0[t] = fma(v0, shuffle(w, m0), a0[t]);
                a1[t] = fma(v1, shuffle(w, m1), a1[t]);
                a2[t] = fma(v2, shuffle(w, m2), a2[t]);
            }
        }
        for (int t = 0; t < TG; ++t) {
            float s[48];
            vstore16(a0[t], 0, s); vstore16(a1[t], 0, s + 16); vstore16(a2[t], 0, s + 32);
            float c0 = 0.0f, c1 = 0.0f, c2 = 0.0f;
            for (int l = 0; l < 48; l += 3) { c0 += s[l]; c1 += s[l + 1]; c2 += s[l + 2]; }
            __global const float *tt = trig + (size_t)(t0 + t) * width;
            for (int i = iv; i < i1; ++i) {
                c0 += row[3 * i] * tt[i]; c1 += row[3 * i + 1] * tt[i]; c2 += row[3 * i + 2] * tt[i];
            }
            o[3 * (t0 + t)] = c0; o[3 * (t0 + t) + 1] = c1; o[3 * (t0 + t) + 2] = c2;
        }
    }
}
