"""Materials: each G-buffer sample's material resolved from its material's factors and texture
maps (base colour, metallic-roughness, normal, occlusion, emissive) into `gb_mat`, which every
lighting pass reads (kernels/material.cl; twin: iblbake/render/twin/material.py resolve_materials). Runs
only where some material in use has a map: an untextured scene reads its material table."""

from __future__ import annotations

from iblbake.render.passes.base import Buffer, Pass, material_defines


class Materials(Pass):
    name = "material"
    function = "materials"
    kernel = "material.cl"
    buffers = (Buffer("gb_mat", count=3),)     # (base colour, metallic), (emissive, roughness), (normal, occlusion)

    def runs(self, scene, fx):
        return "HAS_TEXTURES" in material_defines(scene)

    def defines(self, scene, fx):
        return material_defines(scene)

    def scene_inputs(self, scene):
        d = scene.data
        return {"materials": d["materials"], "objects": d["objects"]}

    def run(self, ctx):
        s = self.launch_samples(ctx)
        return {"textures": ctx.table["texture_count"], "samples_per_s": round(ctx.table["n"] / max(s, 1e-9))}
