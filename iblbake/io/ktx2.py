"""KTX 2.0 cube maps with their mip levels and 2D textures of one level (lightmap atlases),
uncompressed, written from the KTX 2.0 specification (Khronos, "KTX File Format Specification",
version 2.0) and the Khronos Data Format Specification's basic descriptor block (what libktx's
createDFDUnpacked / createDFDPacked produce for the same formats):

    identifier | header (9 x u32) | index (4 x u32, 2 x u64) | level index (levelCount x 3 x u64,
    level 0 first) | DFD (u32 total size + one basic block) | key/value data (sorted by key, each
    entry padded to 4 bytes) | per level, smallest first: mip padding to lcm(texel size, 4), then
    the faces +X -X +Y -Y +Z -Z, rows top to bottom

No supercompression, so byteLength == uncompressedByteLength. Faces follow the Vulkan/OpenGL
cube-map convention, which is iblbake's (docs/conventions.md "Cube maps") (conventions.dir_from_cube); the
orientation key says "rd" (s to the right, t down), the spec's value for cube maps."""

from __future__ import annotations

import math
import struct

import numpy as np

from iblbake.errors import InputError

IDENTIFIER = b"\xabKTX 20\xbb\r\n\x1a\n"

# VkFormat values (Vulkan's VkFormat enum); typeSize; bytes per texel; channels stored
FORMATS = {
    "rgba16f": {"vk": 97, "name": "R16G16B16A16_SFLOAT", "type_size": 2, "texel": 8},
    "rgba32f": {"vk": 109, "name": "R32G32B32A32_SFLOAT", "type_size": 4, "texel": 16},
    "b10g11r11": {"vk": 122, "name": "B10G11R11_UFLOAT_PACK32", "type_size": 4, "texel": 4},
    "e5b9g9r9": {"vk": 123, "name": "E5B9G9R9_UFLOAT_PACK32", "type_size": 4, "texel": 4},
}
PACKED = ("b10g11r11", "e5b9g9r9")          # one little-endian u32 per texel, RGB only

# Khronos Data Format: RGBSDA model, BT.709 primaries, linear transfer, straight alpha
_MODEL_RGBSDA, _PRIMARIES_BT709, _TRANSFER_LINEAR = 1, 1, 1
_CH_R, _CH_G, _CH_B, _CH_A = 0, 1, 2, 15
_FLOAT, _SIGNED, _EXPONENT = 0x80, 0x40, 0x20    # sample qualifiers in the channelType byte
_F32_ONE, _F32_MINUS_ONE, _F32_ZERO = 0x3F800000, 0xBF800000, 0


def _dfd(fmt: str) -> bytes:
    """The DFD: dfdTotalSize, then one basic descriptor block with a sample per channel."""
    if fmt == "b10g11r11":       # packed little-endian: R bits 0-10, G 11-21, B 22-31, unsigned float
        samples = [(0, 11, _CH_R | _FLOAT, _F32_ZERO, _F32_ONE), (11, 11, _CH_G | _FLOAT, _F32_ZERO, _F32_ONE),
                   (22, 10, _CH_B | _FLOAT, _F32_ZERO, _F32_ONE)]
    elif fmt == "e5b9g9r9":
        # per channel its 9-bit mantissa (bits 0-8, 9-17, 18-26; upper 8448 as libktx's vk2dfd
        # writes it) and the shared 5-bit exponent (bits 27-31, bias 15 as lower, 31 upper): the
        # exact descriptor libktx compares a file's against before it accepts the format
        samples = [s for i, ch in enumerate((_CH_R, _CH_G, _CH_B))
                   for s in ((9 * i, 9, ch, 0, 8448), (27, 5, ch | _EXPONENT, 15, 31))]
    else:
        bits = 8 * FORMATS[fmt]["type_size"]
        samples = [(i * bits, bits, ch | _FLOAT | _SIGNED, _F32_MINUS_ONE, _F32_ONE)
                   for i, ch in enumerate((_CH_R, _CH_G, _CH_B, _CH_A))]
    block_size = 24 + 16 * len(samples)
    block = struct.pack("<IIIIII",
                        0,                                   # vendorId 0 (Khronos), descriptorType 0 (basic)
                        2 | (block_size << 16),              # versionNumber 2, descriptorBlockSize
                        _MODEL_RGBSDA | (_PRIMARIES_BT709 << 8) | (_TRANSFER_LINEAR << 16),   # flags 0
                        0,                                   # texelBlockDimension0..3: 1x1x1x1
                        FORMATS[fmt]["texel"], 0)            # bytesPlane0, bytesPlane1..7 = 0
    for offset, length, channel, lower, upper in samples:
        block += struct.pack("<IIII", offset | ((length - 1) << 16) | (channel << 24), 0, lower, upper)
    return struct.pack("<I", 4 + len(block)) + block


def _key_values(pairs: dict) -> bytes:
    out = b""
    for k in sorted(pairs, key=lambda s: s.encode("utf-8")):      # sorted by key, as bytes
        kv = k.encode("utf-8") + b"\0" + pairs[k].encode("utf-8") + b"\0"
        out += struct.pack("<I", len(kv)) + kv + b"\0" * (-len(kv) % 4)
    return out


def encode_ufloat(v: np.ndarray, mantissa_bits: int) -> np.ndarray:
    """float32 -> unsigned float of 5 exponent bits (bias 15) and `mantissa_bits`, rounded to
    nearest even (Vulkan's conversion rules for B10G11R11): negatives and -0 to 0, values
    above the largest finite to it, NaN to NaN, +Inf to Inf."""
    v = np.asarray(v, np.float32)
    bits = v.view(np.uint32).astype(np.int64)
    shift = 23 - mantissa_bits
    # normal range: re-bias the exponent (127 -> 15) and round the mantissa in one integer step
    # (float bit patterns are monotonic, so a carry out of the mantissa lifts the exponent)
    rebased = bits - ((127 - 15) << 23)
    normal = (rebased + (1 << (shift - 1)) - 1 + ((rebased >> shift) & 1)) >> shift
    # subnormals: value = m / 2^mantissa_bits * 2^-14
    small = np.where((v > 0) & (v < 2.0 ** -14), v, 0).astype(np.float64)
    sub = np.rint(small * 2.0 ** (14 + mantissa_bits)).astype(np.int64)
    max_finite = (30 << mantissa_bits) | ((1 << mantissa_bits) - 1)
    out = np.where(v < 2.0 ** -14, sub, np.minimum(normal, max_finite))
    out = np.where(np.isposinf(v), 31 << mantissa_bits, out)
    out = np.where(np.isnan(v), (31 << mantissa_bits) | 1, out)
    out = np.where(~(v > 0) & ~np.isnan(v), 0, out)
    return out.astype(np.uint32)


def decode_ufloat(x: np.ndarray, mantissa_bits: int) -> np.ndarray:
    x = np.asarray(x, np.uint32).astype(np.int64)
    e, m = x >> mantissa_bits, x & ((1 << mantissa_bits) - 1)
    scale = float(1 << mantissa_bits)
    out = np.where(e == 0, m / scale * 2.0 ** -14, (1 + m / scale) * 2.0 ** (e.astype(np.float64) - 15))
    out = np.where(e == 31, np.where(m == 0, np.inf, np.nan), out)
    return out.astype(np.float32)


def pack_b10g11r11(rgb: np.ndarray) -> np.ndarray:
    r, g, b = (encode_ufloat(rgb[..., i], n) for i, n in enumerate((6, 6, 5)))
    return r | (g << 11) | (b << 22)


def unpack_b10g11r11(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, np.uint32)
    return np.stack([decode_ufloat(x & 0x7FF, 6), decode_ufloat((x >> 11) & 0x7FF, 6),
                     decode_ufloat(x >> 22, 5)], axis=-1)


# EXT_texture_shared_exponent's RGB9_E5 (Vulkan's E5B9G9R9): three 9-bit mantissas without an
# implicit one and a 5-bit exponent of bias 15 that they share
_E5_N, _E5_B = 9, 15
E5_MAX = (2 ** _E5_N - 1) / 2 ** _E5_N * 2.0 ** (31 - _E5_B)      # 65408


def pack_e5b9g9r9(rgb: np.ndarray) -> np.ndarray:
    """The extension's encoding: channels clamped to [0, E5_MAX] (NaN to 0), the shared exponent
    from the largest channel's (floor(log2) read from its float32 exponent bits, which is exact),
    raised by one where that channel's mantissa rounds up to 2^9, each mantissa rounded half up
    at that exponent (in float64, where x 2^k + 0.5 is exact). Channel by channel: numpy's
    reductions and broadcasts over a last axis of 3 cost 10x the arithmetic."""
    rgb = np.asarray(rgb, np.float32)
    c = [np.minimum(np.where(rgb[..., i] > 0, rgb[..., i], np.float32(0)), np.float32(E5_MAX)) for i in range(3)]
    top = np.maximum(np.maximum(c[0], c[1]), c[2])
    e = np.maximum(-_E5_B - 1, (top.view(np.uint32) >> 23).astype(np.int32) - 127) + 1 + _E5_B

    def inverse_scale(e):                     # 2^(B + N - e) as float32 bits: exact, in range
        return ((_E5_B + _E5_N - e + 127).astype(np.uint32) << 23).view(np.float32).astype(np.float64)

    e = e + (np.floor(top * inverse_scale(e) + 0.5) == 2 ** _E5_N)
    inv = inverse_scale(e)
    m = [np.floor(ch * inv + 0.5).astype(np.uint32) for ch in c]
    return m[0] | (m[1] << 9) | (m[2] << 18) | (e.astype(np.uint32) << 27)


def unpack_e5b9g9r9(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, np.uint32)
    scale = np.exp2((x >> 27).astype(np.float64) - _E5_B - _E5_N)
    return np.stack([(x >> (9 * i) & 0x1FF) * scale for i in range(3)], axis=-1).astype(np.float32)


_PACK = {"b10g11r11": pack_b10g11r11, "e5b9g9r9": pack_e5b9g9r9}
_UNPACK = {"b10g11r11": unpack_b10g11r11, "e5b9g9r9": unpack_e5b9g9r9}


def texels(faces: np.ndarray, fmt: str) -> bytes:
    """One level's faces (6, s, s, 3 or 4) as the format's bytes."""
    rgb = np.asarray(faces, np.float32)[..., :3]
    if fmt in PACKED:
        return _PACK[fmt](rgb).astype("<u4").tobytes()
    rgba = np.concatenate([rgb, np.ones(rgb.shape[:-1] + (1,), np.float32)], axis=-1)
    return rgba.astype("<f2" if fmt == "rgba16f" else "<f4").tobytes()


def cube_bytes(levels: list, fmt: str = "rgba16f", metadata: dict | None = None,
               writer: str = "iblbake") -> bytes:
    """A KTX2 cube map of `levels`: level k is (6, s_k, s_k, C) with s_k = max(1, s_0 >> k)."""
    if fmt not in FORMATS:
        raise InputError(f"KTX2 format {fmt!r}: one of {', '.join(FORMATS)}")
    s0 = levels[0].shape[1]
    for k, lv in enumerate(levels):
        if lv.shape[:3] != (6, max(1, s0 >> k), max(1, s0 >> k)):
            raise InputError(f"KTX2 level {k}: faces of {lv.shape[1:3]}, expected 6 of {max(1, s0 >> k)} "
                             f"(a mip chain halves its size at each level)")
    return _container([texels(lv, fmt) for lv in levels], s0, s0, 6, fmt, metadata, writer)


def image_bytes(image, fmt: str = "rgba16f", metadata: dict | None = None, writer: str = "iblbake") -> bytes:
    """A KTX2 2D texture of one level, image (h, w, 3 or 4) with its first row at the top ("rd");
    RGBA formats keep a fourth channel where the image has one (else alpha 1)."""
    if fmt not in FORMATS:
        raise InputError(f"KTX2 format {fmt!r}: one of {', '.join(FORMATS)}")
    a = np.asarray(image, np.float32)
    h, w = a.shape[:2]
    if fmt in PACKED or a.shape[2] == 3:
        data = texels(a[None], fmt)
    else:
        data = a[..., :4].astype("<f2" if fmt == "rgba16f" else "<f4").tobytes()
    return _container([data], w, h, 1, fmt, metadata, writer)


def _container(data: list, width: int, height: int, faces: int, fmt: str, metadata, writer: str) -> bytes:
    """The file around levels' bytes `data` (level 0 first, each level's faces in order)."""
    f = FORMATS[fmt]
    n = len(data)
    dfd = _dfd(fmt)
    kvd = _key_values({"KTXorientation": "rd", "KTXwriter": writer, **(metadata or {})})
    head = 12 + 9 * 4 + 4 * 4 + 2 * 8
    dfd_offset = head + n * 24
    kvd_offset = dfd_offset + len(dfd)
    end = kvd_offset + len(kvd)
    align = math.lcm(f["texel"], 4)
    offsets = [0] * n
    body = b""
    for k in reversed(range(n)):                       # smallest level first in the file
        pad = -(end + len(body)) % align
        body += b"\0" * pad
        offsets[k] = end + len(body)
        body += data[k]
    header = IDENTIFIER + struct.pack("<9I", f["vk"], f["type_size"], width, height, 0, 0, faces, n, 0)
    index = struct.pack("<4I2Q", dfd_offset, len(dfd), kvd_offset, len(kvd), 0, 0)
    level_index = b"".join(struct.pack("<3Q", offsets[k], len(data[k]), len(data[k])) for k in range(n))
    return header + index + level_index + dfd + kvd + body


def read_cube(path, limit: int, hint: str = " (--max-pixels or IBLBAKE_MAX_PIXELS raises it)") -> np.ndarray:
    """Level 0 of a KTX2 cube map in one of FORMATS (what iblbake and most HDR bakers write),
    float32 (6, s, s, 3), faces +X -X +Y -Y +Z -Z, from a regular file of at most `limit` bytes
    (`hint` says how to raise it). Every header field, the level index and the data's bounds are
    checked first; anything else is a one-line error naming the file."""
    from iblbake.io import reads
    path = str(path)
    return parse_cube(reads.read_bytes(path, limit, "a KTX2 cube map", hint), path)


def parse_cube(data: bytes, path: str) -> np.ndarray:
    """read_cube's parse of a file's bytes (what tests/fuzz_readers.py fuzzes), errors naming path."""
    def bad(what):
        return InputError(f"{path}: not a KTX2 cube map iblbake reads: {what}")

    if len(data) < 80 or data[:12] != IDENTIFIER:
        raise bad("no KTX 2.0 identifier" if len(data) >= 12 else "truncated header")
    vk, type_size, w, h, depth, layers, faces, levels, scheme = struct.unpack_from("<9I", data, 12)
    fmt = next((k for k, v in FORMATS.items() if v["vk"] == vk), None)
    if fmt is None:
        raise bad(f"VkFormat {vk} (iblbake reads {', '.join(v['name'] for v in FORMATS.values())})")
    if scheme != 0:
        raise bad(f"supercompression scheme {scheme} (only uncompressed data)")
    if faces != 6:
        raise bad(f"{faces} faces (a cube map has 6)")
    if w != h or w < 1 or depth > 1 or layers > 1:
        raise bad(f"{w}x{h}, depth {depth}, {layers} layers (a cube map's faces are square, one layer)")
    if levels < 1 or 80 + 24 * levels > len(data):
        raise bad(f"level index of {levels} levels runs past the file's {len(data)} bytes")
    offset, length, _ = struct.unpack_from("<3Q", data, 80)
    need = 6 * w * w * FORMATS[fmt]["texel"]
    if length != need:
        raise bad(f"level 0 holds {length} bytes, 6 faces of {w}x{w} {FORMATS[fmt]['name']} need {need}")
    if offset + length > len(data):
        raise bad(f"level 0 ({offset} + {length} bytes) runs past the file's end ({len(data)} bytes; truncated?)")
    if fmt in PACKED:
        return _UNPACK[fmt](np.frombuffer(data, "<u4", need // 4, offset).reshape(6, w, w))
    raw = np.frombuffer(data, dtype={"rgba16f": "<f2", "rgba32f": "<f4"}[fmt], count=need // FORMATS[fmt]["type_size"],
                        offset=offset)
    return raw.reshape(6, w, w, 4)[..., :3].astype(np.float32)
