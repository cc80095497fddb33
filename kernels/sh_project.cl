/* SH projection, the bandwidth-bound half (see iblbake/sh.py, "separable form"):
 *   S[j][x][t*3 + c] = sum over columns i of chunk x of L_c(i, j) * T_t(phi_i)
 * T is the equirect azimuth basis (1, sqrt2 cos m phi, sqrt2 sin m phi), NT = 2*bands - 1 terms,
 * uploaded as trig[i][t]. The host sums chunks and contracts rows in float64. */
#ifndef NT
#define NT 5
#endif

__kernel void sh_row_sums(__global const float *image, const int width, const int channels,
                          __global const float *trig, const int chunk, __global float *out)
{
    const int x = get_global_id(0), nx = get_global_size(0), j = get_global_id(1);
    float acc[NT * 3];
    for (int k = 0; k < NT * 3; ++k) acc[k] = 0.0f;
    const int i0 = x * chunk, i1 = min(width, i0 + chunk);
    __global const float *row = image + (size_t)j * width * channels;
    for (int i = i0; i < i1; ++i) {
        const float r = row[i * channels], g = row[i * channels + 1], b = row[i * channels + 2];
        __global const float *t = trig + (size_t)i * NT;
        for (int k = 0; k < NT; ++k) {
            const float w = t[k];
            acc[3 * k] += r * w;
            acc[3 * k + 1] += g * w;
            acc[3 * k + 2] += b * w;
        }
    }
    __global float *o = out + ((size_t)j * nx + x) * (NT * 3);
    for (int k = 0; k < NT * 3; ++k) o[k] = acc[k];
}
