"""A validated scene as the device sees it: camera vectors, sub-pixel jitter, and the material,
sphere, plane, triangle and BVH records (layouts in iblbake.scene.layout.py, kernels/layout.h).
Shared by the OpenCL renderer and its numpy twin."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from iblbake.core import sampling
from iblbake.errors import InputError
from iblbake.scene.layout import FLOAT4S, SURFACE_FLAGS
from iblbake.scene import geometry
from iblbake.scene.bvh import build_bvh, device_tree
from iblbake.scene.load import Scene


def camera_vectors(cam: dict):
    """(origin, forward, right*half_width, up*half_height, orthographic) in float64."""
    w, h = cam["resolution"]
    proj = cam["projection"]
    c = cam[proj]
    pos = np.asarray(c["position"], np.float64)
    fwd = np.asarray(c["look_at"], np.float64) - pos
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.asarray(c["up"], np.float64))
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    if proj == "perspective":
        hh = math.tan(math.radians(c["fov_y"]) / 2)
        hw = hh * w / h
    else:
        hw = c["width"] / 2
        hh = hw * h / w
    return pos, fwd, right * hw, up * hh, proj == "orthographic"


def pixel_jitter(spp: int):
    """Sub-pixel sample positions: the centre for spp = 1, else a centred Hammersley set."""
    if spp == 1:
        return np.array([[0.5, 0.5]])
    pts = sampling.hammersley(spp).astype(np.float64)
    return np.mod(pts + 0.5 / spp, 1.0)


@dataclass
class SceneArrays:
    materials: np.ndarray     # (m, FLOAT4S["MATERIAL"], 4) float32
    material_names: list
    spheres: np.ndarray       # (s, 2, 4) float32
    planes: np.ndarray        # (p, 5, 4) float32
    tris: np.ndarray          # (t, 6, 4) float32, BVH order: v0|material, v1|object, v2, 3 normals
    bvh: np.ndarray           # (nodes, 8) float32: the binary tree (scene/bvh.py build_bvh), a GPU's
    geometry_report: dict
    tri_attr: np.ndarray | None = None      # (t, TRIANGLE_ATTR, 4) float32, BVH order (uv, tangents, density)
    records: list | None = None             # the material table (iblbake.scene.materials)
    tri_closed: np.ndarray | None = None    # (t, 2) int32, BVH order: component, its solid (geometry.closed_components)
    bvh_wide: np.ndarray | None = None      # (records, 4) float32: the 4-wide tree, a CPU's (scene/bvh.py device_tree)


def _int_bits(x):
    return np.asarray(x, np.int32).view(np.float32)


def scene_arrays(scene: Scene, meshes=None) -> SceneArrays:
    """Every record the device reads but the textures. `meshes`, the (triangles, BVH nodes, 4-wide
    BVH records, report, triangle attributes, closed parts) of mesh_arrays(), may come from a cache
    (they are the costly part: a 1.3M-triangle PLY takes seconds to load and split)."""
    from iblbake.scene import materials

    d = scene.data
    records, _offsets = materials.table(scene)
    names = [r["name"] for r in records]
    index = {n: i for i, n in enumerate(d["materials"])}
    mats, _maps = materials.device_arrays(records, {(i, k): 0 for i, r in enumerate(records) for k in r["maps"]})
    flags = materials.surface_flags(records)
    spheres, planes = [], []
    for oid, o in enumerate(d["objects"]):
        if "sphere" in o:
            s = np.zeros((2, 4), np.float32)
            s[0, :3], s[0, 3] = o["sphere"]["center"], o["sphere"]["radius"]
            s[1, 0], s[1, 1], s[1, 2] = (_int_bits(index[o["material"]]), _int_bits(oid),
                                         _int_bits(flags[index[o["material"]]]))
            spheres.append(s)
        elif "plane" in o:
            p = o["plane"]
            n, t, b = geometry.plane_frame(p["normal"])
            size = p["size"]
            hw, hd = (math.inf, math.inf) if size is None else \
                ((size / 2, size / 2) if not isinstance(size, list) else (size[0] / 2, size[1] / 2))
            a = np.zeros((FLOAT4S["PLANE"], 4), np.float32)
            a[0, :3], a[0, 3] = p["point"], _int_bits(index[o["material"]])
            a[1, :3], a[1, 3] = n, _int_bits(oid)
            a[2, :3], a[2, 3] = t, hw
            a[3, :3], a[3, 3] = b, hd
            a[4, 0] = _int_bits(flags[index[o["material"]]])
            planes.append(a)
    arr, nodes, wide, report, attr, closed = meshes if meshes is not None else mesh_arrays(scene)
    if len(arr):                     # the flags of the triangles' materials now (the cache keeps none)
        arr = arr.copy()
        tri_flags = flags[arr[:, 0, 3].view(np.int32)]
        arr[:, 2, 3] = _int_bits(tri_flags | solid_flags(scene, arr, closed, tri_flags))
    spheres = np.array(spheres, np.float32).reshape(-1, 2, 4)
    for i, s in enumerate(spheres):
        oid = int(s[1, 1:2].view(np.int32)[0])
        f = int(s[1, 2:3].view(np.int32)[0])
        if solid_object(d["objects"][oid], True, _camera_inside_sphere(scene, s[0])):
            s[1, 2] = _int_bits(f | SURFACE_FLAGS["solid"])
    return SceneArrays(mats, names, spheres, np.array(planes, np.float32).reshape(-1, FLOAT4S["PLANE"], 4), arr, nodes,
                       report, attr, records, closed, wide)


def solids_digest(arrays: SceneArrays) -> str:
    """A digest of which surfaces bound solids (SURFACE_FLAGS solid, solid_flipped) in the packed
    scene: what `objects.N.solid: auto` decided from the camera's position. A traced bake's cache
    key holds it (the same objects make a room or a solid as the camera moves in or out)."""
    import hashlib

    bits = SURFACE_FLAGS["solid"] | SURFACE_FLAGS["solid_flipped"]
    h = hashlib.sha256()
    for a in (arrays.tris[:, 2, 3] if len(arrays.tris) else np.zeros(0, np.float32),
              arrays.spheres[:, 1, 2] if len(arrays.spheres) else np.zeros(0, np.float32)):
        h.update((np.ascontiguousarray(a, np.float32).view(np.int32) & bits).astype(np.int8).tobytes())
        h.update(b"|")
    return h.hexdigest()[:16]


def solid_object(obj: dict, closed: bool, camera_inside: bool) -> bool:
    """Whether a closed part of an object bounds a solid to the probes (objects.N.solid): auto,
    where it is closed and the camera is not inside it (a room seen from within is no solid)."""
    return obj["solid"] is True or (obj["solid"] == "auto" and closed and not camera_inside)


def _camera_inside_sphere(scene: Scene, s) -> bool:
    pos = np.asarray(camera_vectors(scene.data["camera"])[0])
    return float(np.linalg.norm(pos - s[:3].astype(np.float64))) < float(s[3])


def solid_flags(scene: Scene, arr, closed, tri_flags) -> np.ndarray:
    """SURFACE_FLAGS' solid bits of each triangle (docs/conventions.md "Sides"): a triangle of a
    closed component bounds a solid, as the object's `solid` key decides: inside it by the
    component's volume where double-sided (flipped where wound inwards), by its winding where
    single-sided (a single-sided surface is there from its front alone)."""
    out = np.zeros(len(arr), np.int32)
    if closed is None or not len(arr):
        return out
    from iblbake.scene import geometry
    comp, sign = closed[:, 0], closed[:, 1]
    v = arr[:, :3, :3].astype(np.float64)
    inside = geometry.inside_closed(camera_vectors(scene.data["camera"])[0], v[:, 0], v[:, 1], v[:, 2], comp, sign)
    objs = scene.data["objects"]
    oid = arr[:, 1, 3].view(np.int32)
    for o in np.unique(oid):
        sel = oid == o
        obj = objs[int(o)]
        for c in np.unique(comp[sel]):
            part = sel & (comp == c)
            sg = int(sign[part][0])
            if solid_object(obj, sg != 0, int(c) in inside):
                out[part] = SURFACE_FLAGS["solid"] | (SURFACE_FLAGS["solid_flipped"] if sg < 0 else 0)
    return np.where(tri_flags & SURFACE_FLAGS["single_sided"], out & SURFACE_FLAGS["solid"], out)


def mesh_arrays(scene: Scene):
    """(triangles (t, 6, 4) float32 in BVH order, the binary BVH's nodes (n, 8) float32, the 4-wide
    BVH's records (m, 4) float32 (bvh.device_tree), report, triangle attributes (t, TRIANGLE_ATTR, 4)
    float32 in BVH order, closed parts (t, 2) int32 in BVH order: component and solid,
    geometry.closed_components) of every mesh object of the scene, in world space."""
    from iblbake.scene import materials

    d = scene.data
    _records, offsets = materials.table(scene)
    counts = {oid: len(materials.file_materials(o["mesh"]["path"], f"{scene.source}: objects.{oid}.mesh"))
              for oid, o in enumerate(d["objects"]) if materials.brings_materials(o)}
    t0 = time.perf_counter()
    attributes = needs_attributes(scene)
    tris = geometry.build_triangles(d["objects"], offsets, scene.source, counts, attributes)
    check_texcoords(tris, _records, scene)
    load_s = time.perf_counter() - t0
    report = {"meshes": tris.stats, "triangles": len(tris), "load_s": round(load_s, 4)}
    if len(tris):
        lo, hi = geometry.triangle_bounds(tris)
        bvh = build_bvh(lo, hi)
        o = bvh.order
        arr = np.zeros((len(tris), 6, 4), np.float32)
        arr[:, 0, :3], arr[:, 0, 3] = tris.v0[o], _int_bits(tris.material[o])
        arr[:, 1, :3], arr[:, 1, 3] = tris.v1[o], _int_bits(tris.object_id[o])
        arr[:, 2, :3] = tris.v2[o]
        arr[:, 3:6, :3] = tris.normals[o]
        nodes, wide = bvh.nodes, device_tree(bvh, arr[:, 0, :3], arr[:, 1, :3], arr[:, 2, :3])
        report.update({"bvh_build_s": round(bvh.build_s, 4), "bvh_nodes": bvh.node_count, "bvh_depth": bvh.depth,
                       "bvh4_nodes": len(bvh.wide), "bvh4_depth": bvh.wide_depth})
        attr = np.zeros((len(tris) if attributes else 0, FLOAT4S["TRIANGLE_ATTR"], 4), np.float32)
        if attributes:
            attr[:, 0:3] = np.nan_to_num(tris.uv[o])
            attr[:, 3:6] = tris.tangents[o]
            attr[:, 6, :2] = tris.uv_density[o]
        closed = np.stack([tris.component[o], tris.solid[o]], 1).astype(np.int32)
    else:
        arr, nodes, wide, _report, attr, closed = no_meshes()
    return arr, nodes, wide, report, attr, closed


def no_meshes():
    """mesh_arrays() of a scene without a triangle"""
    return (np.zeros((0, FLOAT4S["TRIANGLE"], 4), np.float32), np.zeros((0, 8), np.float32),
            np.zeros((0, 4), np.float32), {"meshes": [], "triangles": 0, "load_s": 0.0},
            np.zeros((0, FLOAT4S["TRIANGLE_ATTR"], 4), np.float32), np.zeros((0, 2), np.int32))


def needs_attributes(scene: Scene) -> bool:
    """Whether the kernels read the triangles' texture coordinates and tangents (some material
    in use has a texture or an alpha mask)."""
    from iblbake.scene import materials

    fx = materials.defines(materials.used(scene))
    return "HAS_TEXTURES" in fx or "HAS_ALPHA_MASK" in fx


def check_texcoords(tris, records, scene) -> None:
    """A textured material on triangles without the texture coordinates its maps read is an
    error naming both."""
    for m in np.unique(tris.material):
        r = records[m]
        sets = {ref["texcoord"]: kind for kind, ref in r["maps"].items()}
        for k, kind in sets.items():
            sel = tris.material == m
            bad = ~np.isfinite(tris.uv[sel][..., 2 * k:2 * k + 2]).all(axis=(1, 2))
            if bad.any():
                oid = int(tris.object_id[sel][bad][0])
                path = scene.data["objects"][oid]["mesh"]["path"]
                raise InputError(f"{scene.source}: objects.{oid}: material {r['name']!r} has a {kind} map "
                                 f"read through TEXCOORD_{k}, but mesh {path} has no such texture coordinates "
                                 f"on {int(bad.sum())} of its triangles; give it UVs or another material")


def light_records(lights: list) -> np.ndarray:
    """(lights, LIGHT float4s, 4) float32 (layout.FLOAT4S["LIGHT"]) of validated `lights:` entries
    (render adds the extracted sun): what kernels/lights.cl reads.
    KHR_lights_punctual's spot falloff: a = clamp(cos(angle to the axis) scale + offset, 0, 1)^2,
    scale = 1 / max(1e-3, cos(inner) - cos(outer)), offset = -cos(outer) scale."""
    from iblbake.scene.layout import LIGHT_KINDS, SHADOW_MODES

    out = np.zeros((len(lights), FLOAT4S["LIGHT"], 4), np.float32)
    for i, lt in enumerate(lights):
        kind = next(k for k in LIGHT_KINDS if k in lt)
        p = lt[kind]
        r = out[i]
        r[0, 3], r[1, 3], r[3, 3] = LIGHT_KINDS[kind], SHADOW_MODES[lt["shadows"]], lt["shadow_samples"]
        if kind == "directional":
            d = np.asarray(p["direction"], np.float64)
            r[0, :3] = -d / np.linalg.norm(d)
            r[1, :3] = np.asarray(p["color"]) * p["illuminance"]
            r[2, 3] = math.sin(math.radians(p["angular_diameter"]) / 2)   # sine of the angular radius
            r[3, :2] = 0.0, 1.0
            continue
        r[0, :3] = p["position"]
        r[1, :3] = np.asarray(p["color"]) * p["intensity"]
        r[2, 3] = p["radius"]
        r[3, 2] = p["range"] or 0.0
        if kind == "spot":
            d = np.asarray(p["direction"], np.float64)
            r[2, :3] = d / np.linalg.norm(d)
            ci, co = math.cos(math.radians(p["inner_cone_angle"])), math.cos(math.radians(p["outer_cone_angle"]))
            scale = 1.0 / max(1e-3, ci - co)
            r[3, :2] = scale, -co * scale
        else:
            r[3, :2] = 0.0, 1.0
    return out
