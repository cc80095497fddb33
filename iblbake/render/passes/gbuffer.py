"""G-buffer: the primary hit of every camera sample of the tile (kernels/gbuffer.cl); with
`diffuse: lightmap` (and `specular: lightmap`), where each hit lies in the lightmap's atlas (gb_lm,
kernels/lightmap.h)."""

from __future__ import annotations

from iblbake.render.passes.base import Buffer, Pass, geometry_defines, surface_cuts
from iblbake.render.sources import lightmap


class GBuffer(Pass):
    name = "gbuffer"
    kernel = "gbuffer.cl"
    # the G-buffer (scene/layout.py GBUFFER); a textured scene's surface coordinates too
    buffers = (Buffer("gb_pos"), Buffer("gb_nrm"), Buffer("gb_dir"), Buffer("gb_uv", when="HAS_TEXTURES"),
               Buffer("gb_tan", when="HAS_TEXTURES"), Buffer("gb_lod", when="HAS_TEXTURES"),
               Buffer("gb_lm", when="HAS_LIGHTMAP"))
    params = lightmap.UV_PARAMS

    def defines(self, scene, fx):
        return {**geometry_defines(scene), **(lightmap.uv_defines() if lightmap.reads(fx) else {})}

    def reads_bakes(self, scene, fx):
        return ["lightmap"] if lightmap.reads(fx) else []

    def scene_inputs(self, scene):
        # the materials' names only: hits store material indices, values are resolved later; but
        # what a ray meets depends on cut-outs and sides (alpha masks, single-sided materials)
        d = scene.data
        return {"camera": d["camera"], "objects": d["objects"], "materials": list(d["materials"]),
                "cut": surface_cuts(scene),
                "lightmap": "lightmap" in (d["effects"]["diffuse"], d["effects"]["specular"])}

    def setup(self, ctx):
        return lightmap.uv_args(ctx.rt, ctx.loaded.get("lightmap") if lightmap.reads(ctx.plan.effects) else None,
                                ctx.arrays, ctx.bakes)

    def run(self, ctx):
        n = ctx.table["n"]
        s = self.launch_samples(ctx)
        return {"primary_rays": n, "rays_per_s": round(n / max(s, 1e-9))}
