"""Haar wavelets of the panorama's cube faces, the K largest kept (Ng, Ramamoorthi and Hanrahan,
"All-Frequency Shadows Using Non-linear Wavelet Lighting Approximation", SIGGRAPH 2003): a
non-linear approximation, so each kept coefficient carries its index.

- Cube map: six FACE x FACE faces (docs/conventions.md "Cube maps"), each texel the solid-angle
  weighted mean of the pieces of panorama texels that fall in it (cube_average).
- Per face, the orthonormal 2-D Haar pyramid in the texel measure: at block size 2^s
  (s = 1..log2 FACE) the averages (a + b + c + d)/2 of each 2 x 2 block of the level below and
  its three details, H = (top - bottom)/2, V = (left - right)/2, D = (diagonal)/2; the last
  average is the face's scaling coefficient. A detail at block size 2^s is +-1/2^s on its
  4^s texels; the scaling function 1/FACE on the face.
- Kept: the 6 scaling coefficients always (the sky's mean), then the K - 6 largest details by
  their energy on the sphere, sum_ch Rec.709-luminance |c| times the root mean texel solid angle
  of the support (area-weighted, as NRH 2003 weight by area).
- Irradiance, exact for the kept cube map: each term is a signed sum of constant squares on a
  cube face, and the irradiance of a uniform spherical polygon is Lambert's formula
  E = 1/2 sum_edges angle(A, B) n.(A x B)/|A x B| over the polygon clipped to n's hemisphere
  (the closing edge runs along the horizon); cube edges project to great arcs, so a face
  square is such a polygon.

Layout: K rows (R, G, B) of the kept coefficients, with K codes
code = ((face * 6 + s) * 4 + kind) * 1024 + by * 32 + bx (kind 0 scaling, 1 H, 2 V, 3 D; block
(by, bx) of size 2^s; s = 5 for the scaling terms): below 2^18, an exact float32 (the kernel reads
it so); an engine's 16-bit index would renumber the 6 x 1024 positions."""

from __future__ import annotations


import numpy as np

from iblbake.core import conventions
from iblbake.core.bases import common

NAME = "haar"
TITLE = "Haar wavelets"
RANK = 5                # its place in BASES (the schema's choices, the CLI's, the studies')
HEADER = "basis_haar.h"
KEPT = (16, 32, 64, 128, 256)
OPTIONS = {"haar_coefficients": (KEPT, 64, "haar: the cube-map Haar coefficients kept (the largest; 6 of them the "
                                            "faces' means)")}
FACE = 32
GLSL_IRRADIANCE = "haarIrradiance"      # glsl()'s irradiance function
LEVELS = 5            # log2 FACE
SPLIT = 4


def variants() -> list:
    return [{"haar_coefficients": k} for k in KEPT]


def label(opts) -> str:
    return f"Haar {opts['haar_coefficients']}"


def floats(opts) -> int:
    return opts["haar_coefficients"]


def index_bytes(opts) -> int:
    """Each kept coefficient's index (one of 6 FACE^2 = 6144 positions): 2 bytes."""
    return 2 * opts["haar_coefficients"]


def cube_average(image) -> np.ndarray:
    """(6, FACE, FACE, C): each panorama texel split into SPLIT x SPLIT pieces of equal share of
    its solid angle (SPLIT rows weighted by sin theta), each piece given to the cube texel its
    centre falls in; a cube texel's value the weighted mean of what it received, so a uniform
    sky stays exact. Sampling the panorama at cube subsamples instead left a sun's energy to
    which subsamples hit it: 10.1% irradiance RMSE on sunrise with 256 kept at 16 x 16 subsamples,
    2.2% so."""
    img = np.asarray(image, np.float64)
    h, w, nch = img.shape
    x = (np.arange(SPLIT) + 0.5) / SPLIT
    om = conventions.equirect_row_solid_angles(w, h)
    phi = conventions.equirect_phi(w)[:, None] + (0.5 - x[None, :]) * (2 * np.pi / w)    # (w, SPLIT)
    cells = 6 * FACE * FACE
    acc, wsum = np.zeros((nch, cells)), np.zeros(cells)
    for j in range(h):
        th = np.pi * (j + x) / h
        share = np.sin(th) / np.sin(th).sum() * om[j] / SPLIT                         # (SPLIT,)
        st = np.sin(th)[:, None, None]
        d = np.stack(np.broadcast_arrays(st * np.sin(phi), np.cos(th)[:, None, None], st * np.cos(phi)), -1)
        f, s, t = conventions.cube_from_dir(d)                                       # (SPLIT, w, SPLIT)
        cell = ((f * FACE + np.minimum((t * FACE).astype(np.int64), FACE - 1)) * FACE
                + np.minimum((s * FACE).astype(np.int64), FACE - 1)).reshape(-1)
        wt = np.broadcast_to(share[:, None, None], f.shape).reshape(-1)
        wsum += np.bincount(cell, wt, cells)
        col = np.broadcast_to(np.arange(w)[None, :, None], f.shape).reshape(-1)
        for ch in range(nch):
            acc[ch] += np.bincount(cell, wt * img[j, col, ch], cells)
    # a cube texel no piece fell in (a panorama coarser than the cube map) takes the panorama
    # texel at its centre
    u, v = conventions.equirect_uv_from_dir(conventions.cube_texel_dirs(FACE).reshape(-1, 3))
    centre = img[np.minimum((v * h).astype(np.int64), h - 1), np.minimum((u * w).astype(np.int64), w - 1)]
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(wsum[:, None] > 0, (acc / np.where(wsum > 0, wsum, 1.0)).T, centre)
    return out.reshape(6, FACE, FACE, nch)


def forward(cube):
    """(codes (6 FACE^2,), coefficients (6 FACE^2, C), support solid angle (6 FACE^2,)) of every
    Haar term of the six faces, details level by level, then the faces' scaling terms."""
    om = conventions.cube_texel_solid_angles(FACE)
    codes, vals, areas = [], [], []
    a = np.asarray(cube, np.float64)                              # (6, n, n, C)
    for s in range(1, LEVELS + 1):
        tl, tr, bl, br = a[:, 0::2, 0::2], a[:, 0::2, 1::2], a[:, 1::2, 0::2], a[:, 1::2, 1::2]
        n = tl.shape[1]
        f, by, bx = np.meshgrid(np.arange(6), np.arange(n), np.arange(n), indexing="ij")
        block = om.reshape(n, FACE // n, n, FACE // n).mean(axis=(1, 3))
        for kind, c in ((1, tl + tr - bl - br), (2, tl - tr + bl - br), (3, tl - tr - bl + br)):
            codes.append(code(f, s, kind, by, bx).reshape(-1))
            vals.append(0.5 * c.reshape(-1, c.shape[-1]))
            areas.append(np.broadcast_to(block, (6, n, n)).reshape(-1))
        a = 0.5 * (tl + tr + bl + br)
    codes.append(code(np.arange(6), LEVELS, 0, 0, 0))
    vals.append(a.reshape(6, -1))
    areas.append(np.full(6, om.mean()))
    return np.concatenate(codes), np.concatenate(vals), np.concatenate(areas)


def code(f, s, kind, by, bx):
    return ((np.asarray(f) * 6 + s) * 4 + kind) * 1024 + np.asarray(by) * 32 + np.asarray(bx)


def decode(c: int):
    c = int(c)
    rest, pos = divmod(c, 1024)
    fs, kind = divmod(rest, 4)
    f, s = divmod(fs, 6)
    return f, s, kind, pos // 32, pos % 32


def select(codes, vals, areas, k: int):
    """(codes (k,), coefficients (k, C)): the scaling terms and the k - 6 largest details."""
    from iblbake.core.metrics import LUMINANCE
    lum = LUMINANCE if vals.shape[1] >= 3 else np.ones(vals.shape[1])
    scaling = (codes // 1024) % 4 == 0
    energy = np.where(scaling, np.inf, (np.abs(vals[:, :len(lum)]) @ lum) * np.sqrt(areas))
    keep = np.argsort(-energy, kind="stable")[:k]
    return codes[keep], vals[keep]


def project(image, opts) -> np.ndarray:
    """Coefficients (K, C+1): the kept values with each one's code in the last column."""
    codes, c = select(*forward(cube_average(np.asarray(image)[..., :3])), opts["haar_coefficients"])
    return np.concatenate([c, codes[:, None].astype(np.float64)], 1)


def squares(cd: int):
    """[(sign * amplitude, face, s0, t0, s1, t1)] of one term: its constant squares in face
    coordinates (t = 0 the top row)."""
    f, s, kind, by, bx = decode(cd)
    if kind == 0:
        return [(1.0 / FACE, f, 0.0, 0.0, 1.0, 1.0)]
    n, h = (1 << s) / FACE, (1 << (s - 1)) / FACE
    s0, t0, amp = bx * n, by * n, 1.0 / (1 << s)
    signs = {1: (1, 1, -1, -1), 2: (1, -1, 1, -1), 3: (1, -1, -1, 1)}[kind]     # TL TR BL BR
    quads = ((s0, t0), (s0 + h, t0), (s0, t0 + h), (s0 + h, t0 + h))
    return [(sg * amp, f, a, b, a + h, b + h) for sg, (a, b) in zip(signs, quads)]


def _segment(a, b, n):
    """1/2 angle(a, b) n.(a x b)/|a x b|, broadcasting over the leading axes."""
    cr = np.cross(a, b)
    ln = np.linalg.norm(cr, axis=-1)
    ang = np.arctan2(ln, (a * b).sum(-1))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ln > 0, 0.5 * ang * (cr * n).sum(-1) / np.where(ln > 0, ln, 1.0), 0.0)


def rects_irradiance(f, s0, t0, s1, t1, n) -> np.ndarray:
    """int over each face square (arrays (M,) of face and face coordinates) of max(0, n.w) dw at
    normals n (N, 3), shape (M, N): Lambert's formula on the square clipped to n's hemisphere,
    the closing edge along the horizon from where the boundary leaves it to where it returns."""
    f, s0, t0, s1, t1 = (np.atleast_1d(np.asarray(x)) for x in (f, s0, t0, s1, t1))
    n = np.asarray(n, np.float64)[None]                                           # (1, N, 3)
    v = conventions.dir_from_cube(f[:, None], np.stack([s0, s0, s1, s1], 1), np.stack([t0, t1, t1, t0], 1))
    outward = np.einsum("mk,mk->m", np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), v[:, 0]) > 0
    v = np.where(outward[:, None, None], v, v[:, ::-1])                           # counter-clockwise from outside
    d = np.einsum("nk,mvk->mnv", n[0], v)                                        # (M, N, 4)
    e = np.zeros(d.shape[:2])
    exit_pt = np.zeros(d.shape[:2] + (3,))
    entry_pt = np.zeros(d.shape[:2] + (3,))
    for i in range(4):
        j = (i + 1) % 4
        vi, vj = v[:, None, i], v[:, None, j]                                    # (M, 1, 3)
        di, dj = d[..., i], d[..., j]
        with np.errstate(invalid="ignore", divide="ignore"):
            x = vi + (vj - vi) * (di / np.where(di != dj, di - dj, 1.0))[..., None]
        both, out, inn = (di >= 0) & (dj >= 0), (di >= 0) & (dj < 0), (di < 0) & (dj >= 0)
        e += np.where(both, _segment(vi, vj, n), 0.0)
        e += np.where(out, _segment(vi, x, n), 0.0) + np.where(inn, _segment(x, vj, n), 0.0)
        exit_pt = np.where(out[..., None], x, exit_pt)
        entry_pt = np.where(inn[..., None], x, entry_pt)
    clipped = (d < 0).any(-1) & (d >= 0).any(-1)
    return e + np.where(clipped, _segment(exit_pt, entry_pt, n), 0.0)


def rect_irradiance(f, s0, t0, s1, t1, n) -> np.ndarray:
    """One square's irradiance at normals n, (N,)."""
    return rects_irradiance(f, s0, t0, s1, t1, n)[0]


def _values(coeffs):
    c = np.asarray(coeffs, np.float64)
    return c[:, :-1], c[:, -1].astype(np.int64)


def radiance(coeffs, dirs, opts) -> np.ndarray:
    vals, codes = _values(coeffs)
    d = np.asarray(dirs, np.float64)
    face, s, t = conventions.cube_from_dir(d)
    out = np.zeros(d.shape[:-1] + (vals.shape[1],))
    for cval, cd in zip(vals, codes):
        for amp, f, s0, t0, s1, t1 in squares(cd):
            m = (face == f) & (s >= s0) & (s < s1) & (t >= t0) & (t < t1)
            out += np.where(m[..., None], amp * cval, 0.0)
    return out


def irradiance(coeffs, normals, opts) -> np.ndarray:
    vals, codes = _values(coeffs)
    n = np.asarray(normals, np.float64)
    flat = n.reshape(-1, 3)
    sq = [(k, *q) for k, cd in enumerate(codes) for q in squares(cd)]
    term, amp, f, s0, t0, s1, t1 = (np.array(x) for x in zip(*sq))
    out = np.zeros((len(flat), vals.shape[1]))
    w = np.zeros((len(codes), len(sq)))
    w[term, np.arange(len(sq))] = amp
    for r0 in range(0, len(flat), 256):                 # (squares, normals) a block at a time
        e = rects_irradiance(f, s0, t0, s1, t1, flat[r0:r0 + 256])
        out[r0:r0 + 256] = (w @ e).T @ vals
    return np.maximum(0.0, out).reshape(n.shape[:-1] + (vals.shape[1],))


def validate(coeffs, opts) -> np.ndarray:
    k = opts["haar_coefficients"]
    a = np.asarray(coeffs, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] < 2:
        raise ValueError(f"Haar {k}: expected {k} rows of per-channel values and a code, got shape {a.shape}")
    common.check_coefficients(a, k, f"Haar {k} coefficients")
    codes = a[:, -1]
    if (codes != np.round(codes)).any() or (codes < 0).any():
        raise ValueError(f"Haar {k}: codes must be non-negative integers")
    for cd in codes.astype(np.int64):
        f, s, kind, by, bx = decode(cd)
        scaling = kind == 0 and s == LEVELS and by == bx == 0
        detail = kind in (1, 2, 3) and 1 <= s <= LEVELS and max(by, bx) < FACE >> s
        if f > 5 or not (scaling or detail):
            raise ValueError(f"Haar {k}: code {cd} is no Haar term of a {FACE} x {FACE} face")
    if len(set(codes.tolist())) != k:
        raise ValueError(f"Haar {k}: a term kept twice")
    return a


def defines(opts) -> dict:
    return {"BASIS_HAAR": 1, "HAAR_TERMS": opts["haar_coefficients"]}


def pack(coeffs, opts) -> np.ndarray:
    """K rows (value rgb, code)."""
    vals, codes = _values(coeffs)
    out = np.zeros((len(codes), 4), np.float32)
    out[:, :3] = vals[:, :3]
    out[:, 3] = codes
    return out


def glsl(coeffs, opts) -> str:
    vals, codes = _values(coeffs)
    k = len(codes)
    return f"""// iblbake Haar wavelets of the cube faces ({FACE} x {FACE}), the {k} largest kept (Ng, Ramamoorthi,
// Hanrahan 2003); irradiance exact for them by Lambert's formula on each clipped face square; world +y up.
// diffuse = albedo / PI * haarIrradiance(normalize(N));
{common.glsl_vec3_array("HAAR_VALUE", vals[:, :3])}
const int HAAR_CODE[{k}] = int[{k}]({", ".join(str(int(c)) for c in codes)});

vec3 haarCubeDir(int f, float s, float t) {{
    float a = 2.0 * s - 1.0, b = 2.0 * t - 1.0;
    if (f == 0) return vec3(1.0, -b, -a);
    if (f == 1) return vec3(-1.0, -b, a);
    if (f == 2) return vec3(a, 1.0, b);
    if (f == 3) return vec3(a, -1.0, -b);
    if (f == 4) return vec3(a, -b, 1.0);
    return vec3(-a, -b, -1.0);
}}

float haarSegment(vec3 a, vec3 b, vec3 n) {{
    vec3 c = cross(a, b);
    float l = length(c);
    return l > 0.0 ? 0.5 * atan(l, dot(a, b)) * dot(c, n) / l : 0.0;
}}

float haarRect(int f, float s0, float t0, float s1, float t1, vec3 n) {{
    vec3 v[4];
    v[0] = haarCubeDir(f, s0, t0); v[1] = haarCubeDir(f, s0, t1);
    v[2] = haarCubeDir(f, s1, t1); v[3] = haarCubeDir(f, s1, t0);
    if (dot(cross(v[1] - v[0], v[2] - v[0]), v[0]) < 0.0) {{ vec3 w = v[1]; v[1] = v[3]; v[3] = w; }}
    float e = 0.0;
    vec3 xo = vec3(0.0), xi = vec3(0.0);
    bool above = false, below = false;
    for (int i = 0; i < 4; ++i) {{
        vec3 p = v[i], q = v[(i + 1) % 4];
        float di = dot(n, p), dj = dot(n, q);
        if (di >= 0.0) above = true; else below = true;
        vec3 x = di != dj ? p + (q - p) * (di / (di - dj)) : p;
        if (di >= 0.0 && dj >= 0.0) e += haarSegment(p, q, n);
        else if (di >= 0.0) {{ e += haarSegment(p, x, n); xo = x; }}
        else if (dj >= 0.0) {{ e += haarSegment(x, q, n); xi = x; }}
    }}
    return (above && below) ? e + haarSegment(xo, xi, n) : e;
}}

vec3 haarIrradiance(vec3 n) {{
    vec3 e = vec3(0.0);
    for (int k = 0; k < {k}; ++k) {{
        int c = HAAR_CODE[k], pos = c % 1024, rest = c / 1024;
        int kind = rest % 4, fs = rest / 4, s = fs % 6, f = fs / 6, by = pos / 32, bx = pos % 32;
        if (kind == 0) {{ e += HAAR_VALUE[k] * (haarRect(f, 0.0, 0.0, 1.0, 1.0, n) / {FACE}.0); continue; }}
        float w = float(1 << s) / {FACE}.0, h = 0.5 * w, s0 = float(bx) * w, t0 = float(by) * w;
        float amp = 1.0 / float(1 << s);
        float tl = haarRect(f, s0, t0, s0 + h, t0 + h, n), tr = haarRect(f, s0 + h, t0, s0 + w, t0 + h, n);
        float bl = haarRect(f, s0, t0 + h, s0 + h, t0 + w, n), br = haarRect(f, s0 + h, t0 + h, s0 + w, t0 + w, n);
        float sum = kind == 1 ? tl + tr - bl - br : kind == 2 ? tl - tr + bl - br : tl - tr - bl + br;
        e += HAAR_VALUE[k] * (amp * sum);
    }}
    return max(e, vec3(0.0));
}}
"""
