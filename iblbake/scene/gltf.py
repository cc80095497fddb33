"""glTF 2.0 files (.gltf with external or embedded buffers, .glb) read as the glTF 2.0
specification (Khronos) defines them: the default scene's node hierarchy, every triangle
primitive with its POSITION, NORMAL, TEXCOORD_0/1 and TANGENT attributes, and the materials with
their textures, samplers and KHR_texture_transform.

Written here rather than taken from trimesh, which keeps only TEXCOORD_0 and drops TANGENT,
samplers, KHR_texture_transform and normal/occlusion scales; the container is small (a JSON
document, buffers, typed accessors). Every malformed input is an InputError naming the file and
what is wrong in it (the fuzz suite feeds it assimp's broken models and mutated files).
"""

from __future__ import annotations

import base64
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from iblbake.errors import InputError
from iblbake.io.gltf import split_glb
from iblbake.io import confine, reads

COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
NORMALIZE = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
MAX_NODE_DEPTH = 256
# sampler enums (glTF 2.0, from OpenGL): wrap modes and filters
WRAP = {33071: "clamp", 33648: "mirror", 10497: "repeat"}
MAG = {9728: "nearest", 9729: "linear"}
MIN = {9728: "nearest", 9729: "linear", 9984: "nearest_mipmap_nearest", 9985: "linear_mipmap_nearest",
       9986: "nearest_mipmap_linear", 9987: "linear_mipmap_linear"}
# the glTF default material (spec 3.9.6): base colour 1, metallic 1, roughness 1
DEFAULT_MATERIAL = {"name": "default", "base_color": [1.0, 1.0, 1.0], "alpha": 1.0, "metallic": 1.0, "roughness": 1.0,
                    "emissive": [0.0, 0.0, 0.0], "specular": 1.0, "specular_color": [1.0, 1.0, 1.0], "alpha_mode": "opaque", "alpha_cutoff": 0.5, "double_sided": False,
                    "maps": {}}


def _fail(where: str, path, what: str):
    raise InputError(f"{where}: mesh {path} cannot be read ({what}); check the file (OBJ, PLY, STL, GLB/glTF)")


@dataclass
class Primitive:
    positions: np.ndarray              # (n, 3) float64, world space of the file (node transforms applied)
    faces: np.ndarray                  # (m, 3) int64, counter-clockwise front faces
    normals: np.ndarray | None         # (n, 3)
    texcoords: list                    # [uv0 or None, uv1 or None], (n, 2) float64, glTF's: v down
    tangents: np.ndarray | None        # (n, 4): xyz, w the bitangent's sign
    material: int                      # index into Document.materials(), -1: the default material


@dataclass
class Document:
    path: Path
    where: str
    doc: dict
    binary: bytes | None = None                      # a GLB's BIN chunk
    _buffers: dict = field(default_factory=dict)

    # -- buffers and accessors ---------------------------------------------------------------
    def _list(self, key) -> list:
        v = self.doc.get(key, [])
        if not isinstance(v, list):
            _fail(self.where, self.path, f"{key} is not a list")
        return v

    def _item(self, key, i, what=None) -> dict:
        items = self._list(key)
        if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < len(items) or not isinstance(items[i], dict):
            _fail(self.where, self.path, f"{what or key} index {i!r} is not one of its {len(items)} {key}")
        return items[i]

    def buffer(self, i: int) -> bytes:
        if i not in self._buffers:
            b = self._item("buffers", i, "buffer")
            uri = b.get("uri")
            if uri is None:
                if self.binary is None or i != 0:
                    _fail(self.where, self.path, f"buffer {i} has no uri and the file no binary chunk")
                data = self.binary
            else:
                data = self._uri_bytes(uri, f"buffer {i}")
            n = b.get("byteLength")
            if not isinstance(n, int) or n < 0 or n > len(data):
                _fail(self.where, self.path, f"buffer {i} declares byteLength {n!r} but holds {len(data)} bytes")
            self._buffers[i] = data[:n]
        return self._buffers[i]

    def _uri_bytes(self, uri, what: str) -> bytes:
        if not isinstance(uri, str):
            _fail(self.where, self.path, f"{what}: uri {uri!r} is not a string")
        if uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            if not head.endswith(";base64"):
                _fail(self.where, self.path, f"{what}: a data uri that is not base64")
            try:
                return base64.b64decode(payload, validate=True)
            except ValueError:
                _fail(self.where, self.path, f"{what}: its data uri is not valid base64")
        try:
            f = confine.asset_file(self.path, uri)
        except ValueError as e:
            raise InputError(f"{self.where}: mesh {self.path}: {what} {uri!r} {e}") from None
        if not os.path.exists(f):          # not Path.exists: a name too long raised OSError
            raise InputError(f"{self.where}: mesh {self.path}: {what} {uri!r} cannot be read "
                             f"(no such file); it must be where the URI says, beside the file")
        try:
            return reads.read_bytes(f, reads.mesh_bytes(), f"a glTF {what.split()[0]}", reads.MESH_HINT)
        except InputError as e:
            raise InputError(f"{self.where}: mesh {self.path}: {what} {uri!r}: {e}") from None

    def view(self, i: int):
        """(bytes of the buffer, offset, length, stride) of bufferView i, bounds checked."""
        v = self._item("bufferViews", i, "bufferView")
        data = self.buffer(v.get("buffer", -1))
        off, n, stride = v.get("byteOffset", 0), v.get("byteLength"), v.get("byteStride")
        if not all(isinstance(x, int) and x >= 0 for x in (off, n)) or off + n > len(data):
            _fail(self.where, self.path, f"bufferView {i} reaches past its buffer")
        if stride is not None and (not isinstance(stride, int) or not 4 <= stride <= 252):
            _fail(self.where, self.path, f"bufferView {i}: byteStride {stride!r}")
        return data, off, n, stride

    def accessor(self, i: int) -> np.ndarray:
        """Accessor i as float64 (normalised integers scaled to [0, 1] or [-1, 1]) or int64 (indices),
        shape (count, width); sparse substitutions applied."""
        a = self._item("accessors", i, "accessor")
        ct, kind, count = a.get("componentType"), a.get("type"), a.get("count")
        if ct not in COMPONENTS or kind not in WIDTH or not isinstance(count, int) or count < 0:
            _fail(self.where, self.path, f"accessor {i}: componentType {ct!r}, type {kind!r}, count {count!r}")
        dt, width = np.dtype(COMPONENTS[ct]).newbyteorder("<"), WIDTH[kind]
        elem = dt.itemsize * width
        if "bufferView" in a:
            data, off, n, stride = self.view(a["bufferView"])
            aoff = a.get("byteOffset", 0)
            stride = stride or elem
            if not isinstance(aoff, int) or aoff < 0 or (count and aoff + (count - 1) * stride + elem > n):
                _fail(self.where, self.path, f"accessor {i} reaches past its bufferView")
            if count:
                raw = np.lib.stride_tricks.as_strided(
                    np.frombuffer(data, dtype=np.uint8, count=(count - 1) * stride + elem, offset=off + aoff),
                    shape=(count, elem), strides=(stride, 1))
                out = np.ascontiguousarray(raw).view(dt).reshape(count, width)
            else:
                out = np.zeros((0, width), dt)
        else:
            out = np.zeros((count, width), dt)
        out = out.astype(np.float64 if ct == 5126 or a.get("normalized") else np.int64)
        if a.get("normalized"):
            if ct not in NORMALIZE:
                _fail(self.where, self.path, f"accessor {i}: normalized with componentType {ct}")
            out = np.maximum(out / NORMALIZE[ct], -1.0)
        sparse = a.get("sparse")
        if sparse is not None:
            out = self._sparse(i, out, sparse)
        return out

    def _sparse(self, i, out, sparse):
        try:
            n = int(sparse["count"])
            ix, vals = sparse["indices"], sparse["values"]
            idx = self._typed(ix, n, 1, i)
            v = self._typed({**vals, "componentType": self.doc["accessors"][i]["componentType"]}, n, out.shape[1], i)
        except (KeyError, TypeError, ValueError):
            _fail(self.where, self.path, f"accessor {i}: malformed sparse block")
        idx = idx.ravel().astype(np.int64)
        if np.any((idx < 0) | (idx >= len(out))):
            _fail(self.where, self.path, f"accessor {i}: sparse index outside its {len(out)} elements")
        out = out.copy()
        a = self.doc["accessors"][i]
        if a.get("normalized") and a["componentType"] in NORMALIZE:
            v = np.maximum(v / NORMALIZE[a["componentType"]], -1.0)
        out[idx] = v
        return out

    def _typed(self, block, count, width, i):
        ct = block.get("componentType")
        if ct not in COMPONENTS:
            raise ValueError
        data, off, n, _ = self.view(block["bufferView"])
        boff = block.get("byteOffset", 0)
        dt = np.dtype(COMPONENTS[ct]).newbyteorder("<")
        if boff + count * width * dt.itemsize > n:
            _fail(self.where, self.path, f"accessor {i}: sparse block reaches past its bufferView")
        return np.frombuffer(data, dt, count * width, off + boff).reshape(count, width).astype(np.float64)

    # -- images --------------------------------------------------------------------------------
    def image(self, i: int):
        """(bytes, a name for messages) of image i."""
        im = self._item("images", i, "image")
        name = im.get("uri") if isinstance(im.get("uri"), str) and not str(im.get("uri")).startswith("data:") \
            else im.get("name") or f"image {i}"
        if "uri" in im:
            return self._uri_bytes(im["uri"], f"image {i}"), str(name)
        if "bufferView" in im:
            data, off, n, _ = self.view(im["bufferView"])
            return bytes(data[off:off + n]), str(name)
        _fail(self.where, self.path, f"image {i} has neither uri nor bufferView")

    # -- materials -----------------------------------------------------------------------------
    def materials(self) -> list:
        """Every material as iblbake's material record (scene/materials.py), its maps as
        {"image": index, "texcoord", "transform" (2x3), "wrap": (s, t), "mag", "min", "strength"}."""
        return [self._material(i, m) for i, m in enumerate(self._list("materials"))]

    def _material(self, i, m) -> dict:
        if not isinstance(m, dict):
            _fail(self.where, self.path, f"material {i} is not an object")
        name = str(m.get("name") or f"material {i}")
        pbr = m.get("pbrMetallicRoughness") or {}
        base = _floats(pbr.get("baseColorFactor", [1, 1, 1, 1]), 4, self, f"material {name}: baseColorFactor")
        emissive = _floats(m.get("emissiveFactor", [0, 0, 0]), 3, self, f"material {name}: emissiveFactor")
        strength = ((m.get("extensions") or {}).get("KHR_materials_emissive_strength") or {}).get("emissiveStrength", 1.0)
        spec = (m.get("extensions") or {}).get("KHR_materials_specular") or {}
        mode = m.get("alphaMode", "OPAQUE")
        if mode not in ("OPAQUE", "MASK", "BLEND"):
            _fail(self.where, self.path, f"material {name}: alphaMode {mode!r}")
        rec = {"name": name, "base_color": base[:3], "alpha": base[3],
               "metallic": _unit(pbr.get("metallicFactor", 1.0), self, f"material {name}: metallicFactor"),
               "roughness": _unit(pbr.get("roughnessFactor", 1.0), self, f"material {name}: roughnessFactor"),
               "emissive": [e * float(strength) for e in emissive], "alpha_mode": mode.lower(),
               "specular": _unit(spec.get("specularFactor", 1.0), self, f"material {name}: specularFactor"),
               "specular_color": [max(c, 0.0) for c in _floats(spec.get("specularColorFactor", [1, 1, 1]), 3, self,
                                                               f"material {name}: specularColorFactor")],
               "alpha_cutoff": float(m.get("alphaCutoff", 0.5)), "double_sided": bool(m.get("doubleSided", False)),
               "maps": {}}
        for kind, info, extra in (("base_color", pbr.get("baseColorTexture"), None),
                                  ("metallic_roughness", pbr.get("metallicRoughnessTexture"), None),
                                  ("normal", m.get("normalTexture"), "scale"),
                                  ("occlusion", m.get("occlusionTexture"), "strength"),
                                  ("emissive", m.get("emissiveTexture"), None)):
            if info is not None:
                rec["maps"][kind] = self._texture_info(info, name, kind, extra)
        return rec

    def _texture_info(self, info, material, kind, extra) -> dict:
        if not isinstance(info, dict):
            _fail(self.where, self.path, f"material {material}: {kind} texture is not an object")
        tex = self._item("textures", info.get("index"), f"material {material}: {kind} texture")
        source = tex.get("source")
        if source is None:
            exts = ", ".join(tex.get("extensions") or {}) or "none"
            raise InputError(f"{self.where}: mesh {self.path}: material {material}: its {kind} texture has no "
                             f"PNG or JPEG source (extensions: {exts}); iblbake reads PNG and JPEG textures")
        self._item("images", source, f"material {material}: {kind} texture's image")
        sampler = self._item("samplers", tex["sampler"], "sampler") if "sampler" in tex else {}
        tt = (info.get("extensions") or {}).get("KHR_texture_transform") or {}
        texcoord = tt.get("texCoord", info.get("texCoord", 0))
        if texcoord not in (0, 1):
            raise InputError(f"{self.where}: mesh {self.path}: material {material}: {kind} texture reads "
                             f"TEXCOORD_{texcoord}; iblbake reads TEXCOORD_0 and TEXCOORD_1")
        off = _floats(tt.get("offset", [0, 0]), 2, self, f"material {material}: KHR_texture_transform offset")
        scale = _floats(tt.get("scale", [1, 1]), 2, self, f"material {material}: KHR_texture_transform scale")
        rot = float(tt.get("rotation", 0.0))
        return {"image": source, "texcoord": int(texcoord), "transform": uv_transform(off, rot, scale),
                "wrap": (WRAP.get(sampler.get("wrapS", 10497), "repeat"), WRAP.get(sampler.get("wrapT", 10497), "repeat")),
                "mag": MAG.get(sampler.get("magFilter"), "linear"),
                "min": MIN.get(sampler.get("minFilter"), "linear_mipmap_linear"),
                "strength": float(info.get(extra, 1.0)) if extra else 1.0}

    # -- geometry ------------------------------------------------------------------------------
    def primitives(self) -> list:
        """Every triangle primitive of the default scene (or of every root node without one), in
        the file's world space."""
        scenes = self._list("scenes")
        if scenes:
            s = self._item("scenes", self.doc.get("scene", 0), "scene")
            roots = s.get("nodes", [])
        else:
            children = {c for n in self._list("nodes") if isinstance(n, dict) for c in n.get("children", [])}
            roots = [i for i in range(len(self._list("nodes"))) if i not in children]
        if not isinstance(roots, list):
            _fail(self.where, self.path, "a scene's nodes are not a list")
        out = []
        for r in roots:
            self._walk(r, np.eye(4), out, set())
        return out

    def _walk(self, i, parent, out, path):
        node = self._item("nodes", i, "node")
        if i in path or len(path) > MAX_NODE_DEPTH:
            _fail(self.where, self.path, f"node {i} is its own ancestor (a cycle in the node tree)")
        m = parent @ _node_matrix(node, self, i)
        if "mesh" in node:
            mesh = self._item("meshes", node["mesh"], f"node {i}: mesh")
            for k, prim in enumerate(mesh.get("primitives", [])):
                p = self._primitive(prim, m, f"mesh {node['mesh']} primitive {k}")
                if p is not None:
                    out.append(p)
        kids = node.get("children", [])
        if not isinstance(kids, list):
            _fail(self.where, self.path, f"node {i}: children is not a list")
        for c in kids:
            self._walk(c, m, out, path | {i})

    def _primitive(self, prim, m, what) -> Primitive | None:
        if not isinstance(prim, dict) or not isinstance(prim.get("attributes"), dict):
            _fail(self.where, self.path, f"{what}: no attributes")
        if "KHR_draco_mesh_compression" in (prim.get("extensions") or {}):
            raise InputError(f"{self.where}: mesh {self.path} uses Draco compression (KHR_draco_mesh_compression), "
                             f"which iblbake does not decode; export it uncompressed")
        mode = prim.get("mode", 4)
        if mode not in (4, 5, 6):
            return None                                   # points and lines: nothing to render
        att = prim["attributes"]
        if "POSITION" not in att:
            _fail(self.where, self.path, f"{what}: no POSITION")
        pos = self.accessor(att["POSITION"])
        if pos.shape[1] != 3:
            _fail(self.where, self.path, f"{what}: POSITION is not VEC3")
        n = len(pos)

        def attribute(name, width):
            if name not in att:
                return None
            a = self.accessor(att[name])
            if a.shape != (n, width):
                _fail(self.where, self.path, f"{what}: {name} has {a.shape[0]} x {a.shape[1]} values for {n} vertices")
            return a.astype(np.float64)

        if "indices" in prim:
            idx = self.accessor(prim["indices"])
            if idx.shape[1] != 1 or idx.dtype.kind != "i":
                _fail(self.where, self.path, f"{what}: indices are not unsigned integers")
            idx = idx.ravel()
        else:
            idx = np.arange(n, dtype=np.int64)
        faces = _triangles(idx, mode)
        normals, tangents = attribute("NORMAL", 3), attribute("TANGENT", 4)
        uvs = [attribute("TEXCOORD_0", 2), attribute("TEXCOORD_1", 2)]
        lin = m[:3, :3]
        det = float(np.linalg.det(lin))
        with np.errstate(all="ignore"):
            pos = pos @ lin.T + m[:3, 3]
            if normals is not None and abs(det) > 1e-300:
                normals = normals @ np.linalg.inv(lin)          # the inverse transpose
            if tangents is not None:
                xyz = tangents[:, :3] @ lin.T
                # a mirroring transform flips the bitangent's side (cross(n, t) turns with it)
                tangents = np.concatenate([xyz, tangents[:, 3:] * (1.0 if det >= 0 else -1.0)], axis=1)
        if det < 0:                                              # spec: a negative determinant flips winding
            faces = faces[:, ::-1]
        mat = prim.get("material", -1)
        if mat != -1:
            self._item("materials", mat, f"{what}: material")
        return Primitive(pos, faces, normals, uvs, tangents, mat)


def read(path, where: str) -> Document:
    """Parse a .gltf (JSON) or .glb (binary container) file."""
    path = Path(path)
    try:
        data = reads.read_bytes(path, reads.mesh_bytes(), "a mesh", reads.MESH_HINT)
    except InputError as e:
        raise InputError(f"{where}: mesh {e}") from None
    binary = None
    if data[:4] == b"glTF":
        try:
            text, binary = split_glb(data)
        except ValueError as e:
            _fail(where, path, str(e))
    elif path.suffix.lower() == ".glb":         # a .glb is read by its header, never as JSON
        _fail(where, path, f"not a GLB file: its header is {data[:4]!r}, a GLB's starts with b'glTF'")
    else:
        text = data
    try:
        doc = json.loads(text.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        _fail(where, path, f"not glTF JSON: {' '.join(str(e).split())[:100]}")
    if not isinstance(doc, dict) or not isinstance(doc.get("asset"), dict):
        _fail(where, path, "no asset object: not a glTF document")
    version = str(doc["asset"].get("version", ""))
    if not version.startswith("2."):
        _fail(where, path, f"glTF version {version or '?'}; iblbake reads glTF 2.0")
    return Document(path, where, doc, binary)


def _file_uris(data) -> list:
    """The URIs naming files (not data:) in a .gltf document (its JSON text) or a .glb (its bytes:
    the JSON chunk), buffers and images, as written; [] for data that cannot be parsed (the loader
    reports it)."""
    try:
        if isinstance(data, bytes) and data[:4] == b"glTF":
            data = split_glb(data)[0]
        doc = json.loads(data)
        uris = [x.get("uri") for key in ("buffers", "images") for x in doc.get(key, []) if isinstance(x, dict)]
    except (ValueError, AttributeError, TypeError, RecursionError):
        return []
    return [u for u in uris if isinstance(u, str) and u and not u.startswith("data:")]


def relative_uris(data) -> list:
    """The files a .gltf or .glb (its text or bytes) names by URI, buffers and images, unquoted and
    relative to it; [] for data that cannot be parsed (the loader reports it)."""
    return [unquote(u, errors="surrogateescape") for u in _file_uris(data)]


def named_files(path) -> list:
    """(uri, the file it names or None, why io/confine.py refuses it or None) of every file URI of
    the .gltf or .glb at `path`; [] for a file that cannot be read or parsed (the loader says so)."""
    path = Path(path)
    if path.suffix.lower() not in (".gltf", ".glb"):
        return []
    try:
        data = reads.read_bytes(path, reads.mesh_bytes(), "a mesh")
    except (InputError, ValueError):
        return []
    out = []
    for u in _file_uris(data):
        try:
            out.append((u, confine.asset_file(path, u), None))
        except ValueError as e:
            out.append((u, None, str(e)))
    return out


def external_files(path) -> list:
    """The files a .gltf or .glb reads beside itself (buffers and images by relative URI), for depfiles
    and cache keys: none that io/confine.py refuses (nothing reads those; the loader names them)."""
    return [os.path.normpath(f) for _, f, _ in named_files(path) if f is not None]    # a link named as given


def uv_transform(offset, rotation: float, scale) -> np.ndarray:
    """KHR_texture_transform's matrix T R S as its 2 x 3 upper rows: uv' = M (u, v, 1). The
    extension's GLSL builds R column by column, mat3(cos, sin, 0, -sin, cos, 0, 0, 0, 1): in rows,
    [[cos, -sin], [sin, cos]]."""
    c, s = math.cos(rotation), math.sin(rotation)
    return np.array([[c * scale[0], -s * scale[1], offset[0]], [s * scale[0], c * scale[1], offset[1]]])


def _triangles(idx, mode) -> np.ndarray:
    if mode == 4:
        n = len(idx) // 3 * 3
        return idx[:n].reshape(-1, 3)
    if len(idx) < 3:
        return np.zeros((0, 3), np.int64)
    k = np.arange(len(idx) - 2)
    if mode == 5:                                 # strip: every other triangle reversed
        a, b = np.where(k % 2 == 0, idx[k], idx[k + 1]), np.where(k % 2 == 0, idx[k + 1], idx[k])
        return np.stack([a, b, idx[k + 2]], axis=1)
    return np.stack([np.full(len(k), idx[0]), idx[k + 1], idx[k + 2]], axis=1)   # fan


def _node_matrix(node, doc, i) -> np.ndarray:
    if "matrix" in node:
        m = _floats(node["matrix"], 16, doc, f"node {i}: matrix")
        return np.asarray(m, np.float64).reshape(4, 4).T          # column-major
    t = _floats(node.get("translation", [0, 0, 0]), 3, doc, f"node {i}: translation")
    x, y, z, w = _floats(node.get("rotation", [0, 0, 0, 1]), 4, doc, f"node {i}: rotation")
    s = _floats(node.get("scale", [1, 1, 1]), 3, doc, f"node {i}: scale")
    q = math.sqrt(x * x + y * y + z * z + w * w) or 1.0
    x, y, z, w = x / q, y / q, z / q, w / q
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = r * np.asarray(s)[None, :]
    m[:3, 3] = t
    return m


def _floats(v, n, doc, what):
    if not isinstance(v, list) or len(v) != n or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                         and math.isfinite(x) for x in v):
        _fail(doc.where, doc.path, f"{what} is not {n} finite numbers")
    return [float(x) for x in v]


def _unit(v, doc, what):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= v <= 1.0:
        _fail(doc.where, doc.path, f"{what} {v!r} is not in [0, 1]")
    return float(v)
