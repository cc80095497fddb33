"""Ray-traced ambient occlusion (effects.ao: raytraced) into `ao_buf`, one value per G-buffer
sample, which the shade pass applies to the approximate IBL: cosine-weighted visibility within
ao_radius through the BVH (kernels/ao.cl; twin: iblbake/render/twin/ao.py). The screen-space
method is the gtao pass (render/passes/gtao.py)."""

from __future__ import annotations

from iblbake.render.passes.base import Buffer, Pass, geometry_defines, surface_cuts


class AmbientOcclusion(Pass):
    name = "ao"
    kernel = "ao.cl"
    params = ("ao_seed", "ao_samples", "ao_radius")
    buffers = (Buffer("ao_buf", "float"),)

    def runs(self, scene, fx):
        return scene.data["effects"]["ao"] == "raytraced" and fx.any_approximate

    def defines(self, scene, fx):
        return geometry_defines(scene)

    def scene_inputs(self, scene):
        d = scene.data
        return {"camera": d["camera"], "objects": d["objects"], "cut": surface_cuts(scene),
                "ao": {k: d["effects"][k] for k in ("ao", "ao_radius", "ao_samples")},
                "seed": d["effects"]["reference"]["seed"]}

    def setup(self, ctx) -> dict:
        e = ctx.scene.data["effects"]
        return {"ao_seed": e["reference"]["seed"], "ao_samples": e["ao_samples"], "ao_radius": e["ao_radius"]}

    def run(self, ctx):
        n = ctx.table["n"]
        s = self.launch_samples(ctx)
        k = ctx.args[self.name]["ao_samples"]
        return {"rays_per_sample": k, "rays_per_s": round(n * k / max(s, 1e-9))}
