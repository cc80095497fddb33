"""Reference: progressive Monte Carlo of the exact direct environment lighting, with visibility
(kernels/paths/reference.cl; twin: iblbake/render/twin/reference.py exact), and with
effects.reference.bounces other than 1 the path tracer. The pass declares the program, its defines
and its batching; its samples are a ray source (render/paths/camera.py CameraSamples) run by the
one driver (render/paths/trace.py), whose mean is added into `radiance`. With target_noise 0 (a
fixed budget) no error is estimated and the samples of a G-buffer sample are one sequence instead
of two replicates: 1.07-1.23x less variance at equal samples (kernels/sampler.h sampler_replicate)."""

from __future__ import annotations

import numpy as np

from iblbake.core import sampling
from iblbake.device.launch import sample_slices
from iblbake.render.device_scene import panorama_args
from iblbake.render.passes.base import Buffer, Pass, geometry_defines, mode_defines
from iblbake.render.passes.lights import Lights, frame_lights
from iblbake.render.paths.camera import CameraSamples
from iblbake.render.paths.trace import trace
from iblbake.scene import pack


def environment_args(ctx, dist) -> dict:
    """The frame's panorama and its importance-sampling tables (dist) as reference.cl's arguments,
    uploaded once per runtime and panorama (render/device_scene.py panorama_args)."""
    return panorama_args(ctx.rt, ctx.bakes, ctx.image, dist)


class Reference(Pass):
    name = "reference"
    kernel = "paths/reference.cl"
    params = ("img", "w", "h", "marginal", "conditional", "guide", "env_norm", "seed", "replicates", "first", "batch",
              "slices", "lights", "nlights")
    # radiance, and one batch's sums per sample read back (the host adds them up in float64)
    buffers = (Buffer("radiance"), Buffer("ref_batch"))
    host_sample_bytes = 32
    host_writes = ("radiance",)      # the mean, added on the host
    profiles = "paths"               # render/paths/profile.py

    def runs(self, scene, fx):
        return "reference" in (fx.diffuse, fx.specular)

    def reads_bakes(self, scene, fx):
        return ["env_cdf"]

    def reads_environment(self, scene, fx):
        return True                   # the texels it samples

    def defines(self, scene, fx):
        d = mode_defines(fx)          # reference.cl computes only the reference terms
        if scene.data["effects"]["reference"]["visibility"]:
            d.update(VISIBILITY=1, **geometry_defines(scene))
        if fx.bounces != 1:
            d["BOUNCES"] = fx.bounces     # paths, only where light can pass between surfaces (plan.py)
            if Lights().runs(scene, fx):
                d["PATH_LIGHTS"] = 1      # the lights pass lights the first vertex, paths the others
        return d

    def setup(self, ctx) -> dict:
        rt = ctx.rt
        out = environment_args(ctx, ctx.loaded["env_cdf"])
        recs = np.zeros((0, 4), np.float32)
        if "PATH_LIGHTS" in ctx.plan.defines[self.name]:
            recs = pack.light_records(frame_lights(ctx.scene, ctx.bakes.sun(ctx.scene.data["environment"])))
        out.update(lights=rt.to_device(recs.reshape(-1, 4) if len(recs) else np.zeros((4, 4), np.float32)),
                   nlights=len(recs),
                   replicates=sampling.reference_replicates(ctx.scene.data["effects"]["reference"]["target_noise"]))
        return out

    def batching(self, ctx) -> tuple:
        """(samples per G-buffer sample in a launch, work items per G-buffer sample) of this tile."""
        ref = ctx.scene.data["effects"]["reference"]
        batch = ref["batch"] or (256 if ctx.rt.info.kind == "GPU" else 32)
        batch += batch & 1                            # even: both replicates advance together
        return batch, sample_slices(ctx.rt, ctx.table["n"], batch)

    def batch_args(self, ctx, first: int, b: int, slices: int, out) -> tuple:
        """(global size, arguments) of the launch of samples first .. first + b - 1 (the path
        profile launches the same batches: render/paths/profile.py)."""
        n = ctx.table["n"]
        return (n * min(slices, b),), {**ctx.args[self.name], "seed": ctx.scene.data["effects"]["reference"]["seed"],
                                       "first": first, "batch": b, "slices": min(slices, b), "ref_batch": out}

    def profile(self, ctx, repeats):
        from iblbake.render.paths.profile import REPEATS, profile_reference
        return profile_reference(ctx, self, repeats=REPEATS if repeats is None else repeats)

    def run(self, ctx):
        mean, report = trace(CameraSamples(ctx, self))         # the one driver (render/paths/trace.py)
        # the mean joins what the other lighting passes added
        rt, t, n = ctx.rt, ctx.table, ctx.table["n"]
        out = np.zeros((n, 4), np.float32)
        out[:, :3] = mean.astype(np.float32)
        radiance = rt.read(t["radiance"], (n, 4))
        rt.cl.enqueue_copy(rt.queue, t["radiance"], radiance + out)
        return report
