"""Resolve: each pixel the mean of its samples' radiance, alpha its coverage, and the AOVs
(kernels/resolve.cl); read back into the frame's rows of this tile."""

from __future__ import annotations

from iblbake.render.passes.base import Buffer, Pass

from iblbake.scene.load import AOVS


class Resolve(Pass):
    name = "resolve"
    kernel = "resolve.cl"
    # radiance: read even where no lighting pass runs (both terms off, background hidden: zeros)
    buffers = (Buffer("radiance"), Buffer("hdr", per="pixel"), Buffer("aov_normal", per="pixel", when="WRITE_AOVS"),
               Buffer("aov_albedo", per="pixel", when="WRITE_AOVS"),
               Buffer("aov_depth", "float", per="pixel", when="WRITE_AOVS"),
               Buffer("aov_object", "float", per="pixel", when="WRITE_AOVS"))

    fills = ("hdr", "aovs")

    def defines(self, scene, fx):
        return {"WRITE_AOVS": 1} if any(scene.data["output"][a] for a in AOVS) else {}

    def scene_inputs(self, scene):
        return {**super().scene_inputs(scene), "aovs": [a for a in AOVS if scene.data["output"][a]]}

    def run(self, ctx):
        t = ctx.table
        ctx.launch(self, (t["npix"],))
        rows = ctx.tile_rows
        sl = slice(ctx.row0, ctx.row0 + rows)
        ctx.rt.read_into(t["hdr"], ctx.frame_hdr[sl])        # whole rows: contiguous
        if "WRITE_AOVS" in ctx.plan.defines[self.name]:
            for a in AOVS:
                ctx.rt.read_into(t[f"aov_{a}"], ctx.frame_aovs[a][sl])
        return {}
