"""glTF 2.0 files: one EXT_lights_image_based light (below), and Binary, the buffer of meshes'
accessors a lightmap's glTF is built with (render/lightmaps/gltf_scene.py). The light (the extension's README in the Khronos
glTF repository: extensions/2.0/Vendor/EXT_lights_image_based): its irradianceCoefficients,
and its specularImages, N mips x 6 faces (+X -X +Y -Y +Z -Z) of square power-of-two PNGs, each
mip half the size of the one above, in RGBD.

RGBD, as Babylon.js (the extension's reference loader) packs and unpacks it (its
helperFunctions toRGBD / fromRGBD, rgbdMaxRange 255):

    D   = clamp(floor(max(255 / max(r, g, b), 1)) / 255, 0, 1)      stored in alpha
    rgb = clamp((colour D)^(1/2.2), 0, 1)                            the gamma helps 8-bit steps
    colour = rgb^2.2 / D                                             (decoding)

so a texel holds up to 255 and keeps about 1/255 of its largest channel; brighter texels clip.

`.gltf` writes the PNGs beside it (STEM_specular_LEVEL_FACE.png, FACE in px nx py ny pz nz) and
the JSON last; `.glb` holds everything in one binary buffer (glTF's GLB container: 12-byte
header, a JSON chunk padded with spaces, a BIN chunk padded with zeros, both to 4 bytes).
Every file is written atomically. The PNGs hold no colour chunk (sRGB, gAMA): RGBD bytes are not
colours, and OpenImageIO's PNG writer declares sRGB, so pillow writes them.
"""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path
from urllib.parse import quote

import numpy as np

from iblbake.errors import IblbakeError

EXTENSION = "EXT_lights_image_based"
GLB_MAGIC, JSON_CHUNK, BIN_CHUNK = 0x46546C67, 0x4E4F534A, 0x004E4942     # "glTF", "JSON", "BIN\0"
FACES = ("px", "nx", "py", "ny", "pz", "nz")
RGBD_MAX = 255.0          # Babylon's rgbdMaxRange: the largest value a texel holds
GAMMA = 2.2               # Babylon's LinearEncodePowerApprox


def rgbd_encode(colour) -> np.ndarray:
    """Linear RGB (..., 3), >= 0 -> RGBD bytes (..., 4), exactly as Babylon's toRGBD then an
    8-bit store (round to nearest). Negative and non-finite values store 0."""
    c = np.nan_to_num(np.asarray(colour, np.float64), nan=0.0, posinf=RGBD_MAX, neginf=0.0)
    c = np.maximum(c, 0.0)
    m = np.maximum(c.max(axis=-1), 1e-6)               # Babylon's maxEps
    d = np.clip(np.floor(np.maximum(RGBD_MAX / m, 1.0)) / 255.0, 0.0, 1.0)
    rgb = np.clip(c * d[..., None], 0.0, 1.0) ** (1.0 / GAMMA)
    return np.rint(np.concatenate([rgb, d[..., None]], axis=-1) * 255.0).astype(np.uint8)


def rgbd_decode(rgbd) -> np.ndarray:
    """RGBD bytes (..., 4) -> linear RGB (..., 3): Babylon's fromRGBD."""
    b = np.asarray(rgbd, np.float64) / 255.0
    return (b[..., :3] ** GAMMA) / np.maximum(b[..., 3:4], 1.0 / 255.0)


def png_bytes(rgba: np.ndarray) -> bytes:
    """An 8-bit RGBA PNG with no colour-space chunk."""
    from iblbake.io.images import png_bytes
    return png_bytes(np.ascontiguousarray(rgba, np.uint8), colour=False)


def split_glb(data: bytes) -> tuple:
    """(JSON chunk, BIN chunk or None) of a GLB container (data starting with "glTF"); ValueError
    saying what is wrong with it."""
    if len(data) < 20:
        raise ValueError("a GLB shorter than its header")
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2 or length > len(data):
        raise ValueError(f"GLB version {version}, length {length} of {len(data)} bytes")
    n, kind = struct.unpack_from("<II", data, 12)
    if kind != JSON_CHUNK or 20 + n > length:
        raise ValueError("GLB without a JSON chunk first")
    binary = None
    pos = 20 + n + (-n % 4)
    if pos + 8 <= length:
        bn, bkind = struct.unpack_from("<II", data, pos)
        if bkind == BIN_CHUNK and pos + 8 + bn <= length:
            binary = data[pos + 8:pos + 8 + bn]
    return data[20:20 + n], binary


def written_by_iblbake(path) -> bool:
    """Whether `path` is a glTF or GLB file whose asset.generator names iblbake (what export-gltf
    may replace without --force)."""
    from iblbake.io import reads

    try:
        head = reads.read_head(path, 20)
        if head[:4] == b"glTF":         # a GLB: its JSON chunk only, the images not read
            n, kind = struct.unpack_from("<II", head, 12)
            if kind != JSON_CHUNK or n > reads.JSON_BYTES:
                return False
            text = reads.read_head(path, 20 + n)[20:]
        else:
            text = reads.read_bytes(path, reads.JSON_BYTES, "a glTF document")
        return str(json.loads(text)["asset"]["generator"]).startswith("iblbake")
    except (OSError, ValueError, KeyError, TypeError, struct.error, IblbakeError):
        return False


def sidecars(path, levels: int) -> list:
    """The PNGs a .gltf light of `levels` mips writes beside itself."""
    path = Path(path)
    return [path.with_name(f"{path.stem}_specular_{k}_{face}.png") for k in range(levels) for face in FACES] \
        if path.suffix.lower() == ".gltf" else []


def file_uri(name: str) -> str:
    """The relative URI of a file beside the document: its name's bytes percent-encoded (RFC 3986;
    a '#', '%', space or non-UTF-8 byte would otherwise be misread), plain names unchanged."""
    return quote(os.fsencode(name), safe="")


def light_document(coefficients, size: int, levels: int, intensity: float, name: str, extras: dict) -> dict:
    """The glTF document of one scene lit by one image-based light; images filled in by write()."""
    coefficients = np.asarray(coefficients, np.float64)
    if coefficients.shape != (9, 3) or not np.all(np.isfinite(coefficients)):
        raise ValueError("irradianceCoefficients must be 9 x 3 finite numbers")
    return {
        "asset": {"version": "2.0", "generator": extras.get("generator", "iblbake")},
        "extensionsUsed": [EXTENSION],
        "extensions": {EXTENSION: {"lights": [{
            "name": name, "intensity": float(intensity),
            "irradianceCoefficients": [[float(v) for v in row] for row in coefficients],
            "specularImageSize": int(size),
            "specularImages": [[6 * k + f for f in range(6)] for k in range(levels)],
        }]}},
        "scene": 0,
        "scenes": [{"name": name, "extensions": {EXTENSION: {"light": 0}}}],
        "extras": {k: v for k, v in extras.items() if k != "generator"},
    }


def write(path, coefficients, pngs, size: int, intensity: float = 1.0, name: str = "environment",
          extras: dict | None = None) -> list:
    """Write the light: `pngs[k][f]` the PNG bytes of mip k, face f. .gltf or .glb by the path's
    suffix. Returns the paths written (the document last)."""
    from iblbake.io import atomic

    path = Path(path)
    kind = path.suffix.lower()
    if kind not in (".gltf", ".glb"):
        raise IblbakeError(f"{path}: a glTF light is written as .gltf (PNGs beside it) or .glb (one file)")
    if len(pngs) < 1 or any(len(faces) != 6 for faces in pngs):
        raise ValueError("specular images: every mip needs six faces")
    doc = light_document(coefficients, size, len(pngs), intensity, name, extras or {})
    flat = [b for faces in pngs for b in faces]
    written = []
    if kind == ".gltf":
        doc["images"] = []
        with atomic.Batch() as batch:       # every face, then the document (renamed last), or none
            for png, data in zip(sidecars(path, len(pngs)), flat):
                batch.write_bytes(png, data)
                written.append(png)
                doc["images"].append({"uri": file_uri(png.name), "mimeType": "image/png"})
            batch.write_text(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")
        return written + [path]
    views, offset = [], 0
    for data in flat:
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(data)})
        offset += -(-len(data) // 4) * 4
    doc["buffers"] = [{"byteLength": offset}]
    doc["bufferViews"] = views
    doc["images"] = [{"bufferView": i, "mimeType": "image/png"} for i in range(len(flat))]
    atomic.write_bytes(path, glb_bytes(doc, b"".join(d + b"\0" * (-len(d) % 4) for d in flat)))
    return [path]


def glb_bytes(doc: dict, binary: bytes) -> bytes:
    """glTF's binary container: header (magic, version 2, length), JSON chunk, BIN chunk."""
    js = json.dumps(doc, separators=(",", ":"), allow_nan=False).encode("utf-8")
    js += b" " * (-len(js) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<II", len(js), JSON_CHUNK) + js + struct.pack("<II", len(binary), BIN_CHUNK) + binary
    return struct.pack("<III", GLB_MAGIC, 2, 12 + len(chunks)) + chunks


class Binary:
    """A glTF buffer being built (lightmaps' meshes: render/lightmaps/gltf_scene.py): each array
    added is a bufferView of its own, 4-byte aligned, and an accessor over it."""
    TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}
    COMPONENTS = {np.dtype(np.float32): 5126, np.dtype(np.uint32): 5125}

    def __init__(self):
        self.data, self.views, self.accessors = bytearray(), [], []

    def add(self, array, target: int | None = None, bounds: bool = False) -> int:
        """The accessor index of `array` (n,) or (n, c), float32 or uint32; bounds: its min and max
        (POSITION needs them). target: 34962 vertex attributes, 34963 indices."""
        a = np.ascontiguousarray(array)
        self.data += b"\0" * (-len(self.data) % 4)
        view = {"buffer": 0, "byteOffset": len(self.data), "byteLength": a.nbytes}
        if target:
            view["target"] = target
        self.data += a.astype(a.dtype.newbyteorder("<")).tobytes()
        self.views.append(view)
        acc = {"bufferView": len(self.views) - 1, "componentType": self.COMPONENTS[a.dtype], "count": len(a),
               "type": self.TYPES[1 if a.ndim == 1 else a.shape[1]]}
        if bounds:
            acc["min"], acc["max"] = [float(x) for x in a.min(0)], [float(x) for x in a.max(0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def attach(self, doc: dict, uri: str) -> bytes:
        """The buffer's bytes, its views and accessors set in doc, the buffer at `uri` (file_uri)."""
        self.data += b"\0" * (-len(self.data) % 4)
        doc["buffers"] = [{"byteLength": len(self.data), "uri": uri}]
        doc["bufferViews"], doc["accessors"] = self.views, self.accessors
        return bytes(self.data)
