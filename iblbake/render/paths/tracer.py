"""The paths from a point (kernels/paths/probe_trace.cl: kernels/paths/paths.h's paths, the reference's): the
Tracer binds that kernel to the scene put on the device once (render/device_scene.py DeviceScene),
its panorama, lights and radiance chain; its ray sources (render/paths/rays.py: the irradiance
probes' rays, render/probes/, and the reflection captures' texels, render/reflection_probes.py)
run through the one driver (render/paths/trace.py), as the camera's samples do
(render/paths/camera.py)."""

from __future__ import annotations

import numpy as np

from iblbake.render.device_scene import environment_frame, geometry_defines, has_lights, panorama_args, scene_lights
from iblbake.render.paths.rays import PROGRAM, PointRays
from iblbake.render.paths.trace import trace


def trace_defines(scene, bounces) -> dict:
    """probe_trace.cl's defines: the scene's primitives and material features, the paths' bounces,
    and PATH_LIGHTS where the scene has lights (they light what the probes see, not the probes)."""
    d = {**geometry_defines(scene), "BOUNCES": 0 if bounces == "unbounded" else bounces + 1}
    if has_lights(scene):
        d["PATH_LIGHTS"] = 1
    return d


class Tracer:
    """Probe rays on a job's device (render/units.py Job: a scene, a runtime, the bake store), against
    the scene on the device (job.device_scene), its panorama (with its importance-sampling tables,
    the env_cdf bake), the radiance chain an escaping ray reads (the radiance bake) and its lights."""

    def __init__(self, job, settings: dict, back_faces_black: bool = True, skip_objects=()):
        from iblbake.scene import pack

        rt = self.rt = job.rt
        scene, bakes = job.scene, job.bakes
        self.job, self.settings, self.back_faces_black = job, settings, back_faces_black
        dist = self.dist = job.read("env_cdf")         # the texels' importance samples too (lightmaps/bake.py)
        self.rotation = scene.data["environment"]["rotation_y"]
        chain = job.read("radiance")       # what an escaping probe ray reads (probe_trace.cl)
        image, _info = job.panorama()
        self.defines = trace_defines(scene, settings["bounces"])
        recs = np.zeros((0, 4), np.float32)
        if "PATH_LIGHTS" in self.defines:
            recs = pack.light_records(scene_lights(scene, bakes.sun(scene.data["environment"])))
        skip = np.zeros(max(len(scene.data["objects"]), 1), np.int32)
        skip[list(skip_objects)] = 1
        self.table = {**job.device_scene.table, **environment_frame(scene.data["environment"])}
        self.args = {**panorama_args(rt, bakes, image, dist), "nlights": len(recs), **bakes.chain(rt, chain),
                     "lights": rt.to_device(recs.reshape(-1, 4) if len(recs) else np.zeros((4, 4), np.float32)),
                     "skip_obj": rt.to_device(skip), "skip": int(bool(len(skip_objects)))}
        self.rays_traced = 0

    def launch(self, global_size, function, **args):
        """Run probe_trace.cl's `function` with the scene's defines, table and bound arguments."""
        return self.rt.launch(PROGRAM, function, self.defines, global_size, self.table, **self.args, **args)

    def trace(self, positions, dirs, shade: bool, progress=None, done=0.0, share=1.0, probe0=0, ray0=0, ids=None):
        """(radiance (probes, rays, 3), signed distance (probes, rays), the object each ray met
        (probes, rays), -1 none) from every position, or from those numbered `ids` alone (theirs, in
        that order); dirs (rays, 3), or (rays, 4) with each ray's share of the sphere in w
        (probe_trace.cl). probe0, ray0: the first probe's and ray's numbers (their random
        streams). The rays are a PointRays source (render/paths/rays.py)."""
        return trace(PointRays(self, positions, dirs, shade, progress, done, share, probe0, ray0, ids))
