"""Sample sets and warps, each warp a pair sample_x / pdf_x (pbrt-v4's habit), float64, and the
random numbers: the Sampler of kernels/sampler.h (pairs of Owen-scrambled Sobol points) and the
environment's importance sampling. Mirrors kernels/sampling.h, kernels/sampler.h and
kernels/envmap.h; tests/test_sampling.py checks every warp on both sides with a chi-square test
against its own pdf (as Mitsuba 3's ChiSquareTest)."""

from __future__ import annotations

import numpy as np

from iblbake.core import brdf
from iblbake.core import conventions
from iblbake.core.metrics import LUMINANCE


M32 = 0xFFFFFFFF


def reverse_bits32(x):
    """kernels/sampler.h reverse_bits32: the 32 bits of x in reverse order."""
    x = np.asarray(x, np.uint64) & M32
    x = ((x << 16) | (x >> 16)) & M32
    x = ((x & 0x00FF00FF) << 8) | ((x & 0xFF00FF00) >> 8)
    x = ((x & 0x0F0F0F0F) << 4) | ((x & 0xF0F0F0F0) >> 4)
    x = ((x & 0x33333333) << 2) | ((x & 0xCCCCCCCC) >> 2)
    return ((x & 0x55555555) << 1) | ((x & 0xAAAAAAAA) >> 1)


def radical_inverse_vdc(i):
    """Van der Corput radical inverse in base 2 of 32-bit integers: bits mirrored about the point."""
    return reverse_bits32(i).astype(np.float64) * (1.0 / 4294967296.0)


def hammersley(n: int):
    """The N-point Hammersley set (i/N, radical_inverse_vdc(i)), shape (N, 2)."""
    i = np.arange(n)
    return np.stack([i / n, radical_inverse_vdc(i)], axis=-1)


def sample_ggx_half(u, alpha):
    """GGX half-vector in the local frame (z = normal) from u in [0,1)^2.

    phi = 2 pi u0, theta = atan2(alpha sqrt(u1), sqrt(1 - u1)) (finite at u1 -> 1);
    pdf over half-vectors = D(h) cos(theta_h)  (pdf_ggx_half).
    """
    u = np.asarray(u, dtype=np.float64)
    phi = 2.0 * np.pi * u[..., 0]
    theta = np.arctan2(np.asarray(alpha) * np.sqrt(u[..., 1]), np.sqrt(np.maximum(0.0, 1.0 - u[..., 1])))
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def reflect_ggx_half(u, t, b, n, v, alpha):
    """One GGX half vector a point (sample_ggx_half of u (2,), in the frame t, b, n) and the view v
    reflected about it: (noh, voh, l, nol), noh floored at 1e-7 (a weight divides by it). The
    importance twin draws its lobe this way."""
    hl = sample_ggx_half(np.broadcast_to(u, (len(n), 2)), alpha)
    return (np.maximum(hl[:, 2], 1e-7), *_reflected(hl, t, b, n, v))


def reflect_ggx_vndf(u, t, b, n, v, nov, alpha):
    """One GGX visible normal a point (sample_ggx_vndf of u, (2,) or (points, 2), seen from v in the
    frame t, b, n, its z the caller's NoV: floored as the kernel's) and the view v reflected about
    it: (its NoH unfloored, voh, l, nol). The lobe mode's twin and the reflection probes' taps draw
    their lobes this way."""
    vl = np.stack([(v * t).sum(1), (v * b).sum(1), nov], -1)
    hl = sample_ggx_vndf(vl, alpha, np.broadcast_to(u, (len(n), 2)))
    return (hl[:, 2], *_reflected(hl, t, b, n, v))


def _reflected(hl, t, b, n, v):
    """(voh, l, nol) of the view v reflected about the local half vectors hl (frame t, b, n)."""
    h = t * hl[:, 0:1] + b * hl[:, 1:2] + n * hl[:, 2:3]
    voh = (v * h).sum(1)
    l = 2 * voh[:, None] * h - v
    return voh, l, (n * l).sum(1)


def pdf_ggx_half(noh, alpha):
    return brdf.d_ggx(noh, alpha) * np.clip(noh, 0.0, 1.0)


def pdf_ggx_reflected(noh, voh, alpha):
    """pdf of l = reflect(-v, h) when h ~ pdf_ggx_half: D(h) NoH / (4 VoH) (Jacobian 1/(4 VoH))."""
    return pdf_ggx_half(noh, alpha) / np.maximum(4.0 * voh, 1e-30)


def to_world(local, n):
    """Local (x, y, z = n) vectors to world, with the Duff et al. 2017 frame (docs/conventions.md)."""
    t, b = conventions.tangent_frame(n)
    return local[..., 0:1] * t + local[..., 1:2] * b + local[..., 2:3] * np.asarray(n)


# --- random and quasi-random numbers -----------------------------------------------------------

def pcg_hash(x):
    """PCG hash of 32-bit integers (Jarzynski and Olano 2020): one PCG state step and its output
    permutation; kernels/sampler.h pcg_hash."""
    s = (np.asarray(x, np.uint64) * 747796405 + 2891336453) & 0xFFFFFFFF
    word = (((s >> ((s >> 28) + 4)) ^ s) * 277803737) & 0xFFFFFFFF
    return ((word >> 22) ^ word).astype(np.uint32)


# bins of a guide table (the marginal's and each panorama row's), a power of two (cdf_guides; kernels/layout.h)
ENV_GUIDE_BINS = 256


# Every sample's dimensions (kernels/sampler.h): pairs of Owen-scrambled Sobol points
def laine_karras_permutation(x, seed):
    x = (np.asarray(x, np.uint64) + np.asarray(seed, np.uint64)) & M32
    for m in (0x6c50b47c, 0xb82f1e52, 0xc7afe638, 0x8d22f6e6):
        x ^= (x * m) & M32
    return x


def nested_uniform_scramble(x, seed):
    return reverse_bits32(laine_karras_permutation(reverse_bits32(x), seed))


def sobol_dim1(i):
    """Sobol's second dimension (kernels/sampler.h sobol_dim1)."""
    i = np.asarray(i, np.uint64).copy()
    r, v = np.zeros_like(i), np.full_like(i, 0x80000000)
    for _ in range(32):
        r ^= np.where(i & 1, v, 0)
        i >>= 1
        v ^= v >> 1
    return r


def owen_sobol(j, seed, p: int, c: int):
    """kernels/sampler.h owen_sobol: coordinate c of pair p of sample j of stream seed (Burley
    2020, "Practical Hash-based Owen Scrambling")."""
    u32 = lambda a: np.asarray(a, np.uint64).astype(np.uint32)                 # noqa: E731
    s = pcg_hash(u32(seed) ^ pcg_hash(np.uint32(p + 0x51ED27)))
    i = nested_uniform_scramble(j, s)
    x = reverse_bits32(i) if c == 0 else sobol_dim1(i)
    y = nested_uniform_scramble(x, pcg_hash(u32((s.astype(np.uint64) + c + 1) & M32)))
    return (y >> 8).astype(np.float64) * (1.0 / 16777216.0)


def sampler_1d(seed, gid, k, d: int):
    """kernels/sampler.h sampler_1d: dimension d of sample k of G-buffer sample (or stream) gid:
    coordinate d & 1 of pair d >> 1 of Owen-scrambled Sobol points, one sequence per (seed, gid)."""
    stream = pcg_hash(np.uint32(seed) ^ pcg_hash(np.asarray(gid, np.uint64).astype(np.uint32)))
    return owen_sobol(k, stream, d >> 1, d & 1)


def reference_replicates(target_noise: float) -> int:
    """Independent sequences the reference's samples of a G-buffer sample form (kernels/sampler.h
    sampler_replicate): two where the frame stops at a noise target (their means' difference is
    its error estimate: render/passes/reference.py), else one, which errs less at equal samples."""
    return 2 if target_noise > 0 else 1


class Sampler:
    """kernels/sampler.h's Sampler: the dimensions of sample number k of every G-buffer sample (or
    stream) gid, handed out in the order a kernel asks for them (next_1d, next_2d as the kernel's
    sampler_1d, sampler_2d); gid an array, k and seed one value or arrays of gid's shape."""

    def __init__(self, seed, gid, k):
        self.seed, self.gid, self.k, self.dim = seed, gid, k, 0

    @classmethod
    def replicate(cls, seed, gid, k, replicates: int):
        """kernels/sampler.h sampler_replicate: with 2 replicates, even and odd k are samples k // 2
        of two independent sequences."""
        if replicates < 2:
            return cls(seed, gid, k)
        k = np.asarray(k, np.uint64)
        seed = np.uint32(seed) ^ pcg_hash(((0x2545F491 + (k & 1)) & M32).astype(np.uint32))
        return cls(seed, gid, k >> 1)

    def next_1d(self):
        self.dim += 1
        return sampler_1d(self.seed, self.gid, self.k, self.dim - 1)

    def next_2d(self):
        a = self.next_1d()
        return np.stack([a, self.next_1d()], -1)


# --- warps: local frame z = normal ------------------------------------------------------------------

def sample_cosine_hemisphere(u):
    """Malley's method: a uniform disk point lifted to the hemisphere; pdf = cos(theta) / pi."""
    u = np.asarray(u, np.float64)
    r, phi = np.sqrt(u[..., 0]), 2 * np.pi * u[..., 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1 - u[..., 0]))], -1)


def pdf_cosine_hemisphere(cos_theta):
    return np.maximum(cos_theta, 0.0) / np.pi


def sample_uniform_cone(u, cos_max):
    """Uniform in the cone cos(theta) >= cos_max: cos(theta) = 1 - u0 (1 - cos_max)."""
    u = np.asarray(u, np.float64)
    ct = 1 - u[..., 0] * (1 - cos_max)
    st, phi = np.sqrt(np.maximum(0.0, 1 - ct * ct)), 2 * np.pi * u[..., 1]
    return np.stack([st * np.cos(phi), st * np.sin(phi), ct], -1)


def pdf_uniform_cone(cos_max):
    return 1.0 / (2 * np.pi * (1 - cos_max))


def g1_smith(nov, alpha):
    a2 = np.asarray(alpha) ** 2
    return 2 * nov / (nov + np.sqrt(a2 + (1 - a2) * nov * nov))


def sample_ggx_vndf(vl, alpha, u):
    """GGX visible normals (Heitz 2018): stretch the view vector, sample the projected hemisphere,
    unstretch. pdf over half-vectors G1(v) max(0, v.h) D(h) / NoV."""
    vl, u = np.asarray(vl, np.float64), np.asarray(u, np.float64)
    vh = np.stack([alpha * vl[..., 0], alpha * vl[..., 1], vl[..., 2]], -1)
    vh /= np.linalg.norm(vh, axis=-1, keepdims=True)
    lensq = vh[..., 0] ** 2 + vh[..., 1] ** 2
    inv = np.where(lensq > 0, 1 / np.sqrt(np.maximum(lensq, 1e-300)), 0.0)
    t1 = np.where((lensq > 0)[..., None], np.stack([-vh[..., 1] * inv, vh[..., 0] * inv, 0 * inv], -1),
                  np.array([1.0, 0.0, 0.0]))
    t2 = np.cross(vh, t1)
    r, phi = np.sqrt(u[..., 0]), 2 * np.pi * u[..., 1]
    p1, p2 = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1 + vh[..., 2])
    p2 = (1 - s) * np.sqrt(np.maximum(0.0, 1 - p1 * p1)) + s * p2
    nh = p1[..., None] * t1 + p2[..., None] * t2 + np.sqrt(np.maximum(0.0, 1 - p1 * p1 - p2 * p2))[..., None] * vh
    h = np.stack([alpha * nh[..., 0], alpha * nh[..., 1], np.maximum(1e-7, nh[..., 2])], -1)
    return h / np.linalg.norm(h, axis=-1, keepdims=True)


def lobe_points(k: int):
    """The lobe mode's K points in [0, 1)^2: strata centres in u1, the radical inverse turned
    half a turn in u2, so that K = 1 takes the lobe's median ring (not its edge, as
    Hammersley's first point would) and small K spread around it."""
    i = np.arange(k)
    return np.stack([(i + 0.5) / k, (radical_inverse_vdc(i) + 0.5) % 1.0], -1)


def pdf_ggx_vndf(nov, noh, voh, alpha):
    """pdf of sample_ggx_vndf over half-vectors."""
    return g1_smith(nov, alpha) * np.maximum(voh, 0.0) * brdf.d_ggx(noh, alpha) / nov


# --- the environment -----------------------------------------------------------------------------

class EnvironmentDistribution:
    """Piecewise constant over a panorama's texels, p(texel) proportional to the texel's luminance
    above the panorama's mean, x exact solid angle (MIS compensation: env_sampling_tables); inside a
    texel uniform in (phi, cos theta). Its tables (marginal CDF over rows, one CDF per row, their
    guide tables) are what kernels/envmap.h sample_env reads; the pdf over solid angle per texel is
    the twin's."""

    def __init__(self, image):
        self.marginal, self.conditional, self.pdf, total, self.offset = env_sampling_tables(image)
        self.height, self.width = self.pdf.shape
        # the kernels' pdf: (a texel's luminance - offset, floored at 0) times 1 / total
        # (kernels/envmap.h pdf_env), the pdf table's value without the table (a black panorama's
        # texels give 0: no light to sample)
        self.norm = np.array([1.0 / total, self.offset], np.float32)
        # the rows' guide tables, then the marginal's (kernels/envmap.h sample_env): (H + 1, bins + 1)
        self.guide = np.concatenate([cdf_guides(self.conditional), cdf_guides(self.marginal[None, :])])

    def sample(self, u):
        """Directions in the panorama's frame from u in [0,1)^4 (rows of 4), and their texels."""
        u = np.asarray(u, np.float64)
        h, w = self.height, self.width
        j = np.clip(np.searchsorted(self.marginal, u[:, 0], side="right") - 1, 0, h - 1)
        i = np.zeros(len(u), np.int64)
        for jj in np.unique(j):                   # row by row (a lightmap draws millions at once)
            at = j == jj
            i[at] = np.searchsorted(self.conditional[jj], u[at, 1], side="right") - 1
        i = np.clip(i, 0, w - 1)
        uu = (i + u[:, 2]) / w
        ct = np.cos(np.pi * j / h) + u[:, 3] * (np.cos(np.pi * (j + 1) / h) - np.cos(np.pi * j / h))
        st, phi = np.sqrt(np.maximum(0.0, 1 - ct * ct)), 2 * np.pi * (0.5 - uu)
        return np.stack([st * np.sin(phi), ct, st * np.cos(phi)], -1), j * w + i

    def pdf_of(self, d):
        """pdf over solid angle of directions d (panorama frame): its texel's table entry."""
        u, v = conventions.equirect_uv_from_dir(d)
        i = np.minimum((u * self.width).astype(np.int64), self.width - 1)
        j = np.minimum((v * self.height).astype(np.int64), self.height - 1)
        return self.pdf[j, i].astype(np.float64)


def env_sampling_tables(image):
    """Piecewise-constant environment sampling over texels: p(texel) proportional to max(luminance -
    offset, 0) x exact solid angle, offset the panorama's mean luminance over the sphere ("MIS
    compensation", Karlik et al. 2019, as pbrt-v4's image light samples for its path tracer): every
    path samples the panorama beside a BSDF and weighs the two by MIS, the BSDF's samples cover what
    is about as bright as the mean, and the panorama's go where it stands out. Offset 0 where
    nothing stands out (a constant panorama). Returns (marginal cdf (H+1), conditional cdfs
    (H, W+1), pdf over solid angle per texel (H, W)), float32, built in float64, the total weight
    (the pdf is (luminance - offset) / total) and the offset (float32, as the kernels subtract it)."""
    h, w = image.shape[:2]
    lum = np.maximum(image[..., :3].astype(np.float64) @ LUMINANCE, 0.0)
    omega = conventions.equirect_row_solid_angles(w, h)
    plain = lum * omega[:, None]              # luminance x solid angle, uncompensated
    offset = np.float32(plain.sum() / (omega.sum() * w))
    weight = np.maximum(lum - np.float64(offset), 0.0) * omega[:, None]
    # Nothing (or a rounding's worth) above the mean, a constant panorama: luminance alone. The
    # kernels subtract in float32 (pdf_env), off by ~1e-7 of the luminance, and that error is
    # divided by the compensated total: under 1e-3 of the luminance's total it could outweigh it
    if not weight.sum() >= 1e-3 * plain.sum():
        offset, weight = np.float32(0.0), plain
    total = weight.sum()
    if not total > 0:                     # a black panorama: sample by solid angle
        weight = np.broadcast_to(omega[:, None], (h, w)).copy()
        total = weight.sum()
    row = weight.sum(axis=1)
    marginal = np.concatenate([[0.0], np.cumsum(row)]) / total
    marginal[-1] = 1.0
    cond = np.zeros((h, w + 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.cumsum(weight, axis=1) / row[:, None]
    cond[:, 1:] = np.where(row[:, None] > 0, c, (np.arange(1, w + 1) / w)[None, :])
    cond[:, -1] = 1.0
    pdf = weight / total / omega[:, None]
    return marginal.astype(np.float32), cond.astype(np.float32), pdf.astype(np.float32), total, offset


def cdf_guides(cdfs, bins: int = ENV_GUIDE_BINS):
    """Guide tables of CDFs (Chen and Asau 1974) as kernels/envmap.h sample_env reads them: per
    row (cdfs: (H, W + 1) float32, cdf[0] = 0, cdf[W] = 1), for g = 0 .. bins, the bin of u =
    g / bins (the smallest i with cdf[i + 1] > u, W - 1 where none is), int32 (H, bins + 1). A u
    in [g, g + 1) / bins has its bin between entries g and g + 1; bins is a power of two, so u
    times it is exact in float32 and g is the same on the device."""
    cdfs = np.asarray(cdfs, np.float32)
    w = cdfs.shape[1] - 1
    t = np.arange(bins + 1, dtype=np.float32) / np.float32(bins)
    out = np.stack([np.searchsorted(row[1:], t, side="right") for row in cdfs]) if len(cdfs) else \
        np.zeros((0, bins + 1), np.int64)
    return np.minimum(out, w - 1).astype(np.int32)


def power_heuristic(a, b):
    """MIS weight a^2 / (a^2 + b^2) (Veach 1997); 0 where a is 0, finite for infinite pdfs."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(a > 0, b / a, 0.0)
    return np.where(a > 0, 1 / (1 + r * r), 0.0)
