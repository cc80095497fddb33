/* Irradiance probes: the diffuse light at a surface point from the eight probes of the grid cell
 * around it, as RTXGI's DDGIGetVolumeIrradiance (Irradiance.hlsl, RTXGI-DDGI 1.x; Majercik et al.
 * 2019 and 2021) specifies; constants and layouts in docs/conventions.md "Irradiance probes".
 *   PROBES_SH          each probe stores L2 SH irradiance coefficients (world frame, sh.h's basis),
 *   PROBES_BASIS       each probe stores a directional basis's radiance coefficients, packed by its
 *                      module (PROBE_BASIS_ROWS float4 rows a probe), evaluated by its header's
 *                      basis_irradiance (kernels/bases.h, BASIS_SPACE __global)
 *                      else RTXGI's octahedral irradiance atlas (n x n texels plus a 1-texel border)
 *   PROBE_VISIBILITY   DDGI's weights: wrap shading, Chebyshev visibility on the distance moments'
 *                      atlas, the weight crush and the blend in sqrt(E) (RTXGI's gamma-2 leftover);
 *                      without it plain trilinear interpolation of E (an irradiance volume)
 *   PROBE_CLASSIFICATION  probes marked inactive (probe_data.w = 1) do not contribute
 * Probe index (RTXGI, right-handed y up): gy nx nz + gz nx + gx; its atlas tile: column gx + gy nx,
 * row gz. numpy twin: iblbake/render/twin/probes.py. */
#ifndef IBLBAKE_PROBES_H
#define IBLBAKE_PROBES_H
#include "common.h"
#include "sh.h"
#include "bases.h"

/* the probes' data rows, irradiance, distance moments and the volume record (scene/layout.py
 * PROBE_VOLUME, packed by its pack_probe_volume: grid, biases, texels) */
#define PROBE_PARAMS __global const float4 *probe_data, __global const float4 *probe_irr, \
                     __global const float4 *probe_dist, __global const float4 *probe_volume
#define PROBE_ARGS probe_data, probe_irr, probe_dist, probe_volume
/* the record's fields as the locals a function of PROBE_PARAMS reads (layout.h's accessors) */
#define PROBE_VOLUME_LOCALS \
    const float3 probe_origin = PROBE_VOLUME_ORIGIN(probe_volume), probe_spacing = PROBE_VOLUME_SPACING(probe_volume); \
    const float probe_normal_bias = PROBE_VOLUME_NORMAL_BIAS(probe_volume); \
    const float probe_view_bias = PROBE_VOLUME_VIEW_BIAS(probe_volume); \
    const int3 probe_counts = PROBE_VOLUME_COUNTS(probe_volume); \
    const int probe_nx = probe_counts.x, probe_ny = probe_counts.y, probe_nz = probe_counts.z; \
    const int probe_irr_texels = PROBE_VOLUME_IRRADIANCE_TEXELS(probe_volume); \
    const int probe_dist_texels = PROBE_VOLUME_DISTANCE_TEXELS(probe_volume)
/* where a point's irradiance came from (probe_irradiance's w) */
#define PROBE_SOURCE_CELL 1.0f
#define PROBE_SOURCE_NEAREST 2.0f
#define PROBE_SOURCE_NONE 0.0f

/* DDGIGetOctahedralCoordinates: [-1, 1]^2, +z at the centre, -z at the corners */
IBL_INLINE float2 probe_octahedral(float3 d)
{
    float2 uv = d.xy / (fabs(d.x) + fabs(d.y) + fabs(d.z));
    if (d.z < 0.0f) {
        const float2 s = (float2)(uv.x >= 0.0f ? 1.0f : -1.0f, uv.y >= 0.0f ? 1.0f : -1.0f);
        uv = (1.0f - fabs(uv.yx)) * s;
    }
    return uv;
}

/* A bilinear read of probe `index`'s tile (n interior texels, border 1) at octahedral coordinates
 * oct, in an atlas of nx ny tiles across (DDGIGetProbeUV, then the hardware's bilinear filter:
 * texel centres at half-integers). */
IBL_INLINE float4 probe_atlas_read(__global const float4 *atlas, int index, float2 oct, int n, int nx, int ny, int nz)
{
    const int tile = n + 2, width = tile * nx * ny;
    const int col = index % nx + (index / (nx * nz)) * nx, row = (index / nx) % nz;
    const float x = (float)(col * tile) + 0.5f * (float)tile + oct.x * 0.5f * (float)n - 0.5f;
    const float y = (float)(row * tile) + 0.5f * (float)tile + oct.y * 0.5f * (float)n - 0.5f;
    const float fx0 = floor(x), fy0 = floor(y);
    const int x0 = (int)fx0, y0 = (int)fy0;
    const float fx = x - fx0, fy = y - fy0;
    const float4 a = atlas[y0 * width + x0], b = atlas[y0 * width + x0 + 1];
    const float4 c = atlas[(y0 + 1) * width + x0], d = atlas[(y0 + 1) * width + x0 + 1];
    return mix(mix(a, b, fx), mix(c, d, fx), fy);
}

/* One probe's irradiance at normal n (>= 0: an SH fit rings) */
IBL_INLINE float3 probe_irradiance_at(__global const float4 *probe_irr, int index, float3 n, int texels, int nx, int ny,
                                  int nz)
{
#ifdef PROBES_SH
    float Y[9];
    sh_eval(n, Y);
    float3 e = (float3)(0.0f);
    for (int k = 0; k < 9; ++k) e += probe_irr[9 * index + k].xyz * Y[k];
    return fmax(e, (float3)(0.0f));
#elif defined(PROBES_BASIS)
    return basis_irradiance(probe_irr + PROBE_BASIS_ROWS * index, n);
#else
    return fmax(probe_atlas_read(probe_irr, index, probe_octahedral(n), texels, nx, ny, nz).xyz, (float3)(0.0f));
#endif
}

/* How much of the probes' irradiance a point takes (RTXGI's DDGIGetVolumeBlendWeight): 1 inside
 * the box of the probes' cells (half a cell beyond the outer probes along an axis with more than
 * one: a probes.min/max box's faces, whose probes stand half a cell in), falling linearly to 0 one
 * spacing outside it along each axis (the rest from what lies outside every volume: the
 * panorama's SH). */
IBL_INLINE float probe_volume_weight(float3 p, __global const float4 *probe_volume)
{
    PROBE_VOLUME_LOCALS;
    const float3 n = (float3)(probe_nx, probe_ny, probe_nz);
    const float3 half_extent = 0.5f * probe_spacing * select(n, (float3)(0.0f), isequal(n, (float3)(1.0f)));
    const float3 delta = fabs(p - (probe_origin + 0.5f * probe_spacing * (n - 1.0f))) - half_extent;
    const float3 w = 1.0f - clamp(delta / probe_spacing, 0.0f, 1.0f);
    return w.x * w.y * w.z;
}

/* One probe's value: its irradiance at n, or given the warped specular lobe's weights `spec`
 * (kernels/bases.h basis_specular_weights; a basis that carries one) its radiance along the lobe */
IBL_INLINE float3 probe_value(__global const float4 *probe_irr, int index, float3 n, const float *spec, int texels,
                          int nx, int ny, int nz)
{
#if defined(PROBES_BASIS) && defined(HAS_BASIS_SPECULAR)
    if (spec) return basis_weighted(probe_irr + PROBE_BASIS_ROWS * index, spec);
#endif
    return probe_irradiance_at(probe_irr, index, n, texels, nx, ny, nz);
}

/* The index of the probe at grid coordinates c (the twin's probe_index: y, then z, then x) */
IBL_INLINE int probe_index(int3 c, int nx, int nz)
{
    return c.y * nx * nz + c.z * nx + c.x;
}

/* p moved by `by` along axis k */
IBL_INLINE float3 probe_moved(float3 p, int k, float by)
{
    if (k == 0) p.x += by; else if (k == 1) p.y += by; else p.z += by;
    return p;
}

/* Probe c's own weight at the biased point, its trilinear factor left out (DDGI's with visibility:
 * wrap shading, Chebyshev visibility on the distance moments' atlas, the crush; 1 without): 0 for an
 * inactive probe. Apart from its value: the junction step's side weights need no irradiance read. */
IBL_INLINE float probe_weight(int3 c, float3 p, float3 biased, float3 n, PROBE_PARAMS)
{
    PROBE_VOLUME_LOCALS;
    const int index = probe_index(c, probe_nx, probe_nz);
    const float4 data = probe_data[index];
#ifdef PROBE_CLASSIFICATION
    if (data.w != 0.0f) return 0.0f;
#endif
#ifdef PROBE_VISIBILITY
    const float3 pp = probe_origin + convert_float3(c) * probe_spacing + data.xyz;
    /* wrap shading: a probe behind the surface still counts a little */
    const float wrap = 0.5f * (dot(normalize(pp - p), n) + 1.0f);
    float w = wrap * wrap + PROBE_WRAP_FLOOR;
    /* Chebyshev's bound on the chance the probe sees the point, from the mean and mean square
     * of the probe's distances towards it */
    const float3 to_probe = pp - biased;
    const float dist = length(to_probe);
    const float2 m = probe_atlas_read(probe_dist, index, probe_octahedral(-to_probe / dist), probe_dist_texels,
                                      probe_nx, probe_ny, probe_nz).xy;
    float cheb = 1.0f;
    if (dist > m.x) {
        const float var = fabs(m.x * m.x - m.y), dv = dist - m.x;
        cheb = var / (var + dv * dv);
        cheb = cheb * cheb * cheb;
    }
    w *= fmax(PROBE_CHEBYSHEV_FLOOR, cheb);
    w = fmax(1e-6f, w);
    if (w < PROBE_CRUSH) w *= w * w * (1.0f / (PROBE_CRUSH * PROBE_CRUSH));     /* crush tiny weights, continuously */
    return w;
#else
    return 1.0f;
#endif
}

/* Probe c's weight given its own (probe_weight's w) and its factor `falloff` (the trilinear one, or
 * the fallback's inverse square distance), and its value (probe_value; the irradiance as sqrt E with
 * visibility, E without; the specular radiance as it is): 0 and 0 for an inactive probe (w 0). The
 * value is always written: probe_blend adds weight x value, and an unwritten value (whatever the
 * stack held: a NaN now and then, as a pointer's bits) times a zero weight was a NaN pixel. */
IBL_INLINE float probe_weighted(float w, int3 c, float3 n, float3 falloff, const float *spec, float3 *value,
                                PROBE_PARAMS)
{
    if (w == 0.0f) {
        *value = (float3)(0.0f);
        return 0.0f;
    }
    PROBE_VOLUME_LOCALS;
    const int index = probe_index(c, probe_nx, probe_nz);
    const float3 e = probe_value(probe_irr, index, n, spec, probe_irr_texels, probe_nx, probe_ny, probe_nz);
#ifdef PROBE_VISIBILITY
    const float3 tri = fmax(falloff, PROBE_TRILINEAR_FLOOR);
    *value = spec ? e : sqrt(e);
    return w * tri.x * tri.y * tri.z;
#else
    *value = e;
    return falloff.x * falloff.y * falloff.z;
#endif
}

/* probe_weight and probe_weighted in one: probe c's weight at the biased point and its value */
IBL_INLINE float probe_contribution(int3 c, float3 p, float3 biased, float3 n, float3 falloff, const float *spec,
                                    float3 *value, PROBE_PARAMS)
{
    return probe_weighted(probe_weight(c, p, biased, n, PROBE_ARGS), c, n, falloff, spec, value, PROBE_ARGS);
}

/* The grid cell of g (a point in grid units): its lowest probe, clamped to the grid (last: the
 * highest index per axis), and g's trilinear fractions in it (0-1) */
IBL_INLINE int3 probe_cell(float3 g, int3 last, float3 *alpha)
{
    const int3 base = clamp(convert_int3(floor(g)), (int3)(0), last);
    *alpha = clamp(g - convert_float3(base), 0.0f, 1.0f);
    return base;
}

/* The irradiance at surface point p with shading normal n seen along v (towards the viewer), in
 * xyz; w where it came from (PROBE_SOURCE_*): the eight probes of the cell around the point
 * (RTXGI), or where all eight are inactive the active probes of the 4 x 4 x 4 around it, each
 * weighted by its inverse square distance (in cells) with the same visibility (RTXGI returns 0
 * there), or none of those (0: the caller falls back to the panorama); the grid and biases from
 * the volume record (PROBE_VOLUME_LOCALS, world units). Given `spec` (the warped lobe's weights) the radiance along the lobe instead, the same weights
 * blending it linearly. The cell's lowest probe in *cell and its eight probes' own weights
 * (probe_weight) in own[off.x + 2 off.y + 4 off.z]: probe_irradiance's junction step reuses them. */
IBL_INLINE float4 probe_blend_cell(float3 p, float3 n, float3 v, const float *spec, int3 *cell, float *own,
                                   PROBE_PARAMS)
{
    PROBE_VOLUME_LOCALS;
    const float3 origin = probe_origin, spacing = probe_spacing;
    const int3 last = (int3)(probe_nx - 1, probe_ny - 1, probe_nz - 1);
    const float3 biased = p + n * probe_normal_bias + v * probe_view_bias;
    const float3 g = (biased - origin) / spacing;
    float3 alpha;
    const int3 base = probe_cell(g, last, &alpha);
    *cell = base;
    float3 sum = (float3)(0.0f), value;
    float wsum = 0.0f, source = PROBE_SOURCE_CELL;
    for (int i = 0; i < 8; ++i) {
        const int3 off = (int3)(i & 1, (i >> 1) & 1, (i >> 2) & 1);
        const int3 c = clamp(base + off, (int3)(0), last);
        own[i] = probe_weight(c, p, biased, n, PROBE_ARGS);
        const float w = probe_weighted(own[i], c, n, select(1.0f - alpha, alpha, off == (int3)(1)), spec, &value,
                                       PROBE_ARGS);
        sum += w * value;
        wsum += w;
    }
    if (!(wsum > 0.0f)) {
        source = PROBE_SOURCE_NEAREST;
        const int3 lo = max(base - 1, (int3)(0)), hi = min(base + 2, last);
        for (int z = lo.z; z <= hi.z; ++z)
            for (int y = lo.y; y <= hi.y; ++y)
                for (int x = lo.x; x <= hi.x; ++x) {
                    const float3 dc = convert_float3((int3)(x, y, z)) - g;
                    const float f = 1.0f / fmax(dot(dc, dc), 0.01f);
                    const float w = probe_contribution((int3)(x, y, z), p, biased, n, (float3)(f, 1.0f, 1.0f), spec,
                                                       &value, PROBE_ARGS);
                    sum += w * value;
                    wsum += w;
                }
    }
    if (!(wsum > 0.0f)) return (float4)(0.0f, 0.0f, 0.0f, PROBE_SOURCE_NONE);
    const float3 s = sum / wsum;
#ifdef PROBE_VISIBILITY
    if (!spec) return (float4)(s * s, source);
#endif
    return (float4)(s, source);
}

/* probe_blend_cell without its cell's weights */
IBL_INLINE float4 probe_blend(float3 p, float3 n, float3 v, const float *spec, PROBE_PARAMS)
{
    int3 cell;
    float own[8];
    return probe_blend_cell(p, n, v, spec, &cell, own, PROBE_ARGS);
}

/* The probes' weight on either side of the (unbiased) cell of p along each axis, the axis' own
 * trilinear factor left out (visibility and states as in the blend: side[k][0] the low side's), and
 * each side's weighted mean offset along the axis in cells (shift[k][s], the relocated probes':
 * where the layer stands); the cell's lowest probe and p's fractions in it. Own weights only
 * (probe_weight: no irradiance read); given `own`, probe_blend_cell's weights of its cell `blended`,
 * a probe of that cell (most of the point's, often all) weighs as it did there. */
IBL_INLINE int3 probe_sides(float3 p, float3 n, float3 v, int3 blended, const float *own, float side[3][2],
                            float shift[3][2], float3 *alpha, PROBE_PARAMS)
{
    PROBE_VOLUME_LOCALS;
    const int3 last = (int3)(probe_nx - 1, probe_ny - 1, probe_nz - 1);
    const float3 biased = p + n * probe_normal_bias + v * probe_view_bias;
    const int3 base = probe_cell((p - probe_origin) / probe_spacing, last, alpha);
    for (int k = 0; k < 3; ++k) side[k][0] = side[k][1] = shift[k][0] = shift[k][1] = 0.0f;
    for (int i = 0; i < 8; ++i) {
        const int3 off = (int3)(i & 1, (i >> 1) & 1, (i >> 2) & 1), c = clamp(base + off, (int3)(0), last);
        const int3 d = c - blended;
        const bool shared = own && d.x >= 0 && d.x <= 1 && d.y >= 0 && d.y <= 1 && d.z >= 0 && d.z <= 1;
        const float w = shared ? own[d.x + 2 * d.y + 4 * d.z] : probe_weight(c, p, biased, n, PROBE_ARGS);
        float3 f = select(1.0f - *alpha, *alpha, off == (int3)(1));
#ifdef PROBE_VISIBILITY
        f = fmax(f, PROBE_TRILINEAR_FLOOR);
#endif
        const float3 o = probe_data[probe_index(c, probe_nx, probe_nz)].xyz / probe_spacing;
        const float wx = w * f.y * f.z, wy = w * f.x * f.z, wz = w * f.x * f.y;
        side[0][off.x] += wx; shift[0][off.x] += wx * o.x;
        side[1][off.y] += wy; shift[1][off.y] += wy * o.y;
        side[2][off.z] += wz; shift[2][off.z] += wz * o.z;
    }
    return base;
}

/* which side of axis k carries under PROBE_NEAR_DEAD of the weight (a wall's): 0 the low, 1 the high,
 * -1 neither */
IBL_INLINE int probe_dead_side(const float side[3][2], int k)
{
    const float total = side[k][0] + side[k][1];
    if (!(total > 0.0f)) return -1;
    return side[k][0] < PROBE_NEAR_DEAD * total ? 0 : side[k][1] < PROBE_NEAR_DEAD * total ? 1 : -1;
}

/* probe_blend's irradiance, extrapolated to the point where it stands between a wall and the layer
 * of probes nearest it. That layer stands a third of a cell or more off the wall and every point
 * between reads it (the layer beyond is off or unseen), so a junction read a neighbour's light as the
 * layer sees it, not edge-on: a band up to a cell wide too bright (docs/conventions.md "Junctions").
 * By a junction: where one side of the point's own cell (the point's, not the biased one's: the
 * biases move the read onto the layer) carries under PROBE_NEAR_DEAD of the probes' weight (the
 * axis' trilinear factor left out) along two axes or three, or along one with the cell one further
 * along another axis (towards the point's nearer layer) having such a side on that axis (the point
 * within a cell of the junction), along each of the point's own walls the read goes on linearly from
 * the live layer to the point, its gradient the reads one cell apart (the point moved onto the next
 * layer in): a first-order irradiance gradient (Ward & Heckbert 1992) in place of a finer grid. The
 * live layer is where its probes stand, relocated (their mean offset along the axis, which moves it
 * off a wall), at most PROBE_STEP_REACH cells from the layer's read. The sum of the axes' steps kept
 * within [PROBE_STEP_FLOOR, 1] times the read: it only darkens, and a line past a bright layer (a sun
 * patch's) does not reach black (a point by a concave junction sees part of what the
 * layer sees, its neighbour edge-on). Measured at 40 px (256-sample references) on two_storey under
 * city, whose floor by the window wall read the floor's layer, 0.3 cell and its relocation above it,
 * in cells with one wall: 1.19 with the junction's own cells alone, 1.137 now. Taken along one axis
 * everywhere (every wall's cells) 1.09, but trial70's window room's back wall, right at the layer's
 * read (x1.008), went to x0.877; reaching further the secant overshot where the field bends (quad_room
 * under city's floor under its window, flat in the truth, x0.4 by the wall). */
IBL_INLINE float4 probe_irradiance(float3 p, float3 n, float3 v, PROBE_PARAMS)
{
    int3 blended;
    float own[8];
    const float4 e = probe_blend_cell(p, n, v, (const float *)0, &blended, own, PROBE_ARGS);
    if (e.w != PROBE_SOURCE_CELL) return e;
#if !defined(PROBE_VISIBILITY) && !defined(PROBE_CLASSIFICATION)
    return e;                       /* every probe weighs 1: no side is light */
#endif
    PROBE_VOLUME_LOCALS;
    const int3 last = (int3)(probe_nx - 1, probe_ny - 1, probe_nz - 1);
    float3 alpha, nalpha;
    const int3 base = probe_cell((p - probe_origin) / probe_spacing, last, &alpha);
    const float ga[3] = {alpha.x, alpha.y, alpha.z}, sp[3] = {probe_spacing.x, probe_spacing.y, probe_spacing.z};
    const int gb[3] = {base.x, base.y, base.z}, gl[3] = {last.x, last.y, last.z};
    /* the axes along which a step could be taken (a layer inwards of the live one, the point off it):
     * with none, no pass over the cell */
    int open = 0;
    for (int k = 0; k < 3; ++k)
        open += gl[k] >= 2 && ((ga[k] > 1e-6f && gb[k] - 1 >= 0) || (1.0f - ga[k] > 1e-6f && gb[k] + 2 <= gl[k]));
    if (open == 0) return e;
    float side[3][2], shift[3][2], near[3][2], nshift[3][2];
    probe_sides(p, n, v, blended, own, side, shift, &alpha, PROBE_ARGS);
    int walls = 0;
    for (int k = 0; k < 3; ++k) walls += probe_dead_side(side, k) >= 0;
    for (int k = 0; k < 3 && walls == 1; ++k) {
        if (probe_dead_side(side, k) >= 0) continue;
        /* one cell on, towards the nearer layer */
        const float3 q = probe_moved(p, k, (ga[k] < 0.5f ? -1.0f : 1.0f) * sp[k]);
        probe_sides(q, n, v, blended, (const float *)0, near, nshift, &nalpha, PROBE_ARGS);
        walls += probe_dead_side(near, k) >= 0;
    }
    if (walls < 2) return e;
    float3 step = (float3)(0.0f);
    for (int k = 0; k < 3; ++k) {
        const int dead = probe_dead_side(side, k);
        if (dead < 0) continue;
        const float t = dead ? ga[k] : 1.0f - ga[k];                  /* cells from the point to the live layer */
        const int next = dead ? gb[k] - 1 : gb[k] + 2;                 /* the layer after it, inwards */
        if (gl[k] < 2 || !(t > 1e-6f) || next < 0 || next > gl[k]) continue;
        /* the live layer where its probes stand: o cells further in */
        const float o = dead ? -shift[k][0] / side[k][0] : shift[k][1] / side[k][1];
        const float3 q = probe_moved(p, k, (dead ? -1.0f : 1.0f) * (t + 1.0f) * sp[k]);
        const float4 e2 = probe_blend(q, n, v, (const float *)0, PROBE_ARGS);
        const float reach = fmin(fmax(t + o, 0.0f) / fmax(1.0f - o, 0.25f), PROBE_STEP_REACH);
        if (e2.w == PROBE_SOURCE_CELL) step -= reach * (e2.xyz - e.xyz);
    }
    return (float4)(clamp(e.xyz + step, PROBE_STEP_FLOOR * e.xyz, e.xyz), e.w);
}

/* The diffuse irradiance at p with the probes (their irradiance holds the panorama's intensity
 * already: their rays read it scaled): blended by the volume's weight with `sky` (the panorama's SH,
 * scaled) outside it, and `sky` too where no active probe is near; probe_stats counts the samples
 * that fell back ([0] to the nearest active probes, [1] to the sky) and [4] those that lie outside
 * the volume or on its fading edge. */
IBL_INLINE float3 probes_diffuse(float3 p, float3 n, float3 v, float3 sky, PROBE_PARAMS, __global int *probe_stats)
{
    const float wv = probe_volume_weight(p, probe_volume);
    float3 e = (1.0f - wv) * sky;
    /* outside the volume, or on its fading edge (over 0.1% of its light the SH's): a point on the
     * box's faces (the walls a box was drawn on) rounds to 1 - 2e-7 in float32, and is inside */
    if (wv < 0.999f) atomic_inc(&probe_stats[4]);
    if (wv > 0.0f) {
        const float4 pe = probe_irradiance(p, n, v, PROBE_ARGS);
        if (pe.w == PROBE_SOURCE_NEAREST) atomic_inc(&probe_stats[0]);
        if (pe.w == PROBE_SOURCE_NONE) atomic_inc(&probe_stats[1]);
        e += wv * (pe.w == PROBE_SOURCE_NONE ? sky : pe.xyz);
    }
    return e;
}

#if defined(PROBES_BASIS) && defined(HAS_BASIS_SPECULAR)
/* The radiance along the warped GGX lobe (axis d, world frame; sharpness lam_w) at p from probes
 * whose basis carries a specular lobe (`specular: probes`), blended by the volume's weight with
 * `sky` (the distant split sum's radiance) outside it, and `sky` where no active probe is near;
 * probe_stats[2], [3] count those samples as [0], [1] do the irradiance's. */
IBL_INLINE float3 probes_specular(float3 p, float3 n, float3 v, float3 d, float lam_w, float3 sky,
                              __global const float *basis_table, PROBE_PARAMS, __global int *probe_stats)
{
    const float wv = probe_volume_weight(p, probe_volume);
    float3 li = (1.0f - wv) * sky;
    if (wv > 0.0f) {
        float s[BASIS_SPECULAR_ROWS];
        basis_specular_weights(probe_irr, basis_table, d, lam_w, s);   /* the lobes' axes: any probe's block */
        const float4 pl = probe_blend(p, n, v, s, PROBE_ARGS);
        if (pl.w == PROBE_SOURCE_NEAREST) atomic_inc(&probe_stats[2]);
        if (pl.w == PROBE_SOURCE_NONE) atomic_inc(&probe_stats[3]);
        li += wv * (pl.w == PROBE_SOURCE_NONE ? sky : pl.xyz);
    }
    return li;
}
#endif

#endif
