"""The scene on the device: its geometry (spheres, planes, triangles and their BVH), materials and
textures as the tables every tracing kernel binds (kernels/scene.h SCENE_PARAMS and `materials`),
put on a runtime's device once per scene content (Bakes.device_scene, memoised as Bakes.on_device
is) and shared by a frame's passes and by the bakes that trace the scene (the irradiance probes,
the reflection captures), so that none of them needs a frame. Beside the tables, what a traced
ray reads of the rest of the scene: the defines saying which primitives and material features
the tables hold, the scene's lights (with the panorama's extracted sun), the panorama with its
importance-sampling tables, and the panorama's frame (rotation, intensity)."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from iblbake.scene.load import Scene

# the scene's part of a kernel's parameters: what DeviceScene.table binds
TABLE = ("spheres", "nspheres", "planes", "nplanes", "bvh", "tris", "ntris", "materials", "tri_attr", "mat_maps",
         "texels", "tex_levels", "tex_info", "texture_count")


@dataclass(eq=False)
class DeviceScene:
    """A scene's tables on one runtime's device.

    arrays: the host records (scene/pack.py SceneArrays) the tables were made from.
    table: TABLE's names -> device buffers and counts, for Runtime.launch.
    key: the digest of everything the tables hold (the memo's key, with the runtime).
    """

    arrays: object
    table: dict
    key: str


def _padded(a, shape):
    return a if a is not None and len(a) else np.zeros(shape, np.float32)


def digest(*arrays, head: str = "") -> str:
    """sha256 of `head` and the arrays' dtypes, shapes and bytes (None: absent)."""
    h = hashlib.sha256(head.encode())
    for a in arrays:
        if a is None:
            h.update(b"|None")
            continue
        a = np.ascontiguousarray(a)
        h.update(f"|{a.dtype}{a.shape}|".encode())
        h.update(memoryview(a).cast("B") if a.size else b"")
    return h.hexdigest()


def geometry_tables(rt, arrays) -> dict:
    """The triangles, BVH and triangle attributes on the device (the large part of a mesh scene): the
    BVH the device's kernels traverse, the 4-wide tree on a CPU, the binary tree elsewhere
    (device/programs.py device_options, WIDE_BVH)."""
    from iblbake.device.programs import WIDE_BVH
    from iblbake.scene.layout import FLOAT4S
    bvh = arrays.bvh_wide if WIDE_BVH in rt.device_options else arrays.bvh.reshape(-1, 4)
    return {"bvh": rt.to_device(_padded(bvh, (1, 4))), "tris": rt.to_device(_padded(arrays.tris, (1, 6, 4))),
            "tri_attr": rt.to_device(_padded(arrays.tri_attr, (1, FLOAT4S["TRIANGLE_ATTR"], 4)))}


def tables(rt, arrays, mat_maps, geometry: dict, textures: tuple, texture_count: int) -> dict:
    """TABLE of a scene: its spheres, planes and materials uploaded here, `geometry` (the device's
    triangles, BVH and attributes) and `textures` (the device's texels, levels and infos) as given."""
    from iblbake.scene.layout import FLOAT4S
    return {"spheres": rt.to_device(_padded(arrays.spheres, (1, 2, 4))), "nspheres": len(arrays.spheres),
            "planes": rt.to_device(_padded(arrays.planes, (1, FLOAT4S["PLANE"], 4))), "nplanes": len(arrays.planes),
            **geometry, "ntris": len(arrays.tris), "materials": rt.to_device(arrays.materials.reshape(-1, 4)),
            "mat_maps": rt.to_device(mat_maps.reshape(-1, 4)),
            **dict(zip(("texels", "tex_levels", "tex_info"), textures)), "texture_count": texture_count}


def environment_frame(env: dict) -> dict:
    """The panorama's rotation about y and intensity, as the kernels that read it bind them."""
    rot = np.radians(env["rotation_y"])
    return {"env_rot": np.array([np.cos(rot), np.sin(rot)], np.float32), "env_scale": env["intensity"]}


def panorama_args(rt, bakes, image, dist) -> dict:
    """The panorama's texels and importance-sampling tables (dist: sampling.EnvironmentDistribution)
    as the named arguments of the kernels that sample it (reference.cl, probe_trace.cl), uploaded
    once per runtime and panorama (a study's references, a volume's and its captures' rays)."""
    from iblbake.bake.radiance import to_rgba

    def upload():
        return {"img": rt.to_device(to_rgba(image)), "marginal": rt.to_device(dist.marginal),
                "conditional": rt.to_device(dist.conditional), "guide": rt.to_device(dist.guide)}
    return {**bakes.on_device(rt, (image, dist.marginal, dist.conditional, dist.guide), upload),
            "w": dist.width, "h": dist.height, "env_norm": dist.norm}


def scene_lights(scene, suns) -> list:
    """The scene's lights, and the lights extracted from the panorama (bake/sun.py: Bakes.sun) as
    directional lights in world space, scaled like the panorama."""
    out = list(scene.data["lights"])
    from iblbake.core import conventions
    env = scene.data["environment"]
    for sun in suns:
        d = conventions.rotate_y(sun.direction, env["rotation_y"])
        out.append({"directional": {"direction": [-x for x in d], "color": sun.color,
                                    "illuminance": sun.illuminance * env["intensity"],
                                    "angular_diameter": sun.angular_diameter},
                    "shadows": env["sun_shadows"], "shadow_samples": env["sun_shadow_samples"]})
    return out


def has_lights(scene) -> bool:
    """Whether the scene has lights: its own, or the panorama's sun extracted as one."""
    return bool(scene.data["lights"]) or scene.data["environment"]["sun"] == "extract"


def geometry_defines(scene: Scene) -> dict:
    """HAS_SPHERES / HAS_PLANES / HAS_TRIANGLES for the primitives the scene has: tracing
    kernels compile only those intersection loops; and the materials' defines, as cut-outs and
    single-sided surfaces change what a ray meets."""
    kinds = {k for o in scene.data["objects"] for k in ("sphere", "plane", "mesh") if k in o}
    return {**{name: 1 for k, name in (("sphere", "HAS_SPHERES"), ("plane", "HAS_PLANES"),
                                       ("mesh", "HAS_TRIANGLES")) if k in kinds}, **material_defines(scene)}


def material_defines(scene: Scene) -> dict:
    """HAS_TEXTURES with a HAS_<KIND>_MAP per map kind in use, HAS_ALPHA_MASK, HAS_SINGLE_SIDED
    (iblbake.scene.materials.defines over the materials some object is shaded with)."""
    from iblbake.scene import materials
    return materials.defines(materials.used(scene))
