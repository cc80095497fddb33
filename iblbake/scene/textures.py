"""Material textures: decoded once per scene into linear float mip pyramids, packed into one
buffer of float32 RGBA texels for the device (exact for 8- and 16-bit sources; half floats would
round a decoded colour by up to 2.4e-4), and sampled as kernels/texture.h samples them
(this module's sample() is its float64 numpy twin).

- Colour maps (base colour, emissive) are sRGB-encoded (glTF 2.0, 3.9.2): decoded to linear
  (IEC 61966-2-1) before filtering; the others (metallic-roughness, occlusion, normal) are linear.
- Pyramids: each level max(1, w/2) x max(1, h/2), every texel the area-weighted mean of the texels
  it covers (exact overlaps, so non-power-of-two sizes keep their mean), in linear space. Normal
  maps are decoded to vectors (2c - 1) first, and every level's vectors renormalised.
- Sampling (glTF samplers): wrap repeat, clamp or mirrored repeat per axis; magnification nearest
  or bilinear; minification with the mip level from the footprint (kernels/gbuffer.cl), nearest
  or linear within a level and between levels (trilinear by default).
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field

import numpy as np

from iblbake.errors import InputError
from iblbake.scene.layout import MAP_KINDS

COLOUR_MAPS = ("base_color", "emissive")
WRAPS = {"repeat": 0, "clamp": 1, "mirror": 2}
# minification: (filter within a level, filter between levels); None: no mipmaps (level 0 only)
MIN_FILTERS = {"nearest": (0, None), "linear": (1, None), "nearest_mipmap_nearest": (0, 0),
               "linear_mipmap_nearest": (1, 0), "nearest_mipmap_linear": (0, 1), "linear_mipmap_linear": (1, 1)}
MAG_FILTERS = {"nearest": 0, "linear": 1}
MAX_TEXTURE_PIXELS = 8192 * 8192


# how a scene's texture limit is raised: the environment for the API, the flag on the command line
RAISE_TEXTURE_LIMIT = "IBLBAKE_MAX_TEXTURE_PIXELS or --max-texture-pixels raises it"


def max_texture_pixels() -> int:
    from iblbake.io.images import env_pixels
    return env_pixels("IBLBAKE_MAX_TEXTURE_PIXELS", MAX_TEXTURE_PIXELS)


def decode(data: bytes, name: str, where: str, max_pixels: int | None = None) -> np.ndarray:
    """An image file's bytes (PNG, JPEG; 8 or 16 bits, any size) -> float32 (h, w, 4) code values
    in [0, 1] (grey expands to RGB, a missing alpha is 1). The size is checked from the header,
    before any pixel is decoded."""
    import OpenImageIO as oiio

    limit = max_pixels or max_texture_pixels()
    head = bytes(data[:8])
    suffix = ".png" if head.startswith(b"\x89PNG") else ".jpg" if head.startswith(b"\xff\xd8") else None
    if suffix is None:
        raise InputError(f"{where}: image {name!r} is not a PNG or JPEG file; iblbake reads those textures")
    fd, tmp = tempfile.mkstemp(suffix=suffix)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        inp = oiio.ImageInput.open(tmp)
        if inp is None:
            raise InputError(f"{where}: image {name!r} cannot be decoded ({' '.join(oiio.geterror().split())[:120]})")
        try:
            spec = inp.spec()
            w, h, c = spec.width, spec.height, spec.nchannels
            if w < 1 or h < 1 or c < 1:
                raise InputError(f"{where}: image {name!r} is {w}x{h} with {c} channels")
            if w * h > limit:
                raise InputError(f"{where}: image {name!r} is {w}x{h}, more than the texture limit of {limit} "
                                 f"pixels ({RAISE_TEXTURE_LIMIT}); or use a smaller texture")
            px = inp.read_image(0, 0, 0, c, oiio.FLOAT)
        finally:
            inp.close()
    finally:
        os.unlink(tmp)
    if not isinstance(px, np.ndarray) or px.size != w * h * c:
        raise InputError(f"{where}: image {name!r} is truncated or corrupt ({' '.join(oiio.geterror().split())[:120]})")
    px = np.asarray(px, np.float32).reshape(h, w, c)
    out = np.ones((h, w, 4), np.float32)
    if c >= 3:
        out[..., :3] = px[..., :3]
        if c >= 4:
            out[..., 3] = px[..., 3]
    else:
        out[..., :3] = px[..., :1]
        if c == 2:
            out[..., 3] = px[..., 1]
    return np.clip(np.nan_to_num(out, nan=0.0), 0.0, 1.0)


def to_linear(codes: np.ndarray, kind: str) -> np.ndarray:
    """Code values -> what is filtered: linear colour for colour maps, unit vectors for normal
    maps (2c - 1, renormalised), the values as stored for the rest."""
    from iblbake.io.color import srgb_decode

    out = np.array(codes, np.float32)
    if kind in COLOUR_MAPS:
        out[..., :3] = srgb_decode(out[..., :3])
    elif kind == "normal":
        out[..., :3] = _unit(2.0 * out[..., :3] - 1.0)
    return out


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    flat = np.zeros_like(v)
    flat[..., 2] = 1.0
    return np.where(n > 1e-12, v / np.maximum(n, 1e-30), flat)


def _taps(n: int, m: int):
    """Indices (m, 3) and weights (m, 3) of the source texels each of m output texels covers when
    n texels shrink to m (n / m <= 3): exact overlaps of [i n/m, (i+1) n/m] with each [j, j+1]."""
    a = np.arange(m) * n / m
    first = np.floor(a).astype(np.int64)
    idx = np.minimum(first[:, None] + np.arange(3)[None, :], n - 1)
    lo = np.maximum(a[:, None], first[:, None] + np.arange(3)[None, :])
    hi = np.minimum(a[:, None] + n / m, first[:, None] + np.arange(3)[None, :] + 1)
    w = np.maximum(hi - lo, 0.0) * (m / n)
    return idx, w


def downsample(img: np.ndarray) -> np.ndarray:
    """One pyramid step: (h, w, c) -> (max(1, h//2), max(1, w//2), c), area-weighted."""
    h, w = img.shape[:2]
    ih, wh = _taps(h, max(1, h // 2))
    iw, ww = _taps(w, max(1, w // 2))
    rows = (img[ih] * wh[:, :, None, None]).sum(axis=1)
    return (rows[:, iw] * ww[None, :, :, None]).sum(axis=2).astype(np.float32)


def pyramid(level0: np.ndarray, kind: str) -> list:
    """Every mip level down to 1 x 1 (linear values as to_linear gives them)."""
    levels = [np.asarray(level0, np.float32)]
    while levels[-1].shape[0] > 1 or levels[-1].shape[1] > 1:
        nxt = downsample(levels[-1])
        if kind == "normal":
            nxt[..., :3] = _unit(nxt[..., :3])
        levels.append(nxt)
    return levels


@dataclass
class Texture:
    name: str                  # for messages: the image URI or path
    kind: str                  # one of MAP_KINDS (how it is decoded)
    levels: list               # float32 (h, w, 4) per mip level
    wrap: tuple = ("repeat", "repeat")
    mag: str = "linear"
    min: str = "linear_mipmap_linear"


@dataclass
class TextureSet:
    """Every texture of a scene as the device reads it: texels (N, 4) float32 of every level of
    every texture, tex_levels (L, 4) int32 (first texel, width, height, 0) and tex_info (T, 4)
    int32 (first level, level count, wrap s | wrap t << 4 | mag << 8 | within << 12 | between << 16,
    between = 3 for no mipmaps)."""
    textures: list = field(default_factory=list)
    upload_s: float = 0.0

    def arrays(self):
        levels, info, texels, off = [], [], [], 0
        for t in self.textures:
            within, between = MIN_FILTERS[t.min]
            info.append([len(levels), len(t.levels), WRAPS[t.wrap[0]] | WRAPS[t.wrap[1]] << 4 |
                         MAG_FILTERS[t.mag] << 8 | within << 12 | (3 if between is None else between) << 16, 0])
            for lv in t.levels:
                h, w = lv.shape[:2]
                levels.append([off, w, h, 0])
                texels.append(lv.reshape(-1, 4))
                off += w * h
        if not texels:
            return np.zeros((1, 4), np.float32), np.zeros((1, 4), np.int32), np.zeros((1, 4), np.int32)
        return (np.concatenate(texels).astype(np.float32), np.asarray(levels, np.int32),
                np.asarray(info, np.int32))

    def texel_count(self) -> int:
        return sum(lv.shape[0] * lv.shape[1] for t in self.textures for lv in t.levels)


def sizes(tex_levels, tex_info) -> dict:
    """Texture index -> (width, height, sampler bits) of level 0, from the device arrays (what
    materials.device_arrays needs to place each map's footprint)."""
    return {t: (int(tex_levels[first, 1]), int(tex_levels[first, 2]), int(bits))
            for t, (first, _n, bits, _) in enumerate(tex_info)}


# --- sampling: the numpy twin of kernels/texture.h ----------------------------------------------

def _wrap(i, n, mode: str):
    if mode == "clamp":
        return np.clip(i, 0, n - 1)
    if mode == "mirror":
        k = np.mod(i, 2 * n)
        return np.where(k < n, k, 2 * n - 1 - k)
    return np.mod(i, n)


def _fetch(lv, x, y, tex: Texture):
    h, w = lv.shape[:2]
    return lv[_wrap(y, h, tex.wrap[1]), _wrap(x, w, tex.wrap[0])].astype(np.float64)


def sample_level(tex: Texture, k, uv, linear) -> np.ndarray:
    """Level k (per sample) at uv, nearest or bilinear (texel centres at (i + 0.5) / w)."""
    uv = np.asarray(uv, np.float64)
    out = np.zeros((len(uv), 4))
    for lvl in np.unique(k):
        sel = k == lvl
        lv = tex.levels[int(lvl)]
        h, w = lv.shape[:2]
        x, y = uv[sel, 0] * w, uv[sel, 1] * h
        if linear:
            x0, y0 = np.floor(x - 0.5), np.floor(y - 0.5)
            fx, fy = (x - 0.5 - x0)[:, None], (y - 0.5 - y0)[:, None]
            x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
            a = _fetch(lv, x0, y0, tex) * (1 - fx) + _fetch(lv, x0 + 1, y0, tex) * fx
            b = _fetch(lv, x0, y0 + 1, tex) * (1 - fx) + _fetch(lv, x0 + 1, y0 + 1, tex) * fx
            out[sel] = a * (1 - fy) + b * fy
        else:
            out[sel] = _fetch(lv, np.floor(x).astype(np.int64), np.floor(y).astype(np.int64), tex)
    return out


def wrap_coordinate(u, mode: str):
    """One period of the coordinate (kernels/texture.h): repeat 1, mirror 2; clamp to [-1, 2]."""
    if mode == "clamp":
        return np.clip(u, -1.0, 2.0)
    p = 2.0 if mode == "mirror" else 1.0
    return u - p * np.floor(u / p)


def sample(tex: Texture, uv, lod) -> np.ndarray:
    """The texture at uv (n, 2) for mip level lod (n,) (log2 of the footprint in level-0 texels):
    the magnification filter where lod <= 0, else the minification filter."""
    lod = np.nan_to_num(np.asarray(lod, np.float64), nan=0.0, posinf=1e30, neginf=-1e30)
    uv = np.asarray(uv, np.float64)
    uv = np.stack([wrap_coordinate(uv[:, 0], tex.wrap[0]), wrap_coordinate(uv[:, 1], tex.wrap[1])], 1)
    top = len(tex.levels) - 1
    within, between = MIN_FILTERS[tex.min]
    mag = lod <= 0.0
    out = np.zeros((len(lod), 4))
    if mag.any():
        out[mag] = sample_level(tex, np.zeros(mag.sum(), np.int64), np.asarray(uv)[mag], MAG_FILTERS[tex.mag] == 1)
    m = ~mag
    if m.any():
        uvm, lm = np.asarray(uv)[m], np.clip(lod[m], 0.0, top)
        if between is None:
            out[m] = sample_level(tex, np.zeros(m.sum(), np.int64), uvm, within == 1)
        elif between == 0:
            out[m] = sample_level(tex, np.floor(lm + 0.5).astype(np.int64).clip(0, top), uvm, within == 1)
        else:
            k0 = np.floor(lm).astype(np.int64).clip(0, top)
            k1 = np.minimum(k0 + 1, top)
            f = (lm - k0)[:, None]
            out[m] = sample_level(tex, k0, uvm, within == 1) * (1 - f) + sample_level(tex, k1, uvm, within == 1) * f
    return out


def footprint_lod(cone_width, cos_incidence, uv_per_area, width: int, height: int, det: float = 1.0):
    """The mip level of a surface footprint (the cone method, Akenine-Moller et al. 2019,
    "Texture Level of Detail Strategies for Real-Time Ray Tracing", Ray Tracing Gems ch. 20):
    log2 of the footprint's width in texels, lambda = log2(W / |n.d|) + 0.5 log2(a w h |det M|),
    with W the ray cone's width at the hit, a the UV area per world area at the hit and M the
    KHR_texture_transform's 2 x 2 part."""
    with np.errstate(divide="ignore"):
        return (np.log2(np.asarray(cone_width) / np.maximum(np.abs(cos_incidence), 1e-6))
                + 0.5 * np.log2(np.asarray(uv_per_area) * width * height * abs(det)))

