"""lightmap.gltf (+ .bin, + the 8-bit image): a lightmap's static geometry as glTF 2.0, each
lightmapped object one mesh (POSITION, NORMAL, TEXCOORD_1: the atlas' UVs, TEXCOORD_0 the same: glTF's
sets start at 0 and the layout keeps no material UVs), a primitive per material (primitives: a glTF
file's several kept apart),
the scene's camera, and the irradiance atlas referenced by the IBLBAKE_lightmap extension (no
standard glTF extension exists; docs/conventions.md "Lightmaps in files" says why this one):

  material.extensions.IBLBAKE_lightmap = {"lightmapTexture": {"index": 0, "texCoord": 1},
                                          "encoding": "gamma 2.2", "irradianceScale": s}
  E (the irradiance, linear) = s * (texel / 255)^2.2; diffuse = albedo / pi * E

declared in extensionsUsed, not extensionsRequired: a loader that does not know it still loads the
meshes. The root's extension block names lightmap.json, which holds every basis' atlases."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np

from iblbake.io import gltf

LINEAR, CLAMP = 9729, 33071
ENCODING = "gamma 2.2"       # E = irradianceScale * (texel / 255)^2.2
# an object with no material of the scene's nor of its file's
DEFAULT_MATERIAL = {"base_color": [0.8, 0.8, 0.8], "metallic": 0.0, "roughness": 1.0, "specular": 1.0,
                    "specular_color": [1.0, 1.0, 1.0]}
SPECULAR = "KHR_materials_specular"


def object_mesh(lay, oid: int, select=None):
    """(positions (v, 3), normals (v, 3), TEXCOORD_1 (v, 2), indices (3t,)) of object oid's
    triangles in the atlas (those of them `select` (n,) marks, where given), corners shared where
    position, normal and UV all agree."""
    tri = lay.objects == oid if select is None else (lay.objects == oid) & select
    n = lay.normals[tri].reshape(-1, 3)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    uv = lay.uv[tri].reshape(-1, 2) / [lay.width, lay.height]
    rows = np.concatenate([lay.corners[tri].reshape(-1, 3), n, uv], 1).astype(np.float32)
    verts, inverse = np.unique(rows, axis=0, return_inverse=True)
    return verts[:, :3], verts[:, 3:6], verts[:, 6:8], inverse.reshape(-1).astype(np.uint32)


def quaternion(m) -> list:
    """The unit quaternion (x, y, z, w) of rotation matrix m (3, 3) (Shepperd's method)."""
    t = np.trace(m)
    if t > 0:
        s = 2 * np.sqrt(1 + t)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2 * np.sqrt(1 + m[i, i] - m[j, j] - m[k, k])
        q = [0.0] * 4
        q[i], q[j], q[k], q[3] = s / 4, (m[j, i] + m[i, j]) / s, (m[k, i] + m[i, k]) / s, (m[k, j] - m[j, k]) / s
    q = np.asarray(q) / np.linalg.norm(q)
    return [float(x) for x in q]


def camera(cam: dict) -> tuple:
    """(glTF camera, its node) of the scene's camera: glTF's looks down its -z, +y up."""
    from iblbake.scene.pack import camera_vectors
    pos, fwd, right, up, ortho = camera_vectors(cam)
    w, h = cam["resolution"]
    rot = np.stack([right / np.linalg.norm(right), up / np.linalg.norm(up), -fwd], 1)
    c = cam[cam["projection"]]
    if ortho:
        mags = {"xmag": float(np.linalg.norm(right)), "ymag": float(np.linalg.norm(up))}
        glc = {"type": "orthographic", "orthographic": {**mags, "znear": 0.01, "zfar": 1000.0}}
    else:
        glc = {"type": "perspective", "perspective": {"yfov": float(np.radians(c["fov_y"])), "aspectRatio": w / h,
                                                      "znear": 0.01, "zfar": 1000.0}}
    return glc, {"name": "camera", "camera": 0, "translation": [float(x) for x in pos], "rotation": quaternion(rot)}


def material(m: dict, name: str, extension: str, scale: float) -> dict:
    """A scene or file material record (scene/materials.py) as glTF's, its KHR_materials_specular
    where it is not the default (specular 0: a loader adds no lobe the bake did not have)."""
    # single-sided: the atlas holds a chart for each lit side of a surface, each wound to face its
    # side (render/lightmaps/uv.py), so a back face culled is the other side's chart shown
    ext = {extension: {"lightmapTexture": {"index": 0, "texCoord": 1}, "encoding": ENCODING, "irradianceScale": scale}}
    colour = [float(x) for x in m["specular_color"]]
    if m["specular"] != 1.0 or colour != [1.0, 1.0, 1.0]:
        ext[SPECULAR] = {"specularFactor": float(m["specular"]), "specularColorFactor": colour}
    return {"name": name, "doubleSided": False,
            "pbrMetallicRoughness": {"baseColorFactor": [float(x) for x in m["base_color"]] + [1.0],
                                     "metallicFactor": float(m["metallic"]), "roughnessFactor": float(m["roughness"])},
            "extensions": ext}


def object_material(sc, oid: int, records: list, offsets: dict) -> tuple:
    """(a key, the record, its glTF name) of object oid's material: the scene's, or its glTF file's
    own (named as in the file) where it brings one; a file of several: the key ("file", oid), its
    triangles' own found by primitives()."""
    from iblbake.scene import materials
    o, first = sc.data["objects"][oid], offsets[oid]
    if not materials.brings_materials(o):
        return (first, records[first], o["material"]) if first >= 0 else (-1, DEFAULT_MATERIAL, "default")
    own = records[first:first + len(materials.file_materials(o["mesh"]["path"], "")) - 1]   # the glTF default last
    if len(own) == 1:
        return first, own[0], own[0]["name"].split(": ", 1)[1]
    if not own:                                     # its primitives take the glTF default
        return first, records[first], "default"
    return ("file", oid), DEFAULT_MATERIAL, ", ".join(r["name"] for r in own)


def triangle_records(lay, oid: int, tris) -> np.ndarray:
    """The material record of each of object oid's atlas triangles: the scene triangle (tris:
    scene/geometry.py build_triangles) with the same corners, which the atlas keeps (a back side's
    wound the other way; compared in float32, as a cached atlas may hold them)."""
    def keys(c):                      # the corners in one order, as bytes
        c = np.ascontiguousarray(c, np.float32)
        order = np.lexsort((c[..., 2], c[..., 1], c[..., 0]))
        return [r.tobytes() for r in np.take_along_axis(c, order[..., None], 1).reshape(len(c), 9)]
    mine = tris.object_id == oid
    record = dict(zip(keys(np.stack([tris.v0[mine], tris.v1[mine], tris.v2[mine]], 1)), tris.material[mine]))
    first = int(tris.material[mine][0])
    return np.array([record.get(k, first) for k in keys(lay.corners[lay.objects == oid])], np.int64)


def primitives(sc, lay, oid: int, records: list, offsets: dict, tris) -> list:
    """(key, record, glTF name, the atlas triangles it covers (n,) or None: all) per primitive of
    object oid: one, or one per material of a glTF file of several (tris(): the scene's triangles)."""
    key, rec, name = object_material(sc, oid, records, offsets)
    if key != ("file", oid):
        return [(key, rec, name, None)]
    per = np.full(len(lay.objects), -1, np.int64)
    per[lay.objects == oid] = triangle_records(lay, oid, tris())
    return [(int(r), records[r], records[r]["name"].split(": ", 1)[-1], per == r) for r in np.unique(per[per >= 0])]


def image_scale(e) -> float:
    """The factor s the 8-bit image holds E / s at: the brightest texel at 1 (8-bit gamma keeps
    about 0.4% of a texel near the top, a few % of one a tenth of it)."""
    top = float(np.max(e)) if np.size(e) else 0.0
    return top if top > 0 else 1.0


def image(e, scale: float) -> bytes:
    """The irradiance atlas as an 8-bit RGB PNG: (E / scale)^(1 / 2.2), its first row at the top.
    Not RGBD: a browser premultiplies a PNG's alpha as it decodes it, and RGBD's alpha (1/255 on a
    texel 255 times the dimmest) then left its RGB a step or two (Babylon read a floor 50% dark)."""
    from iblbake.io.images import png_bytes
    v = np.clip(np.asarray(e, np.float64) / scale, 0.0, 1.0) ** (1.0 / gltf.GAMMA)
    return png_bytes(np.rint(v * 255.0).astype(np.uint8), colour=False)


def lightmapped(lm: dict, sc) -> list:
    """(object index, its name: the scene's `name` or objects.N) of each object in the atlas, in
    the order of the glTF's meshes and nodes (node i is the i-th)."""
    objects = sc.data["objects"]
    ids = sorted(int(o) for o in np.unique(lm["layout"].objects))
    return [(oid, objects[oid].get("name") or f"objects.{oid}") for oid in ids]


def _scene_triangles(sc):
    from iblbake.render.lightmaps.bake import triangles
    return triangles(sc)


def document(lm: dict, sc, stem: str, extension: str, scale: float) -> tuple:
    """(the glTF document, the .bin's bytes)."""
    from iblbake.io.guard import mark
    lay = lm["layout"]
    buf = gltf.Binary()
    from iblbake.scene.materials import table
    records, offsets = table(sc)
    meshes, nodes, materials, names = [], [], [], {}
    tris = functools.cache(lambda: _scene_triangles(sc))
    for oid, label in lightmapped(lm, sc):
        prims = []
        for key, rec, mname, select in primitives(sc, lay, oid, records, offsets, tris):
            if key not in names:
                names[key] = len(materials)
                materials.append(material(rec, mname, extension, scale))
            pos, nrm, uv1, idx = object_mesh(lay, oid, select)
            uv = buf.add(uv1, 34962)
            # TEXCOORD_0 the atlas' UVs too: glTF's indexed attributes start at 0 (the layout keeps no material UVs)
            prims.append({"attributes": {"POSITION": buf.add(pos, 34962, bounds=True), "NORMAL": buf.add(nrm, 34962),
                                         "TEXCOORD_0": uv, "TEXCOORD_1": uv},
                          "indices": buf.add(idx, 34963), "material": names[key], "mode": 4})
        meshes.append({"name": label, "primitives": prims})
        nodes.append({"name": label, "mesh": len(meshes) - 1})
    glc, cam_node = camera(sc.data["camera"])
    nodes.append(cam_node)
    used = sorted({k for m in materials for k in m["extensions"]} - {extension})
    doc = {"asset": {"version": "2.0", "generator": mark()},
           "extensionsUsed": [extension, *used],
           "extensions": {extension: {"manifest": gltf.file_uri(f"{stem}.json")}},
           "scene": 0, "scenes": [{"name": Path(sc.source).stem, "nodes": list(range(len(nodes)))}],
           "nodes": nodes, "meshes": meshes, "materials": materials, "cameras": [glc],
           "samplers": [{"magFilter": LINEAR, "minFilter": LINEAR, "wrapS": CLAMP, "wrapT": CLAMP}],
           "images": [{"uri": gltf.file_uri(f"{stem}.png"), "mimeType": "image/png"}],
           "textures": [{"sampler": 0, "source": 0}],
           "extras": {"source": Path(sc.source).name, "atlas": [lay.width, lay.height]}}    # no absolute path
    data = buf.attach(doc, gltf.file_uri(f"{stem}.bin"))
    return doc, data


def write(lm: dict, sc, folder: Path, stem: str, extension: str, batch) -> float:
    """STEM.gltf, STEM.bin and STEM.png into folder through batch; the image's scale written."""
    e = np.asarray(lm["irradiance"], np.float64)
    scale = image_scale(e[lm["valid"]])
    doc, data = document(lm, sc, stem, extension, scale)
    batch.write_bytes(Path(folder) / f"{stem}.bin", data)
    batch.write_bytes(Path(folder) / f"{stem}.png", image(e, scale))
    batch.write_text(Path(folder) / f"{stem}.gltf", json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return scale
