"""A validated scene as the device sees it: camera vectors, sub-pixel jitter, and the material,
sphere, plane, triangle and BVH records (layouts in iblbake.scene.layout.py, kernels/layout.h).
Shared by the OpenCL renderer and its numpy twin."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from iblbake.core import sampling
from iblbake.scene.layout import FLOAT4S
from iblbake.scene import geometry
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
    materials: np.ndarray     # (m, 2, 4) float32
    material_names: list
    spheres: np.ndarray       # (s, 2, 4) float32
    planes: np.ndarray        # (p, 4, 4) float32
    tris: np.ndarray          # (t, 6, 4) float32, BVH order: v0|material, v1|object, v2, 3 normals
    bvh: np.ndarray           # (nodes, 8) float32
    geometry_report: dict


def _int_bits(x):
    return np.asarray(x, np.int32).view(np.float32)


def scene_arrays(scene: Scene, meshes=None) -> SceneArrays:
    """Every record the device reads. `meshes`, the (triangles, BVH nodes, report) of
    mesh_arrays(), may come from a cache (they are the costly part: a 1.3M-triangle PLY takes
    seconds to load and split)."""
    d = scene.data
    names = list(d["materials"])
    index = {n: i for i, n in enumerate(names)}
    mats = np.zeros((max(len(names), 1), FLOAT4S["MATERIAL"], 4), np.float32)
    for i, n in enumerate(names):
        m = d["materials"][n]
        mats[i, 0, :3], mats[i, 0, 3] = m["base_color"], m["metallic"]
        mats[i, 1, :3], mats[i, 1, 3] = m["emissive"], m["roughness"]
    spheres, planes = [], []
    for oid, o in enumerate(d["objects"]):
        if "sphere" in o:
            s = np.zeros((2, 4), np.float32)
            s[0, :3], s[0, 3] = o["sphere"]["center"], o["sphere"]["radius"]
            s[1, 0], s[1, 1] = _int_bits(index[o["material"]]), _int_bits(oid)
            spheres.append(s)
        elif "plane" in o:
            p = o["plane"]
            n, t, b = geometry.plane_frame(p["normal"])
            size = p["size"]
            hw, hd = (math.inf, math.inf) if size is None else \
                ((size / 2, size / 2) if not isinstance(size, list) else (size[0] / 2, size[1] / 2))
            a = np.zeros((4, 4), np.float32)
            a[0, :3], a[0, 3] = p["point"], _int_bits(index[o["material"]])
            a[1, :3], a[1, 3] = n, _int_bits(oid)
            a[2, :3], a[2, 3] = t, hw
            a[3, :3], a[3, 3] = b, hd
            planes.append(a)
    arr, nodes, report = meshes if meshes is not None else mesh_arrays(scene)
    return SceneArrays(mats, names, np.array(spheres, np.float32).reshape(-1, 2, 4),
                       np.array(planes, np.float32).reshape(-1, 4, 4), arr, nodes, report)


def mesh_arrays(scene: Scene):
    """(triangles (t, 6, 4) float32 in BVH order, BVH nodes (n, 8) float32, report) of every mesh
    object of the scene, in world space."""
    index = {n: i for i, n in enumerate(scene.data["materials"])}
    d = scene.data
    t0 = time.perf_counter()
    tris = geometry.build_triangles(d["objects"], index, scene.source)
    load_s = time.perf_counter() - t0
    report = {"meshes": tris.stats, "triangles": len(tris), "load_s": round(load_s, 4)}
    if len(tris):
        lo, hi = geometry.triangle_bounds(tris)
        bvh = geometry.build_bvh(lo, hi)
        o = bvh.order
        arr = np.zeros((len(tris), 6, 4), np.float32)
        arr[:, 0, :3], arr[:, 0, 3] = tris.v0[o], _int_bits(tris.material[o])
        arr[:, 1, :3], arr[:, 1, 3] = tris.v1[o], _int_bits(tris.object_id[o])
        arr[:, 2, :3] = tris.v2[o]
        arr[:, 3:6, :3] = tris.normals[o]
        nodes = bvh.nodes
        report.update({"bvh_build_s": round(bvh.build_s, 4), "bvh_nodes": bvh.node_count, "bvh_depth": bvh.depth})
    else:
        arr = np.zeros((0, 6, 4), np.float32)
        nodes = np.zeros((0, 8), np.float32)
    return arr, nodes, report


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
