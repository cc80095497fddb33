"""The specular bakes: radiance mip chain, GGX-prefiltered chain, DFG table.

Each has a numpy twin of its kernel in kernels/mips.cl (tests compare them) and the prefiltered
chain has a brute-force float64 reference (every source texel, exact solid angles).

Layouts of the prefiltered chain (every one from the same kernel code path, LAYOUT define):
- equirect:   level of size s is 2s x s
- cubemap:    faces +X -X +Y -Y +Z -Z of s x s stacked vertically (an s x 6s image)
- octahedral: s x s, +y at the centre
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from iblbake.core import brdf
from iblbake.core import conventions
from iblbake.core import sampling

LAYOUT_IDS = {"equirect": 0, "cubemap": 1, "octahedral": 2}
MIN_LEVEL_SIZE = 8
# `convolve` reads a chain level with texels this many times smaller than the lobe's angular scale
TEXELS_PER_LOBE = 12.0  # measured at face 256 on city, r = 0.5: 6 -> 1.05%, 12 -> 0.20%, 24 -> 0.04%


# --- sizes ----------------------------------------------------------------------------------

def radiance_chain_sizes(width: int, height: int):
    """(w, h) of every level: halving down to one row (and at least one column)."""
    sizes = [(width, height)]
    while sizes[-1][1] > 1:
        w, h = sizes[-1]
        sizes.append((max(1, w // 2), max(1, h // 2)))
    return sizes


def default_base_size(layout: str, src_height: int) -> int:
    """equirect: the source height; cubemap: half the source height (1024x512 -> face 256,
    matching texel density at the equator); octahedral: the source height."""
    return max(1, src_height // 2) if layout == "cubemap" else max(1, src_height)


def prefiltered_sizes(base: int, levels: int | None = None, min_size: int = MIN_LEVEL_SIZE):
    """Size parameter s of each level: base >> k, not below min_size (nor below 1). Default
    number of levels: one per halving from base down to min_size."""
    floor = max(1, min(min_size, base))
    if levels is None:
        levels, s = 1, base
        while s // 2 >= floor:
            s //= 2
            levels += 1
    return [max(floor, base >> k) for k in range(levels)]


def level_roughness(levels: int):
    """r_k = k / (K - 1): level 0 is the mirror, the last is roughness 1."""
    return [0.0] if levels == 1 else [k / (levels - 1) for k in range(levels)]


def layout_shape(layout: str, s: int):
    return {"equirect": (s, 2 * s), "cubemap": (6 * s, s), "octahedral": (s, s)}[layout]


def layout_dirs(layout: str, s: int):
    """Directions of the texel centres of one level, shaped like the stored image (H, W, 3)."""
    if layout == "equirect":
        return conventions.equirect_texel_dirs(2 * s, s)
    if layout == "cubemap":
        return conventions.cube_texel_dirs(s).reshape(6 * s, s, 3)
    return conventions.octahedral_texel_dirs(s)


def layout_solid_angles(layout: str, s: int):
    """Solid angle of each texel of one level (H, W); sums to 4 pi (octahedral: numerically)."""
    if layout == "equirect":
        return conventions.equirect_solid_angles(2 * s, s)
    if layout == "cubemap":
        return np.tile(conventions.cube_texel_solid_angles(s), (6, 1))
    # octahedral: Jacobian of the map by finite differences at texel centres, normalised to 4 pi
    d = conventions.octahedral_texel_dirs(s)
    du = np.gradient(d, axis=1)
    dv = np.gradient(d, axis=0)
    a = np.linalg.norm(np.cross(du, dv), axis=-1)
    return a * (4 * np.pi / a.sum())


# --- radiance chain -------------------------------------------------------------------------

def _overlap_matrix(n_dst: int, n_src: int, polar: bool):
    """A[d, s] = measure of the overlap of destination cell d and source cell s on [0, 1]
    (polar: measured in cos(pi v), i.e. solid angle per unit azimuth)."""
    e_src = np.arange(n_src + 1) / n_src
    e_dst = np.arange(n_dst + 1) / n_dst
    lo = np.maximum(e_dst[:-1, None], e_src[None, :-1])
    hi = np.minimum(e_dst[1:, None], e_src[None, 1:])
    if polar:
        mid = np.minimum(lo + hi, 2.0 - lo - hi)
        w = 2.0 * np.sin(0.5 * np.pi * mid) * np.sin(0.5 * np.pi * np.maximum(hi - lo, 0.0))
    else:
        w = hi - lo
    return np.where(hi > lo, w, 0.0)


def downsample_twin(src, dw: int, dh: int):
    """numpy twin of kernels/mips.cl:downsample (float64)."""
    src = np.asarray(src, dtype=np.float64)
    sh, sw = src.shape[:2]
    rows = _overlap_matrix(dh, sh, polar=True)
    cols = _overlap_matrix(dw, sw, polar=False)
    # columns first, then rows: two small contractions (a single three-operand einsum is a
    # 4-deep loop, minutes at 1024x512)
    num = np.einsum("pj,jqc->pqc", rows, np.einsum("qi,jic->jqc", cols, src, optimize=True), optimize=True)
    den = rows.sum(1)[:, None] * cols.sum(1)[None, :]
    return num / den[..., None]


def radiance_chain_twin(image):
    chain = [np.asarray(image, dtype=np.float64)]
    for w, h in radiance_chain_sizes(image.shape[1], image.shape[0])[1:]:
        chain.append(downsample_twin(chain[-1], w, h))
    return chain


def solid_angle_mean(image, layout: str = "equirect", s: int | None = None):
    """Mean radiance weighted by texel solid angle (per channel)."""
    image = np.asarray(image, dtype=np.float64)
    if layout == "equirect":
        wgt = conventions.equirect_solid_angles(image.shape[1], image.shape[0])
    else:
        wgt = layout_solid_angles(layout, s)
    return (image * wgt[..., None]).sum((0, 1)) / wgt.sum()


# --- GGX sample sets --------------------------------------------------------------------------

@dataclass
class SampleSet:
    """Accepted reflected directions of one roughness in the local frame (z = n = v), with
    log2 of each one's solid angle 1 / (N pdf(l)); float32 rows for the kernel."""
    rows: np.ndarray   # (M, 4): l.x, l.y, l.z (= NoL), log2(Omega_s)
    total: int         # N, the Hammersley count (M <= N accepted)


def ggx_sample_set(alpha: float, n: int) -> SampleSet:
    """N Hammersley points warped to GGX half-vectors, reflected about h with v = n:
    l = 2 (n.h) h - n; pdf(l) = D(h) NoH / (4 VoH) = D(h) / 4 (NoH = VoH when v = n)."""
    h = sampling.sample_ggx_half(sampling.hammersley(n), alpha)
    noh = h[:, 2]
    l = 2.0 * noh[:, None] * h - np.array([0.0, 0.0, 1.0])
    keep = l[:, 2] > 0
    pdf = sampling.pdf_ggx_reflected(noh, noh, alpha)
    log2_omega = -np.log2(n * np.maximum(pdf, 1e-30))
    rows = np.concatenate([l, log2_omega[:, None]], axis=1)[keep]
    return SampleSet(rows.astype(np.float32), n)


def texel_solid_angle_at(chain0_w: int, chain0_h: int, dirs):
    """Solid angle density of level-0 equirect texels at each direction's latitude,
    (2 pi / W)(pi / H) sin(theta), floored at the polar row centre (continuous in the direction,
    so that the level choice does not jump at row boundaries)."""
    st = np.sqrt(np.maximum(0.0, 1.0 - np.asarray(dirs)[..., 1] ** 2))
    st = np.maximum(st, math.sin(0.5 * math.pi / chain0_h))
    return (2.0 * math.pi / chain0_w) * (math.pi / chain0_h) * st


def chain_lookup_twin(chain, dirs, lod):
    """numpy twin of chain_lookup: trilinear in the radiance chain."""
    u, v = conventions.equirect_uv_from_dir(dirs)
    # +-inf clamp to the ends; NaN (the 0/0 pdf of a delta lobe) reads level 0
    lod = np.asarray(lod, np.float64)
    lod = np.clip(np.where(np.isnan(lod), 0.0, lod), 0.0, len(chain) - 1)
    l0 = np.floor(lod).astype(np.int64)
    f = (lod - l0)[..., None]
    out = np.zeros(dirs.shape[:-1] + (chain[0].shape[-1],))
    for k in np.unique(l0):
        m = l0 == k
        a = conventions.bilinear_equirect(chain[k], u[m], v[m])
        b = conventions.bilinear_equirect(chain[min(k + 1, len(chain) - 1)], u[m], v[m])
        out[m] = a * (1 - f[m]) + b * f[m]
    return out


def prefilter_twin(chain, dirs, roughness: float, n_samples: int, lod_bias: float = 0.0,
                        fis: bool = True):
    """numpy twin of kernels/mips.cl:prefilter at output directions dirs (..., 3), float64."""
    dirs = np.asarray(dirs, dtype=np.float64)
    flat = dirs.reshape(-1, 3)
    if roughness == 0.0:
        return chain_lookup_twin(chain, flat, np.zeros(len(flat))).reshape(dirs.shape[:-1] + (-1,))
    s = ggx_sample_set(roughness * roughness, n_samples).rows.astype(np.float64)
    t, b = conventions.tangent_frame(flat)
    h0, w0 = chain[0].shape[:2]
    acc = np.zeros((len(flat), chain[0].shape[-1]))
    wsum = np.zeros(len(flat))
    for lx, ly, lz, log2_om in s:
        l = t * lx + b * ly + flat * lz
        l /= np.linalg.norm(l, axis=-1, keepdims=True)
        lod = (0.5 * (log2_om - np.log2(texel_solid_angle_at(w0, h0, l))) + lod_bias) if fis else np.zeros(len(l))
        acc += lz * chain_lookup_twin(chain, l, lod)
        wsum += lz
    return (acc / wsum[:, None]).reshape(dirs.shape[:-1] + (-1,))


def _texel_subsamples(w: int, h: int, s: int):
    """Directions and exact solid angles of an s x s subdivision of every texel, grouped by texel:
    shapes (h*w, s*s, 3) and (h*w, s*s)."""
    d = conventions.equirect_texel_dirs(w * s, h * s).reshape(h, s, w, s, 3)
    om = conventions.equirect_solid_angles(w * s, h * s).reshape(h, s, w, s)
    return (d.transpose(0, 2, 1, 3, 4).reshape(h * w, s * s, 3),
            om.transpose(0, 2, 1, 3).reshape(h * w, s * s))


def prefilter_bruteforce(source, dirs, roughness: float, chunk: int | None = None, max_sub: int | None = None,
                         max_parts: float = 4e6):
    """The ground truth of a prefiltered texel: the integral over the sphere of the source (piecewise
    constant over its texels) against the lobe, sum L(w) D(h) NoL dOmega / sum D(h) NoL dOmega with
    h = normalize(n + w), NoL = n.w > 0 (the limit of Karis' NoL-weighted estimator, N = V = R).
    Every source texel takes part; each is split into s x s parts with exact solid angles, parts no
    wider than a quarter of the lobe's scale alpha nor than 0.05 rad (the midpoint rule on a wide
    lobe), s capped at max_sub (default: at most max_parts parts in all). float64.
    Roughness 0 is the mirror: the source read bilinearly at n."""
    source = np.asarray(source, dtype=np.float64)
    dirs = np.asarray(dirs, dtype=np.float64)
    flat = dirs.reshape(-1, 3)
    if roughness == 0.0:
        u, v = conventions.equirect_uv_from_dir(flat)
        return conventions.bilinear_equirect(source, u, v).reshape(dirs.shape[:-1] + (-1,))
    h, w = source.shape[:2]
    alpha = roughness * roughness
    if max_sub is None:
        max_sub = max(1, int(math.sqrt(max_parts / (h * w))))
    sub = int(min(max_sub, max(1, math.ceil((math.pi / h) / min(0.25 * alpha, 0.05)))))
    src_dirs, d_omega = _texel_subsamples(w, h, sub)
    values = source.reshape(-1, source.shape[-1])
    chunk = chunk or max(1, min(64, int(2e7 // (h * w * sub * sub))))
    out = np.empty((len(flat), values.shape[-1]))
    for i0 in range(0, len(flat), chunk):
        n = flat[i0:i0 + chunk]
        nol = np.einsum("cd,tsd->cts", n, src_dirs)              # (c, texels, parts)
        noh = np.sqrt(np.maximum(0.5 * (1.0 + nol), 0.0))         # n.h with h = (n + w)/|n + w|
        wgt = (np.where(nol > 0, brdf.d_ggx(noh, alpha) * nol, 0.0) * d_omega).sum(-1)  # (c, texels)
        out[i0:i0 + chunk] = (wgt @ values) / wgt.sum(1, keepdims=True)
    return out.reshape(dirs.shape[:-1] + (-1,))


# --- DFG ----------------------------------------------------------------------------------------

def dfg_twin(size: int, n_samples: int, multiscatter: bool = False):
    """numpy twin of kernels/mips.cl:dfg, shape (size, size, 2) indexed [roughness, NoV]."""
    grid = np.arange(size) / (size - 1)
    nov = np.maximum(grid, 1e-4)[None, :]
    r = grid[:, None]
    alpha = r * r
    u = sampling.hammersley(n_samples)
    a = np.zeros((size, size))
    b = np.zeros((size, size))
    vx, vz = np.sqrt(1.0 - nov * nov), nov
    for u0, u1 in u:
        hl = sampling.sample_ggx_half(np.array([u0, u1]), alpha)    # (size, 1, 3)
        hx, hz = hl[..., 0], hl[..., 2]   # v has no y component
        voh = vx * hx + vz * hz
        lz = 2.0 * voh * hz - vz
        nol = np.clip(lz, 0.0, 1.0)
        ok = (nol > 0) & (voh > 0)
        gv = 4.0 * brdf.v_smith_ggx_correlated(nov, nol, alpha) * nol * voh / np.maximum(hz, 1e-30)
        fc = (1.0 - np.clip(voh, 0, 1)) ** 5
        a += np.where(ok, gv * (1 - fc), 0.0)
        b += np.where(ok, gv * fc, 0.0)
    a /= n_samples
    b /= n_samples
    e = np.maximum(a + b, 1.0)   # the exact A + B is <= 1; the QMC estimate can overshoot by ~1e-4
    a, b = a / e, b / e
    out = np.stack([b, a + b] if multiscatter else [a, b], axis=-1)
    return out


def dfg_lookup(table, nov, roughness):
    """Bilinear lookup of a DFG table at (NoV, roughness) on its endpoint-inclusive grid."""
    n = table.shape[0]
    x = np.clip(np.asarray(nov, dtype=np.float64), 0, 1) * (n - 1)
    y = np.clip(np.asarray(roughness, dtype=np.float64), 0, 1) * (n - 1)
    x0 = np.minimum(np.floor(x).astype(int), n - 2)
    y0 = np.minimum(np.floor(y).astype(int), n - 2)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    t = table[y0, x0] * (1 - fx) + table[y0, x0 + 1] * fx
    bt = table[y0 + 1, x0] * (1 - fx) + table[y0 + 1, x0 + 1] * fx
    return t * (1 - fy) + bt * fy


def relative_rmse(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(math.sqrt(np.mean((a - b) ** 2)) / max(math.sqrt(np.mean(b ** 2)), 1e-300))


# --- OpenCL ---------------------------------------------------------------------------------------

def to_rgba(image):
    image = np.asarray(image, dtype=np.float32)
    out = np.zeros(image.shape[:2] + (4,), np.float32)
    out[..., :3] = image[..., :3]
    return out


class OpenCLBaker:
    """Runs kernels/mips.cl on one device (iblbake.cl.Runtime)."""

    def __init__(self, rt):
        self.rt = rt

    def radiance_chain(self, image):
        """Every level as float32 (h, w, 3), and the device buffer of the concatenated chain."""
        rt = self.rt
        sizes = radiance_chain_sizes(image.shape[1], image.shape[0])
        offsets = np.cumsum([0] + [w * h for w, h in sizes])
        buf = rt.empty(int(offsets[-1]) * 16)
        rt.cl.enqueue_copy(rt.queue, buf, to_rgba(image))
        k = rt.kernel("mips.cl", "downsample")
        for lvl in range(1, len(sizes)):
            (sw, sh), (dw, dh) = sizes[lvl - 1], sizes[lvl]
            rt.run(k, (dw, dh), None, buf, np.int32(offsets[lvl - 1]), np.int32(sw), np.int32(sh),
                   np.int32(offsets[lvl]), np.int32(dw), np.int32(dh))
        flat = rt.read(buf, (int(offsets[-1]), 4))
        levels = [flat[offsets[i]:offsets[i + 1], :3].reshape(h, w, 3) for i, (w, h) in enumerate(sizes)]
        return levels, (buf, offsets, sizes)

    def _chain_args(self, device_chain):
        buf, offsets, sizes = device_chain
        rt = self.rt
        off = rt.to_device(np.asarray(offsets[:-1], np.int32))
        lw = rt.to_device(np.asarray([w for w, _ in sizes], np.int32))
        lh = rt.to_device(np.asarray([h for _, h in sizes], np.int32))
        return (buf, off, lw, lh, np.int32(len(sizes)))

    def prefilter_level(self, device_chain, layout: str, s: int, roughness: float, n_samples: int,
                        lod_bias: float = 0.0, fis: bool = True):
        rt = self.rt
        shape = layout_shape(layout, s)
        n = shape[0] * shape[1]
        out = rt.empty(n * 16)
        defines = {"LAYOUT": LAYOUT_IDS[layout]}
        chain_args = self._chain_args(device_chain)
        global_size = (-(-n // 64) * 64,)
        if roughness == 0.0:
            k = rt.kernel("mips.cl", "resample", defines)
            rt.run(k, global_size, None, *chain_args, np.int32(s), np.int32(n), out)
        else:
            ss = ggx_sample_set(roughness * roughness, n_samples)
            k = rt.kernel("mips.cl", "prefilter", defines)
            rt.run(k, global_size, None, *chain_args, rt.to_device(ss.rows), np.int32(len(ss.rows)),
                   np.float32(lod_bias), np.int32(1 if fis else 0), np.int32(s), np.int32(n), out)
        return rt.read(out, (n, 4))[:, :3].reshape(shape + (3,))

    def convolve_level(self, chain_levels, layout: str, s: int, roughness: float,
                       texels_per_lobe: float = TEXELS_PER_LOBE):
        """One prefiltered level by the deterministic `convolve` kernel."""
        rt = self.rt
        alpha = roughness * roughness
        sizes = [(c.shape[1], c.shape[0]) for c in chain_levels]
        lvl, sub = convolve_level_choice(sizes, alpha, texels_per_lobe)
        src = chain_levels[lvl]
        shape = layout_shape(layout, s)
        n = shape[0] * shape[1]
        out = rt.empty(n * 16)
        k = rt.kernel("mips.cl", "convolve", {"LAYOUT": LAYOUT_IDS[layout]})
        col = _column_sin_cos(src.shape[1] * sub).astype(np.float32)
        rt.run(k, (-(-n // 64) * 64,), None, rt.to_device(to_rgba(src)), np.int32(src.shape[1]),
               np.int32(src.shape[0]), rt.to_device(col), np.int32(sub), np.float32(alpha),
               np.float32(lobe_cutoff(alpha)), np.int32(s), np.int32(n), out)
        return rt.read(out, (n, 4))[:, :3].reshape(shape + (3,))

    def dfg(self, size: int, n_samples: int, multiscatter: bool = False):
        rt = self.rt
        out = rt.empty(size * size * 8)
        defines = {"MULTISCATTER": 1} if multiscatter else {}
        k = rt.kernel("mips.cl", "dfg", defines)
        rt.run(k, (size, size), None, np.int32(size), np.int32(n_samples), out)
        return rt.read(out, (size, size, 2))


# --- deterministic convolution (the `convolve` kernel) ---------------------------------------------

def lobe_cutoff(alpha: float, fraction: float = 1e-4) -> float:
    """cos of the angle between n and w beyond which D(h) NoL < fraction * its peak (capped at the
    horizon). D(theta_h)/D(0) = alpha^4 / (cos^2 theta_h (alpha^2 - 1) + 1)^2."""
    a2 = alpha * alpha
    target = a2 / math.sqrt(fraction)            # cos^2(th)(a2 - 1) + 1 at the cut
    if target >= 1.0:
        return 0.0
    cos2 = (target - 1.0) / (a2 - 1.0)
    theta_h = math.acos(math.sqrt(min(1.0, max(0.0, cos2))))
    return max(0.0, math.cos(min(2.0 * theta_h, math.pi / 2)))




def convolve_level_choice(chain_sizes, alpha: float, texels_per_lobe: float = TEXELS_PER_LOBE,
                          min_rows: int = 32):
    """(chain level index, sub-texel split): the coarsest level whose texels are texels_per_lobe
    times smaller than the lobe's angular scale (about 2 alpha in reflected directions) and that
    has at least min_rows rows; where even level 0 is too coarse, its texels are split s x s."""
    scale = 2.0 * alpha
    best = 0
    for k, (w, h) in enumerate(chain_sizes):
        if math.pi / h <= scale / texels_per_lobe and h >= min(min_rows, chain_sizes[0][1]):
            best = k
    h0 = chain_sizes[0][1]
    sub = 1 if best > 0 else max(1, math.ceil((math.pi / h0) * texels_per_lobe / scale))
    return best, sub


def convolve_cost(chain_sizes, out_texels: int, alpha: float, texels_per_lobe: float = TEXELS_PER_LOBE) -> float:
    """Approximate weight evaluations of `convolve` for one level."""
    k, sub = convolve_level_choice(chain_sizes, alpha, texels_per_lobe)
    w, h = chain_sizes[k]
    cells = w * h * sub * sub
    cone = 2.0 * math.pi * (1.0 - lobe_cutoff(alpha))
    return out_texels * min(cells, cone * cells / (4 * math.pi) + 4 * h * sub)


def _column_sin_cos(w: int):
    phi = 2.0 * np.pi * (0.5 - (np.arange(w) + 0.5) / w)
    return np.stack([np.sin(phi), np.cos(phi)], axis=-1)


def convolve_twin(chain, dirs, roughness: float, texels_per_lobe: float = TEXELS_PER_LOBE):
    """numpy twin of kernels/mips.cl:convolve (all texels, the same level, split and cone cut)."""
    alpha = roughness * roughness
    sizes = [(c.shape[1], c.shape[0]) for c in chain]
    k, sub = convolve_level_choice(sizes, alpha, texels_per_lobe)
    lvl = np.asarray(chain[k], np.float64)
    h, w = lvl.shape[:2]
    src, om = _texel_subsamples(w, h, sub)
    src, om = src.reshape(-1, 3), om.reshape(-1)
    vals = np.repeat(lvl.reshape(-1, lvl.shape[-1]), sub * sub, axis=0)
    cut = lobe_cutoff(alpha)
    flat = np.asarray(dirs, np.float64).reshape(-1, 3)
    out = np.empty((len(flat), vals.shape[-1]))
    for i0 in range(0, len(flat), 128):
        c = flat[i0:i0 + 128] @ src.T
        wgt = np.where(c > cut, brdf.d_ggx(np.sqrt(0.5 * (1 + np.maximum(c, -1))), alpha) * c, 0.0) * om
        out[i0:i0 + 128] = (wgt @ vals) / wgt.sum(1, keepdims=True)
    return out.reshape(np.shape(dirs)[:-1] + (-1,))
