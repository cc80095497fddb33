"""Importance: the importance-sampled specular integral (kernels/importance.cl), split
around Schlick's Fresnel into two sums per sample (`spec_sums`) that the shade pass combines with
f0. Its reuse key leaves out what changes only f0 (base colour, metallic): a sheet's metallic or
colour axis samples the panorama once per roughness, and a single frame computes the same two
sums, so a sheet's cell equals its frame bit for bit (twin: iblbake/render/twin/shade.py shade)."""

from __future__ import annotations

import numpy as np

from iblbake.core import sampling
from iblbake.render.passes.base import Buffer, Pass, lighting_inputs, mode_defines

# material keys that change only f0 = mix(0.04 x specular_color x specular, base_color, metallic),
# f90 = mix(specular, 1, metallic) (and the diffuse weight, which the shade pass computes): the two
# sums do not read them
FRESNEL_ONLY = ("base_color", "metallic", "specular", "specular_color")


class Importance(Pass):
    name = "importance"
    kernel = "importance.cl"
    params = ("chain", "off", "lw", "lh", "nlev", "hammersley_pts", "nsamples", "mip_bias")
    buffers = (Buffer("spec_sums", count=2),)     # the two sums per sample

    def runs(self, scene, fx):
        return fx.specular == "importance"

    def reads_bakes(self, scene, fx):
        return ["radiance"]

    def defines(self, scene, fx):
        e = scene.data["effects"]
        d = {"SPECULAR_MODE": mode_defines(fx)["SPECULAR_MODE"]}
        if e["force_mip0"]:
            d["FORCE_MIP0"] = 1
        if e["normalize"] == "accepted":
            d["IMPORTANCE_ACCEPTED"] = 1
        return d

    def scene_inputs(self, scene):
        inputs = lighting_inputs(scene)
        inputs["materials"] = {name: {k: v for k, v in m.items() if k not in FRESNEL_ONLY}
                               for name, m in inputs["materials"].items()}
        return inputs

    def setup(self, ctx) -> dict:
        """Per frame: the radiance chain and the Hammersley points as (cos phi, sin phi, u1)
        (sample_ggx_half_cs)."""
        nsamp = ctx.scene.data["effects"]["samples"]
        pts = sampling.hammersley(nsamp)
        ham = np.zeros((nsamp, 4), np.float32)
        ham[:, 0], ham[:, 1], ham[:, 2] = np.cos(2 * np.pi * pts[:, 0]), np.sin(2 * np.pi * pts[:, 0]), pts[:, 1]
        return {**ctx.chain(ctx.loaded["radiance"]), "hammersley_pts": ctx.rt.to_device(ham), "nsamples": nsamp,
                "mip_bias": ctx.scene.data["effects"]["mip_bias"]}

    def run(self, ctx):
        n, nsamp = ctx.table["n"], ctx.args[self.name]["nsamples"]
        s = self.launch_samples(ctx)
        return {"samples": nsamp, "mpixel_samples_per_s": round(n * nsamp / max(s, 1e-9) / 1e6, 2)}
