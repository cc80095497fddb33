/* A cube map (faces +X -X +Y -Y +Z -Z of s x s, stacked) resampled to an equirect panorama of
 * w x h by exact texel overlaps: each equirect texel the mean of the cube map's box texels over
 * its solid angle. A work-item takes an equirect column (a strip between two meridians): every
 * cube texel the strip meets is clipped to it (a convex polygon of great-circle arcs, a "piece"),
 * and the piece's solid angle below each parallel that crosses it comes from Green's theorem in
 * the equal-area coordinates (phi, y); the symmetries below make that column stand for 16. The
 * derivation, and the float64 twin this follows, is iblbake/bake/cube_resample.py. In double: a
 * piece's area is a difference of its arcs' integrals, each as large as the strip is wide. */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable

#define MAX_POLY 10
#define POLE 1e-12
#define MERIDIAN 1e-14  /* |n_y| of a great circle below this: a meridian, vertical in (phi, y) */

/* face coordinates (a, b) -> direction: origin, along a, along b (conventions.dir_from_cube) */
__constant double FACE_AXES[6][9] = {
    {1, 0, 0, 0, 0, -1, 0, -1, 0},  {-1, 0, 0, 0, 0, 1, 0, -1, 0}, {0, 1, 0, 1, 0, 0, 0, 0, 1},
    {0, -1, 0, 1, 0, 0, 0, 0, -1},  {0, 0, 1, 1, 0, 0, 0, -1, 0},  {0, 0, -1, -1, 0, 0, 0, -1, 0}};

typedef struct {
    double3 p, q, n;
    double integral, dphi, bottom, top;
    int meridian;
} Edge;

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

static int on_arc(const Edge *e, double3 d)
{
    return dot(cross(e->p, d), e->n) >= 0.0 && dot(cross(d, e->q), e->n) >= 0.0;
}

/* atan2(y, x) for the small angles of a piece's arcs (within one equirect column): atan's series
 * to u^9 where |u| = |y / x| <= 1/64 (the next term, u^11 / 11, is below 1e-21), else atan2,
 * whose double precision costs 30-70 ns on a CPU */
static double small_atan2(double y, double x)
{
    if (x > 0.0 && fabs(y) <= x * (1.0 / 64.0)) {
        const double u = y / x, u2 = u * u;
        return u * (1.0 - u2 * (1.0 / 3.0 - u2 * (1.0 / 5.0 - u2 * (1.0 / 7.0 - u2 * (1.0 / 9.0)))));
    }
    return atan2(y, x);
}

/* phi(q) - phi(p), the azimuth turned from p to q, in (-pi, pi] */
static double azimuth_step(double3 p, double3 q) { return small_atan2(p.z * q.x - p.x * q.z, p.x * q.x + p.z * q.z); }

/* the integral of y dphi along the arc a -> b of the great circle of normal n: F(b) - F(a) for
 * F = atan(X / n_y), X = n_x d_z - n_z d_x, as one atan2 (atan u - atan v = atan2(u - v, 1 + uv)) */
static double arc_integral(double3 n, double3 a, double3 b)
{
    const double xa = n.x * a.z - n.z * a.x, xb = n.x * b.z - n.z * b.x;
    return small_atan2((xb - xa) * n.y, n.y * n.y + xa * xb);
}

static Edge make_edge(double3 p, double3 q)
{
    Edge e;
    e.p = p;
    e.q = q;
    const double3 n = cross(p, q);
    const double norm = length(n);
    e.n = norm > 0.0 ? n / norm : (double3)(0.0);
    e.meridian = fabs(e.n.y) < MERIDIAN;
    e.dphi = e.meridian ? 0.0 : azimuth_step(p, q);
    e.integral = e.meridian ? 0.0 : arc_integral(e.n, p, q);
    e.bottom = fmin(p.y, q.y);
    e.top = fmax(p.y, q.y);
    if (e.meridian) return e;                            /* y runs straight between its ends */
    const double3 top = (double3)(-e.n.y * e.n.x, 1.0 - e.n.y * e.n.y, -e.n.y * e.n.z);  /* y's projection */
    for (int s = 0; s < 2; ++s) {
        const double3 x = s ? -top : top;
        if (dot(cross(p, x), e.n) > 0.0 && dot(cross(x, q), e.n) > 0.0) {
            const double y = x.y / length(x);
            e.bottom = fmin(e.bottom, y);
            e.top = fmax(e.top, y);
        }
    }
    return e;
}

/* the integral of (y - Y) dphi over the arc's parts above Y, oriented p -> q */
static double excess(const Edge *e, double big_y)
{
    if (e->meridian || e->top <= big_y) return 0.0;
    if (e->bottom >= big_y) return e->integral - big_y * e->dphi;
    const double3 n = e->n;
    const double rho2 = n.x * n.x + n.z * n.z;
    /* the circle meets the parallel where n_x x + n_z z = -n_y Y and x^2 + z^2 = 1 - Y^2 */
    const double h2 = 1.0 - big_y * big_y - (n.y * big_y) * (n.y * big_y) / rho2;
    const double h = sqrt(fmax(h2, 0.0) / rho2), t = -n.y * big_y / rho2;
    double3 cuts[2];
    int m = 0;
    for (int s = 0; s < 2; ++s) {
        const double sg = s ? -1.0 : 1.0;
        const double3 d = (double3)(t * n.x - sg * h * n.z, big_y, t * n.z + sg * h * n.x);
        if (on_arc(e, d)) cuts[m++] = d;
    }
    if (m == 2 && dot(e->p, cuts[1]) > dot(e->p, cuts[0])) {   /* in order from p */
        const double3 d = cuts[0];
        cuts[0] = cuts[1];
        cuts[1] = d;
    }
    int above = e->p.y != big_y ? e->p.y > big_y : !(e->q.y > big_y);
    double total = 0.0;
    double3 a = e->p;
    for (int k = 0; k <= m; ++k) {
        const double3 b = k < m ? cuts[k] : e->q;
        if (above) total += arc_integral(n, a, b) - big_y * azimuth_step(a, b);
        above = !above;
        a = b;
    }
    return total;
}

typedef struct {
    Edge edges[MAX_POLY];
    int count;
    double pole, pole_dphi, sign, area, bottom, top;
} Piece;

static void make_piece(int face, const double2 *poly, int n_in, Piece *pc)
{
    __constant const double *f = FACE_AXES[face];
    double3 verts[MAX_POLY];
    int is_pole[MAX_POLY];
    int n = 0;
    for (int k = 0; k < n_in; ++k) {
        const double a = poly[k].x, b = poly[k].y;
        if ((face == 2 || face == 3) && fabs(a) < POLE && fabs(b) < POLE) {
            if (n > 0 && is_pole[n - 1]) continue;
            is_pole[n++] = 1;
            continue;
        }
        const double3 d = (double3)(f[0] + a * f[3] + b * f[6], f[1] + a * f[4] + b * f[7], f[2] + a * f[5] + b * f[8]);
        verts[n] = d / length(d);
        is_pole[n++] = 0;
    }
    if (n > 1 && is_pole[0] && is_pole[n - 1]) --n;
    if (n < 3) n = 0;                        /* a sliver of no area at the pole */
    pc->count = 0;
    pc->pole = 0.0;
    pc->pole_dphi = 0.0;
    int has_pole = 0;
    for (int k = 0; k < n; ++k) {
        const int k1 = (k + 1) % n;
        if (is_pole[k]) {
            has_pole = 1;
            pc->pole = face == 2 ? 1.0 : -1.0;
            pc->pole_dphi = azimuth_step(verts[(k + n - 1) % n], verts[k1]);
        } else if (!is_pole[k1] && any(verts[k] != verts[k1])) {
            pc->edges[pc->count++] = make_edge(verts[k], verts[k1]);
        }
    }
    double total = pc->pole * pc->pole_dphi;
    double bottom = has_pole ? pc->pole : 2.0, top = has_pole ? pc->pole : -2.0;
    for (int k = 0; k < pc->count; ++k) {
        total += pc->edges[k].integral;
        bottom = fmin(bottom, pc->edges[k].bottom);
        top = fmax(top, pc->edges[k].top);
    }
    pc->sign = total >= 0.0 ? 1.0 : -1.0;
    pc->area = fabs(total);
    pc->bottom = bottom;
    pc->top = top;
}

/* C(Y): the piece's solid angle where y < Y */
static double below(const Piece *pc, double big_y)
{
    double ex = 0.0;
    for (int k = 0; k < pc->count; ++k) ex += excess(&pc->edges[k], big_y);
    if (pc->pole != 0.0 && pc->pole > big_y) ex += (pc->pole - big_y) * pc->pole_dphi;
    return pc->sign * (pc->sign * pc->area - ex);
}

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

/* Column i's 8 images (each column's full height) accumulated in acc (8 h 3 doubles), then
 * divided by each texel's solid angle into out. */
static void resample_column(__global const float *faces, __constant const int2 *sym, const int s, const int w,
                            const int h, const int i, __global double *acc, __global float *out)
{
    const int mirrors = 2 * i + 1 == s ? 1 : 2;          /* the middle column of an odd s is its own mirror */
    int columns[8];
    for (int k = 0; k < 4; ++k)
        for (int m = 0; m < mirrors; ++m) {
            const int c = (m ? w - 1 - i : i) - k * s;
            columns[k * 2 + m] = c < 0 ? c + w : c;
        }
    for (int j = 0; j < 8 * 3 * h; ++j) acc[j] = 0.0;
    const double phi_lo = 2.0 * M_PI * (0.5 - (double)(i + 1) / (double)w);
    const double phi_hi = 2.0 * M_PI * (0.5 - (double)i / (double)w);
    const int north = h / 2;            /* the northern rows */
    double2 wedge[MAX_POLY], tmp[MAX_POLY], band[MAX_POLY], square[MAX_POLY];
    Piece pc;
    for (int face = 0; face < 6; ++face) {
        if (face == 3) continue;                         /* -Y: the mirror image of +Y */
        const double3 lo = meridian_line(face, phi_lo, 1.0), hi = meridian_line(face, phi_hi, -1.0);
        double2 sq[4] = {(double2)(-1.0, -1.0), (double2)(1.0, -1.0), (double2)(1.0, 1.0), (double2)(-1.0, 1.0)};
        int nw = clip(sq, 4, lo, tmp);
        nw = clip(tmp, nw, hi, wedge);
        if (nw < 3) continue;
        double b_min = 2.0, b_max = -2.0;
        for (int k = 0; k < nw; ++k) {
            b_min = fmin(b_min, wedge[k].y);
            b_max = fmax(b_max, wedge[k].y);
        }
        int r0 = max(0, (int)((b_min + 1.0) * s / 2.0)), r1 = min(s - 1, (int)((b_max + 1.0) * s / 2.0));
        if (face != 2) r1 = min(r1, (s - 1) / 2);        /* a side face's rows reaching above the equator (b < 0) */
        for (int row = r0; row <= r1; ++row) {
            const double e0 = 2.0 * row / s - 1.0, e1 = 2.0 * (row + 1) / s - 1.0;
            int nb = clip(wedge, nw, (double3)(-e0, 0.0, 1.0), tmp);
            nb = clip(tmp, nb, (double3)(e1, 0.0, -1.0), band);
            if (nb < 3) continue;
            double a_min = 2.0, a_max = -2.0;
            for (int k = 0; k < nb; ++k) {
                a_min = fmin(a_min, band[k].x);
                a_max = fmax(a_max, band[k].x);
            }
            const int c0 = max(0, (int)((a_min + 1.0) * s / 2.0)), c1 = min(s - 1, (int)((a_max + 1.0) * s / 2.0));
            for (int col = c0; col <= c1; ++col) {
                const double a0 = 2.0 * col / s - 1.0, a1 = 2.0 * (col + 1) / s - 1.0;
                const double2 texel[4] = {(double2)(a0, e0), (double2)(a1, e0), (double2)(a1, e1), (double2)(a0, e1)};
                int np = clip(texel, 4, lo, tmp);
                np = clip(tmp, np, hi, square);
                if (np < 3) continue;
                make_piece(face, square, np, &pc);
                if (!(pc.area > 0.0) || pc.top <= 0.0) continue;
                const int j_top = min(north - 1, (int)(acos(fmin(1.0, pc.top)) * h / M_PI));
                const int j_bottom = min(north - 1, (int)(acos(fmax(0.0, pc.bottom)) * h / M_PI));
                float3 value[16];                                /* the texel's 16 images */
                for (int g = 0; g < 4 * 2 * 2; ++g)
                    if (mirrors == 2 || !(g & 2)) value[g] = vload3(image_texel(sym, g, face, row, col, s), faces);
                double upper = pc.area;
                for (int j = j_top; j <= j_bottom; ++j) {
                    const double big_y = sin(M_PI * (double)(h - 2 * (j + 1)) / (double)(2 * h));
                    const double lower = big_y > pc.bottom ? below(&pc, big_y) : 0.0;
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
        }
    }
    const double dphi = 2.0 * M_PI / (double)w;
    for (int k = 0; k < 4; ++k)
        for (int m = 0; m < mirrors; ++m) {
            const int c = columns[k * 2 + m];
            for (int j = 0; j < h; ++j) {
                const double omega = dphi * (sin(M_PI * (double)(h - 2 * j) / (double)(2 * h)) -
                                             sin(M_PI * (double)(h - 2 * (j + 1)) / (double)(2 * h)));
                __global const double *a = acc + ((size_t)(k * 2 + m) * h + j) * 3;
                __global float *o = out + ((size_t)j * w + c) * 3;
                for (int ch = 0; ch < 3; ++ch) o[ch] = (float)(a[ch] / omega);
            }
        }
}

/* faces: (6, s, s, 3) floats; out: (h, w, 3) floats. A work-item takes columns gid, gid + size,
 * ... of the (s + 1) / 2 that stand for all; acc is its scratch for one of them, its 8 images'
 * full height in doubles (8 h 3): the work-items alive at once, not the columns, set the
 * scratch's size (on a CPU a few per core, so the 0.2 GB a scratch per column took at face 1024,
 * touched fresh in every call, is 6 MB that stays in cache). */
__kernel void cube_to_equirect(__global const float *faces, __constant const int2 *sym, const int s, const int w,
                               const int h, __global double *scratch, __global float *out)
{
    __global double *acc = scratch + (size_t)get_global_id(0) * 8 * h * 3;
    for (int i = get_global_id(0); i < (s + 1) / 2; i += get_global_size(0))
        resample_column(faces, sym, s, w, h, i, acc, out);
}
