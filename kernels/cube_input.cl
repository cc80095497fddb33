/* A cube map (faces +X -X +Y -Y +Z -Z of s x s, stacked) resampled to an equirect panorama of
 * w x h by exact texel overlaps: each equirect texel the mean of the cube map's box texels over
 * its solid angle. A work-item takes an equirect column (a strip between two meridians): every
 * cube texel the strip meets leaves a part inside it (a "piece"), and the piece's solid angle
 * below each parallel that crosses it has a closed form in the face's own coordinates: on a side
 * face a rectangle under the parallel's curve, on the top face a polygon outside the parallel's
 * circle; the symmetries below make that column stand for 16. The derivation, and the float64
 * twin this follows, is iblbake/bake/cube_resample.py. In double: a piece's solid angle is a sum
 * of terms as large as the strip is wide. */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable

#define MAX_POLY 10

/* face coordinates (a, b) -> direction: origin, along a, along b (conventions.dir_from_cube) */
__constant double FACE_AXES[6][9] = {
    {1, 0, 0, 0, 0, -1, 0, -1, 0},  {-1, 0, 0, 0, 0, 1, 0, -1, 0}, {0, 1, 0, 1, 0, 0, 0, 0, 1},
    {0, -1, 0, 1, 0, 0, 0, 0, -1},  {0, 0, 1, 1, 0, 0, 0, -1, 0},  {0, 0, -1, -1, 0, 0, 0, -1, 0}};

/* the half-plane c + ca a + cb b >= 0 on the side `sense` of the meridian plane of azimuth phi */
static double3 meridian_line(int face, double phi, double sense)
{
    const double mx = cos(phi) * sense, mz = -sin(phi) * sense;
    __constant const double *f = FACE_AXES[face];
    return (double3)(f[0] * mx + f[2] * mz, f[3] * mx + f[5] * mz, f[6] * mx + f[8] * mz);
}

/* Sutherland-Hodgman: the part of the convex polygon in[0..n) where line >= 0, into out */
static int clip(const double2 *in, int n, double3 line, double2 *out)
{
    int m = 0;
    for (int k = 0; k < n; ++k) {
        const double2 p = in[k], q = in[(k + 1) % n];
        const double fp = line.x + line.y * p.x + line.z * p.y, fq = line.x + line.y * q.x + line.z * q.y;
        if (fp >= 0.0 && m < MAX_POLY) out[m++] = p;
        if ((fp >= 0.0) != (fq >= 0.0) && m < MAX_POLY) out[m++] = p + (fp / (fp - fq)) * (q - p);
    }
    return m;
}

/* atan2(y, x) for the small angles of a piece (within one equirect column): atan's series to
 * u^9 where |u| = |y / x| <= 1/64 (the next term, u^11 / 11, is below 1e-21), else atan2, whose
 * double precision costs 30-70 ns on a CPU */
static double small_atan2(double y, double x)
{
    if (x > 0.0 && fabs(y) <= x * (1.0 / 64.0)) {
        const double u = y / x, u2 = u * u;
        return u * (1.0 - u2 * (1.0 / 3.0 - u2 * (1.0 / 5.0 - u2 * (1.0 / 7.0 - u2 * (1.0 / 9.0)))));
    }
    return atan2(y, x);
}

static double cross2(double2 p, double2 q) { return p.x * q.y - p.y * q.x; }

/* signed solid angle of the triangle (face centre, p, q), p and q in face coordinates: Van
 * Oosterom and Strackee's formula for o = (0, 0, 1), u = (p, 1), v = (q, 1) */
static double triangle(double2 p, double2 q)
{
    const double lu = sqrt(1.0 + dot(p, p)), lv = sqrt(1.0 + dot(q, q));
    return 2.0 * small_atan2(cross2(p, q), lu * lv + lu + lv + 1.0 + dot(p, q));
}

/* signed angle at the face centre from p to q */
static double angle(double2 p, double2 q) { return small_atan2(cross2(p, q), dot(p, q)); }

/* A piece. On the top face (side = 0): the polygon poly[0..n) in face coordinates, with each
 * edge's triangle and angle at the centre kept for the bands. On a side face (side = 1): the
 * rectangle [a0, a1] x [e0, e1] in the face's coordinates a and e = -b (up). */
typedef struct {
    double2 poly[MAX_POLY];
    double tri[MAX_POLY], ang[MAX_POLY];
    int n, side;
    double sign, area, bottom, top;
    double a0, a1, e0, e1, under0, under1, turn;
} Piece;

/* squared distance from the face centre to the segment p q */
static double distance2(double2 p, double2 q)
{
    const double2 d = q - p;
    const double a = dot(d, d);
    const double t = a > 0.0 ? fmin(1.0, fmax(0.0, -dot(p, d) / a)) : 0.0;
    const double2 x = p + t * d;
    return dot(x, x);
}

static void make_cap_piece(const double2 *poly, int n, Piece *pc)
{
    pc->side = 0;
    pc->n = n;
    double total = 0.0, far2 = 0.0, near2 = INFINITY;
    int pos = 0, neg = 0;
    for (int k = 0; k < n; ++k) {
        const double2 p = poly[k], q = poly[(k + 1) % n];
        pc->poly[k] = p;
        pc->tri[k] = triangle(p, q);
        pc->ang[k] = angle(p, q);
        total += pc->tri[k];
        far2 = fmax(far2, dot(p, p));
        near2 = fmin(near2, distance2(p, q));
        const double c = cross2(p, q);
        pos |= c > 0.0;
        neg |= c < 0.0;
    }
    if (!(pos && neg)) near2 = 0.0;                  /* the polygon holds the centre */
    pc->sign = total >= 0.0 ? 1.0 : -1.0;
    pc->area = fabs(total);
    pc->top = 1.0 / sqrt(1.0 + near2);
    pc->bottom = 1.0 / sqrt(1.0 + far2);
}

/* signed solid angle of the triangle (centre, poly[k], poly[k + 1]) within rho^2 <= rho2, cap =
 * 1 - Y the disk's solid angle per radian: the triangle where the edge runs inside the circle,
 * the sector where outside (the edge p + t (q - p) meets the circle at the roots of
 * A t^2 + 2 B t + C = 0) */
static double fan_within(const Piece *pc, int k, double rho2, double cap)
{
    const double2 p = pc->poly[k], q = pc->poly[(k + 1) % pc->n], d = q - p;
    const double a = dot(d, d), b = dot(p, d), c = dot(p, p) - rho2;
    const double disc = b * b - a * c;
    if (a == 0.0 || disc <= 0.0) return cap * pc->ang[k];
    /* the root of larger magnitude first, the other from their product c / a: no cancellation */
    const double root = -(b + copysign(sqrt(disc), b));
    const double r1 = root / a, r2 = c / root;
    const double lo = fmax(fmin(r1, r2), 0.0), hi = fmin(fmax(r1, r2), 1.0);
    if (lo >= hi) return cap * pc->ang[k];
    if (lo == 0.0 && hi == 1.0) return pc->tri[k];
    const double2 x1 = p + lo * d, x2 = p + hi * d;
    return cap * (angle(p, x1) + angle(x2, q)) + triangle(x1, x2);
}

/* C(Y) of a top-face piece, Y > 0: the piece outside the circle rho^2 = (1 - Y^2) / Y^2 */
static double cap_below(const Piece *pc, double big_y)
{
    const double rho2 = (1.0 - big_y) * (1.0 + big_y) / (big_y * big_y);
    double inside = 0.0;
    for (int k = 0; k < pc->n; ++k) inside += fan_within(pc, k, rho2, 1.0 - big_y);
    return pc->area - pc->sign * inside;
}

/* the solid angle of [p, q] x [0, e] on a face (signed): F(q, e) - F(p, e) for
 * F(a, e) = atan(a e / sqrt(1 + a^2 + e^2)), the corner formula of a face's rectangles */
static double under(double p, double q, double e)
{
    const double u = q * e / sqrt(1.0 + q * q + e * e), v = p * e / sqrt(1.0 + p * p + e * e);
    return small_atan2(u - v, 1.0 + u * v);
}

/* |a| beyond which a parallel's curve e = t sqrt(1 + a^2) on a side face runs above e */
static double reach(double e, double t)
{
    if (e <= t) return 0.0;
    return t > 0.0 ? sqrt((e / t) * (e / t) - 1.0) : INFINITY;
}

static void make_side_piece(double a0, double a1, double e0, double e1, Piece *pc)
{
    pc->side = 1;
    pc->a0 = a0;
    pc->a1 = a1;
    pc->e0 = e0;
    pc->e1 = e1;
    pc->under0 = under(a0, a1, e0);
    pc->under1 = under(a0, a1, e1);
    pc->turn = small_atan2(a1 - a0, 1.0 + a0 * a1);
    pc->area = pc->under1 - pc->under0;
    const double near = a0 < 0.0 && 0.0 < a1 ? 0.0 : fmin(fabs(a0), fabs(a1)), far = fmax(fabs(a0), fabs(a1));
    const double at_top = e1 > 0.0 ? near : far, at_bottom = e0 > 0.0 ? far : near;   /* y = e / sqrt(1 + a^2 + e^2) */
    pc->top = e1 / sqrt(1.0 + at_top * at_top + e1 * e1);
    pc->bottom = e0 / sqrt(1.0 + at_bottom * at_bottom + e0 * e0);
}

/* C(Y) of a side piece for 0 <= Y < 1, Y = sin(beta): under the curve e = t sqrt(1 + a^2),
 * t = tan(beta), whose solid angle below it is Y (atan q - atan p) over [p, q]; the rectangle's
 * columns are whole where the curve runs above e1, empty where below e0, e0 up to it between */
static double side_below(const Piece *pc, double big_y)
{
    const double t = big_y / sqrt((1.0 - big_y) * (1.0 + big_y));
    const double r0 = reach(pc->e0, t), r1 = reach(pc->e1, t);
    const double cuts[4] = {-r1, -r0, r0, r1};
    double total = 0.0, p = pc->a0;
    for (int k = 0; k <= 4; ++k) {
        const double q = k < 4 ? cuts[k] : pc->a1;
        if (k < 4 && !(p < q && q < pc->a1)) continue;
        const double mid = fabs(p + q) * 0.5;
        const int whole = p == pc->a0 && q == pc->a1;        /* no cut: the piece's own terms */
        if (mid >= r1)
            total += whole ? pc->area : under(p, q, pc->e1) - under(p, q, pc->e0);
        else if (mid >= r0)
            total += whole ? big_y * pc->turn - pc->under0 : big_y * small_atan2(q - p, 1.0 + p * q) - under(p, q, pc->e0);
        p = q;
    }
    return total;
}

/* C(Y): the piece's solid angle where y < Y (Y > 0: the northern rows) */
static double below(const Piece *pc, double big_y) { return pc->side ? side_below(pc, big_y) : cap_below(pc, big_y); }

/* The sphere's symmetries that keep the cube and the equirect grid: turns by k quarter turns
 * about +y (k = 0..3: phi + k pi / 2, column i - k s), the mirror x -> -x (m: column w - 1 - i)
 * and the mirror y -> -y (v: row h - 1 - j). sym[((k * 2 + m) * 2 + v) * 6 + face] holds the
 * face a texel of `face` lands on and how its (row, column) move (bit 4: swapped, then bit 1:
 * row flipped, bit 2: column flipped), found by iblbake/bake/cube_resample.py from the cube-map
 * convention. So a work-item computes the pieces of one column's northern half and adds each
 * to the 8 columns and 2 halves it stands for (4 columns for a column its own mirror image). */
static size_t image_texel(__constant const int2 *sym, int g, int face, int row, int col, int s)
{
    const int2 e = sym[g * 6 + face];
    int r = (e.y & 4) ? col : row, c = (e.y & 4) ? row : col;
    if (e.y & 1) r = s - 1 - r;
    if (e.y & 2) c = s - 1 - c;
    return ((size_t)e.x * s + r) * s + c;
}

/* A piece's parts in the northern rows it crosses, times its texel's 16 images, into acc */
static void add_piece(const Piece *pc, __global const float *faces, __constant const int2 *sym,
                      __global const double *ys, int s, int h, int mirrors, int face, int row, int col,
                      __global double *acc)
{
    if (!(pc->area > 0.0) || pc->top <= 0.0) return;
    const int north = h / 2;
    const int j_top = min(north - 1, (int)(acos(fmin(1.0, pc->top)) * h / M_PI));
    const int j_bottom = min(north - 1, (int)(acos(fmax(0.0, pc->bottom)) * h / M_PI));
    float3 value[16];                                /* the texel's 16 images */
    for (int g = 0; g < 4 * 2 * 2; ++g)
        if (mirrors == 2 || !(g & 2)) value[g] = vload3(image_texel(sym, g, face, row, col, s), faces);
    double upper = pc->area;
    for (int j = j_top; j <= j_bottom; ++j) {
        const double big_y = ys[j + 1];
        const double lower = big_y > pc->bottom ? below(pc, big_y) : 0.0;
        const double part = upper - lower;
        upper = lower;
        if (part == 0.0) continue;
        for (int k = 0; k < 4; ++k)
            for (int m = 0; m < mirrors; ++m)
                for (int v = 0; v < 2; ++v) {
                    const float3 t = value[(k * 2 + m) * 2 + v];
                    __global double *a = acc + ((size_t)(k * 2 + m) * h + (v ? h - 1 - j : j)) * 3;
                    a[0] += part * t.x;
                    a[1] += part * t.y;
                    a[2] += part * t.z;
                }
    }
}

/* phi at the centre of side face +X -X . . +Z -Z: phi = centre + atan(a) on it */
__constant double SIDE_CENTRE[6] = {M_PI / 2, -M_PI / 2, 0.0, 0.0, 0.0, M_PI};

/* The side face's texels in the strip: rectangles, the strip's edges being lines a = tan(phi -
 * centre) on the face; only the rows reaching above the equator (e > 0) */
static void side_face(__global const float *faces, __constant const int2 *sym, __global const double *ys, int s,
                      int h, int mirrors, int face, double phi_lo, double phi_hi, __global double *acc)
{
    const double lo = remainder(phi_lo - SIDE_CENTRE[face], 2.0 * M_PI), hi = lo + (phi_hi - phi_lo);
    if (hi <= -M_PI / 4 || lo >= M_PI / 4) return;
    const double a_lo = lo <= -M_PI / 4 ? -1.0 : tan(lo), a_hi = hi >= M_PI / 4 ? 1.0 : tan(hi);
    const int c0 = max(0, (int)((a_lo + 1.0) * s / 2.0)), c1 = min(s - 1, (int)((a_hi + 1.0) * s / 2.0));
    Piece pc;
    for (int row = 0; row <= (s - 1) / 2; ++row) {
        const double e1 = -(2.0 * row / s - 1.0), e0 = -(2.0 * (row + 1) / s - 1.0);
        for (int col = c0; col <= c1; ++col) {
            const double a0 = fmax(a_lo, 2.0 * col / s - 1.0), a1 = fmin(a_hi, 2.0 * (col + 1) / s - 1.0);
            if (!(a1 > a0)) continue;
            make_side_piece(a0, a1, e0, e1, &pc);
            add_piece(&pc, faces, sym, ys, s, h, mirrors, face, row, col, acc);
        }
    }
}

/* the first and last texel (columns: along a, rows: along b) a polygon on a face reaches */
static int2 texel_span(const double2 *poly, int n, int rows, int s)
{
    double lo = 2.0, hi = -2.0;
    for (int k = 0; k < n; ++k) {
        const double v = rows ? poly[k].y : poly[k].x;
        lo = fmin(lo, v);
        hi = fmax(hi, v);
    }
    return (int2)(max(0, (int)((lo + 1.0) * s / 2.0)), min(s - 1, (int)((hi + 1.0) * s / 2.0)));
}

/* The top face's texels in the strip: each clipped by the strip's two meridian planes (lines
 * through the face's centre) to a polygon of great-circle arcs */
static void top_face(__global const float *faces, __constant const int2 *sym, __global const double *ys, int s,
                     int h, int mirrors, double phi_lo, double phi_hi, __global double *acc)
{
    const int face = 2;
    const double3 lo = meridian_line(face, phi_lo, 1.0), hi = meridian_line(face, phi_hi, -1.0);
    double2 wedge[MAX_POLY], tmp[MAX_POLY], band[MAX_POLY], square[MAX_POLY];
    double2 sq[4] = {(double2)(-1.0, -1.0), (double2)(1.0, -1.0), (double2)(1.0, 1.0), (double2)(-1.0, 1.0)};
    int nw = clip(sq, 4, lo, tmp);
    nw = clip(tmp, nw, hi, wedge);
    if (nw < 3) return;
    const int2 rows = texel_span(wedge, nw, 1, s);
    Piece pc;
    for (int row = rows.x; row <= rows.y; ++row) {
        const double e0 = 2.0 * row / s - 1.0, e1 = 2.0 * (row + 1) / s - 1.0;
        int nb = clip(wedge, nw, (double3)(-e0, 0.0, 1.0), tmp);
        nb = clip(tmp, nb, (double3)(e1, 0.0, -1.0), band);
        if (nb < 3) continue;
        const int2 cols = texel_span(band, nb, 0, s);
        for (int col = cols.x; col <= cols.y; ++col) {
            const double a0 = 2.0 * col / s - 1.0, a1 = 2.0 * (col + 1) / s - 1.0;
            const double2 texel[4] = {(double2)(a0, e0), (double2)(a1, e0), (double2)(a1, e1), (double2)(a0, e1)};
            int np = clip(texel, 4, lo, tmp);
            np = clip(tmp, np, hi, square);
            if (np < 3) continue;
            make_cap_piece(square, np, &pc);
            add_piece(&pc, faces, sym, ys, s, h, mirrors, face, row, col, acc);
        }
    }
}

/* Column i's pieces (its northern half) into acc: 8 images, each the column's full height in
 * doubles (8 h 3). ys: the rows' edges y = cos(theta), h + 1 from the top (cube_resample.row_edges:
 * one table for kernel and twin, and no sine per use). */
static void resample_column(__global const float *faces, __constant const int2 *sym, __global const double *ys,
                            const int s, const int w, const int h, const int i, __global double *acc)
{
    const int mirrors = 2 * i + 1 == s ? 1 : 2;          /* the middle column of an odd s is its own mirror */
    for (int j = 0; j < 8 * 3 * h; ++j) acc[j] = 0.0;
    const double phi_lo = 2.0 * M_PI * (0.5 - (double)(i + 1) / (double)w);
    const double phi_hi = 2.0 * M_PI * (0.5 - (double)i / (double)w);
    top_face(faces, sym, ys, s, h, mirrors, phi_lo, phi_hi, acc);   /* -Y: the mirror image of +Y */
    for (int face = 0; face < 6; ++face)
        if (face != 2 && face != 3) side_face(faces, sym, ys, s, h, mirrors, face, phi_lo, phi_hi, acc);
}

/* faces: (6, s, s, 3) floats; out: (h, w, 3) floats. A work-item takes blocks of BLOCK (a define)
 * adjacent columns, blocks gid, gid + size, ... of the (s + 1) / 2 columns that stand for all, with a
 * scratch acc for one block: the work-items alive at once, not the columns, set the scratch's size
 * (on a CPU a few per core: 25 MB at face 1024 where a scratch per column was 0.2 GB, touched
 * fresh in every call). A block's images are runs of adjacent columns (the mirror images run
 * backwards), so its texels go out a cache line at a time: written one column at a time, every
 * 12-byte texel cost the output a line read and written back. */
__kernel void cube_to_equirect(__global const float *faces, __constant const int2 *sym, __global const double *ys,
                               const int s, const int w, const int h, __global double *scratch,
                               __global float *out)
{
    const size_t image = (size_t)8 * h * 3;
    __global double *acc = scratch + get_global_id(0) * BLOCK * image;
    const int count = (s + 1) / 2;
    const double dphi = 2.0 * M_PI / (double)w;
    for (int i0 = get_global_id(0) * BLOCK; i0 < count; i0 += get_global_size(0) * BLOCK) {
        const int n = min(BLOCK, count - i0);
        for (int b = 0; b < n; ++b) resample_column(faces, sym, ys, s, w, h, i0 + b, acc + b * image);
        for (int j = 0; j < h; ++j) {
            const double omega = (ys[j] - ys[j + 1]) * dphi;
            for (int k = 0; k < 4; ++k)
                for (int m = 0; m < 2; ++m)
                    for (int b = 0; b < n; ++b) {
                        const int i = i0 + b;
                        if (m && 2 * i + 1 == s) continue;    /* the middle column of an odd s: its own mirror */
                        int c = (m ? w - 1 - i : i) - k * s;
                        c = c < 0 ? c + w : c;
                        __global const double *a = acc + b * image + ((size_t)(k * 2 + m) * h + j) * 3;
                        __global float *o = out + ((size_t)j * w + c) * 3;
                        for (int ch = 0; ch < 3; ++ch) o[ch] = (float)(a[ch] / omega);
                    }
        }
    }
}
