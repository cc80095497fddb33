"""The paths from a point (kernels/paths/probe_trace.cl: kernels/paths/paths.h's paths, the reference's): the
Tracer traces rays from positions against the scene put on the device once (render/device_scene.py
DeviceScene) with its panorama, lights and radiance chain. Its ray sources: the irradiance
probes' rays (render/probes/) and the reflection captures' texels (render/reflection_probes.py);
the camera's G-buffer samples are the reference pass's (render/passes/reference.py)."""

from __future__ import annotations

import numpy as np

from iblbake.device.launch import whole_units
from iblbake.render.device_scene import environment_frame, geometry_defines, has_lights, panorama_args, scene_lights


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
        dist = job.read("env_cdf")
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

    def trace(self, positions, dirs, shade: bool, progress=None, done=0.0, share=1.0, probe0=0, ray0=0):
        """(radiance (probes, rays, 3), signed distance (probes, rays), the object each ray met
        (probes, rays), -1 none) from every position; dirs (rays, 3), or (rays, 4) with each ray's
        share of the sphere in w (probe_trace.cl). probe0, ray0: the first probe's and ray's
        numbers (their random streams)."""
        rt, n, nrays = self.rt, len(positions), len(dirs)
        pos = rt.to_device(np.pad(np.asarray(positions, np.float32), ((probe0, 0), (0, 1))))
        dirs = np.asarray(dirs, np.float32)
        dir_buf = rt.to_device(dirs if dirs.shape[1] == 4 else np.pad(dirs, ((0, 0), (0, 1))))
        per = whole_units(rt, nrays)           # whole probes per launch (device/launch.py)
        out = np.empty((n, nrays, 4), np.float32)
        obj = np.empty((n, nrays), np.int32)
        buf = rt.empty(16 * min(n, per) * nrays)
        obj_buf = rt.empty(4 * min(n, per) * nrays)
        for first in range(0, n, per):
            count = min(per, n - first)
            rt.launch("paths/probe_trace.cl", "probe_trace", self.defines, (count * nrays,), self.table, **self.args,
                      probe_pos=pos, ray_dirs=dir_buf, nrays=nrays, first=probe0 + first, count=count, ray0=ray0,
                      ray_solid_angle=4 * np.pi / nrays,
                      seed=self.settings["seed"], shade=int(shade), back_faces_black=int(self.back_faces_black),
                      ray_out=buf, ray_obj=obj_buf)
            out[first:first + count] = rt.read(buf, (count * nrays, 4)).reshape(count, nrays, 4)
            obj[first:first + count] = rt.read(obj_buf, (count * nrays,), np.int32).reshape(count, nrays)
            if progress:
                progress(done + share * (first + count) / n)
        self.rays_traced += n * nrays
        return out[..., :3].astype(np.float64), out[..., 3].astype(np.float64), obj

