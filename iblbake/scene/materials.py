"""The scene's material table: its own named materials, then the materials of every glTF mesh
that brings its own (no `material:` on the object), each as one record:

    base_color (linear RGB factor), alpha, metallic, roughness, emissive, specular and
    specular_color (KHR_materials_specular's factors), alpha_mode (opaque | mask), alpha_cutoff,
    double_sided, maps {kind: texture reference}

A texture reference: source (("path", file) or ("gltf", file, image index)), name (for
messages), texcoord (0 | 1), transform (KHR_texture_transform's 2 x 3 matrix), wrap (s, t),
mag, min (glTF sampler filters), strength (normal scale, occlusion strength).

On the device: `materials` (FLOAT4S["MATERIAL"] float4 per material: (base colour, metallic),
(emissive, roughness), (the dielectric's F0 and F90)) and `mat_maps` (MATERIAL_MAPS float4s per material, iblbake/scene/layout.py).
"""

from __future__ import annotations

import functools
import math
import os
from pathlib import Path

import numpy as np

from iblbake.errors import InputError
from iblbake.scene import textures

MAP_KEYS = {f"{k}_map": k for k in textures.MAP_KINDS}
GLTF_SUFFIXES = (".gltf", ".glb")


def brings_materials(obj: dict) -> bool:
    """A mesh object without `material:` whose file is glTF: shaded with the file's materials."""
    return "mesh" in obj and not obj.get("material") and Path(obj["mesh"]["path"]).suffix.lower() in GLTF_SUFFIXES


def scene_record(name: str, m: dict) -> dict:
    """A scene material (validated dict, paths absolute) as a record."""
    from iblbake.scene.gltf import uv_transform

    rec = {"name": name, "base_color": list(m["base_color"]), "alpha": m["alpha"], "metallic": m["metallic"],
           "roughness": m["roughness"], "emissive": list(m["emissive"]), "alpha_mode": m["alpha_mode"],
           "specular": m["specular"], "specular_color": list(m["specular_color"]),
           "alpha_cutoff": m["alpha_cutoff"], "double_sided": m["double_sided"], "maps": {}}
    for key, kind in MAP_KEYS.items():
        t = m.get(key)
        if t:
            rec["maps"][kind] = {"source": ("path", t["path"]), "name": t["path"], "texcoord": t["texcoord"],
                                 "transform": uv_transform(t["uv_offset"], math.radians(t["uv_rotation"]), t["uv_scale"]),
                                 "wrap": (t["wrap"], t["wrap"]), "mag": t["filter"],
                                 "min": "linear_mipmap_linear" if t["filter"] == "linear" else "nearest_mipmap_nearest",
                                 "strength": t.get("scale", t.get("strength", 1.0))}
    return rec


@functools.lru_cache(maxsize=64)
def _file_materials(path: str, mtime_ns: int, size: int, where: str) -> tuple:
    from iblbake.scene import gltf

    doc = gltf.read(path, where)
    try:
        recs = doc.materials()
    except (AttributeError, TypeError, KeyError, ValueError, IndexError, OverflowError) as e:
        raise InputError(f"{where}: mesh {path} cannot be read (its materials: {' '.join(str(e).split())[:100]}); "
                         f"check the file") from None
    out = []
    for r in recs + [dict(gltf.DEFAULT_MATERIAL)]:
        r = dict(r)
        r["maps"] = {k: {**v, "source": ("gltf", path, v["image"]), "name": _image_name(doc, v["image"])}
                     for k, v in r["maps"].items()}
        r["name"] = f"{Path(path).name}: {r['name']}"
        out.append(r)
    return tuple(out)


def _image_name(doc, i) -> str:
    im = doc.doc["images"][i]
    uri = im.get("uri")
    return uri if isinstance(uri, str) and not uri.startswith("data:") else str(im.get("name") or f"image {i}")


def file_materials(path: str, where: str) -> list:
    """The materials of a glTF file, the glTF default material last (for primitives without one)."""
    try:
        st = os.stat(path)
    except OSError:
        raise InputError(f"{where}: mesh {path} not found") from None
    return list(_file_materials(str(path), st.st_mtime_ns, st.st_size, where))


def table(scene) -> tuple:
    """(records, offsets): the scene's materials in its order, then for each object that brings
    its own (brings_materials), its file's; offsets[object index] is the first record of a file's
    materials, else the index of the object's scene material."""
    d = scene.data
    names = list(d["materials"])
    records = [scene_record(n, d["materials"][n]) for n in names]
    offsets = {}
    for oid, o in enumerate(d["objects"]):
        if brings_materials(o):
            offsets[oid] = len(records)
            records += file_materials(o["mesh"]["path"], f"{scene.source}: objects.{oid}.mesh")
        else:
            offsets[oid] = names.index(o["material"]) if o.get("material") in names else -1
    return records, offsets


def used(scene) -> list:
    """The records some object can be shaded with (BLEND refused: iblbake renders no transparency)."""
    records, offsets = table(scene)
    out, seen = [], set()
    for oid, o in enumerate(scene.data["objects"]):
        if brings_materials(o):
            idx = range(offsets[oid], offsets[oid] + len(file_materials(o["mesh"]["path"], "")))
        else:
            idx = [offsets[oid]]
        for i in idx:
            if i >= 0 and i not in seen:
                seen.add(i)
                out.append(records[i])
    check_supported(out, scene.source)
    return out


def check_supported(records, where: str) -> None:
    for r in records:
        if r["alpha_mode"] == "blend":
            raise InputError(f"{where}: material {r['name']!r} has alphaMode BLEND (transparency), which iblbake "
                             f"does not render; set OPAQUE or MASK (with alphaCutoff) in the file, or give the "
                             f"object a scene material")


def defines(records) -> dict:
    """What the kernels compile for these materials: HAS_TEXTURES and one HAS_<KIND>_MAP per map
    kind some material uses, HAS_ALPHA_MASK and HAS_SINGLE_SIDED where some material asks."""
    out = {}
    kinds = {k for r in records for k in r["maps"]}
    if kinds:
        out["HAS_TEXTURES"] = 1
        out.update({f"HAS_{k.upper()}_MAP": 1 for k in kinds})
    if any(r["alpha_mode"] == "mask" for r in records):
        out["HAS_ALPHA_MASK"] = 1
    if any(not r["double_sided"] for r in records):
        out["HAS_SINGLE_SIDED"] = 1
    return out


def texture_key(ref: dict, kind: str) -> tuple:
    """What makes two references one texture on the device."""
    return (ref["source"], kind, tuple(ref["wrap"]), ref["mag"], ref["min"])


def read_source(source, where: str) -> bytes:
    """An image's bytes: a scene texture's file, or a glTF file's image (its own file, data URI
    or buffer view)."""
    from iblbake.scene import gltf

    if source[0] == "path":
        from iblbake.io import reads
        try:
            return reads.read_bytes(source[1], reads.image_bytes(textures.max_texture_pixels()), "a texture",
                                    f" ({textures.RAISE_TEXTURE_LIMIT})")
        except InputError as e:
            raise InputError(f"{where}: texture {e}") from None
    return gltf.read(source[1], where).image(source[2])[0]


def load_textures(records, where: str, max_pixels: int | None = None):
    """(TextureSet, {(record index, kind): texture index}): each distinct texture read and
    decoded once."""
    import time

    t0 = time.perf_counter()
    ts = textures.TextureSet()
    index, slots = {}, {}
    for ri, r in enumerate(records):
        for kind, ref in r["maps"].items():
            key = texture_key(ref, kind)
            if key not in index:
                data = read_source(ref["source"], f"{where}: material {r['name']!r}")
                img = textures.decode(data, ref["name"], f"{where}: material {r['name']!r}", max_pixels)
                index[key] = len(ts.textures)
                ts.textures.append(textures.Texture(ref["name"], kind, textures.pyramid(textures.to_linear(img, kind), kind),
                                                    tuple(ref["wrap"]), ref["mag"], ref["min"]))
            slots[(ri, kind)] = index[key]
    ts.upload_s = time.perf_counter() - t0
    return ts, slots


def dielectric_f0(r) -> list:
    """KHR_materials_specular: a dielectric's F0 at IOR 1.5 (0.04) tinted by specular_color,
    clipped to 1, times its specular weight (which is also its F90: weight 0 leaves no lobe, a pure
    Lambert surface)."""
    return [r["specular"] * min(0.04 * c, 1.0) for c in r["specular_color"]]


def surface_flags(records) -> np.ndarray:
    """Per record SURFACE_FLAGS (layout.py): what a ray must test where it meets the material."""
    from iblbake.scene.layout import SURFACE_FLAGS

    return np.array([(0 if r["double_sided"] else SURFACE_FLAGS["single_sided"])
                     | (SURFACE_FLAGS["alpha_mask"] if r["alpha_mode"] == "mask" else 0) for r in records] or [0],
                    np.int32)


def device_arrays(records, slots, sizes=None) -> tuple:
    """(materials (M, FLOAT4S["MATERIAL"], 4), mat_maps (M, MATERIAL_MAPS, 4)) float32 for the kernels; `sizes`
    (texture index -> (width, height, sampler bits)) gives each slot's level offset and the first
    slot of the material whose footprint it shares (the same sizes, sampler, UV set and transform)."""
    from iblbake.scene.layout import FLOAT4S

    n = max(len(records), 1)
    mats = np.zeros((n, FLOAT4S["MATERIAL"], 4), np.float32)
    maps = np.zeros((n, FLOAT4S["MATERIAL_MAPS"], 4), np.float32)
    ints = maps.view(np.int32)
    ints[:, 2::3, 3] = -1                                      # no texture in any slot
    for i, r in enumerate(records):
        mats[i, 0, :3], mats[i, 0, 3] = r["base_color"], r["metallic"]
        mats[i, 1, :3], mats[i, 1, 3] = r["emissive"], r["roughness"]
        mats[i, 2, :3], mats[i, 2, 3] = dielectric_f0(r), r["specular"]
        maps[i, 0] = [r["alpha"], r["alpha_cutoff"] if r["alpha_mode"] == "mask" else -1.0,
                      r["maps"].get("normal", {}).get("strength", 1.0), r["maps"].get("occlusion", {}).get("strength", 1.0)]
        maps[i, 1, 0] = 0.0 if r["double_sided"] else 1.0
        shared = {}
        for k, kind in enumerate(textures.MAP_KINDS):
            ref = r["maps"].get(kind)
            if ref is None:
                continue
            m = np.asarray(ref["transform"], np.float64)
            t = slots[(i, kind)]
            maps[i, 2 + 3 * k, :3], maps[i, 3 + 3 * k, :3] = m[0], m[1]
            ints[i, 2 + 3 * k, 3] = t
            ints[i, 3 + 3 * k, 3] = ref["texcoord"]
            ints[i, 4 + 3 * k, 1] = k
            if sizes is not None:
                w, h, bits = sizes[t]
                with np.errstate(divide="ignore"):
                    maps[i, 4 + 3 * k, 0] = 0.5 * np.log2(w * h * abs(m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]))
                ints[i, 4 + 3 * k, 1] = shared.setdefault((w, h, bits, ref["texcoord"], m.tobytes()), k)
    return mats, maps
