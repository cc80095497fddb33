"""Ambient occlusion (effects.ao: raytraced): cosine-weighted visibility within ao_radius per
G-buffer sample, into `ao_buf`, which the shade pass applies to the IBL (kernels/ao.cl; twin:
iblbake/render/twin.py ambient_occlusion)."""

from __future__ import annotations

from iblbake.render.passes.base import Pass, geometry_defines


class AmbientOcclusion(Pass):
    name = "ao"
    kernel = "ao.cl"
    reads = ("gb_pos", "gb_nrm", "gb_dir", "spheres", "planes", "bvh", "tris")
    writes = ("ao_buf",)

    def runs(self, scene, fx):
        # it occludes the approximate IBL terms; the reference traces true visibility instead
        return scene.data["effects"]["ao"] == "raytraced" and (
            fx.diffuse == "sh" or fx.specular in ("importance", "prefiltered", "lobe"))

    def defines(self, scene, fx):
        return geometry_defines(scene)

    def scene_inputs(self, scene):
        d = scene.data
        return {"camera": d["camera"], "objects": d["objects"],
                "ao": {k: d["effects"][k] for k in ("ao", "ao_radius", "ao_samples")},
                "seed": d["effects"]["reference"]["seed"]}

    def setup(self, ctx) -> dict:
        e = ctx.scene.data["effects"]
        return {"ao_seed": e["reference"]["seed"] ^ 0x5A0, "ao_samples": e["ao_samples"], "ao_radius": e["ao_radius"]}

    def run(self, ctx):
        n = ctx.table["n"]
        s = self.launch_samples(ctx)
        k = ctx.args[self.name]["ao_samples"]
        return {"rays_per_sample": k, "rays_per_s": round(n * k / max(s, 1e-9))}
