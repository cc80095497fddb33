"""Tone map: exposure, operator and display encoding into 8 bits (kernels/tonemap.cl), only when
a PNG frame is written."""

from __future__ import annotations

from iblbake.render.passes.base import DISPLAY_KEYS, Buffer, Pass
from iblbake.scene.layout import TONEMAP_IDS


class Tonemap(Pass):
    name = "tonemap"
    kernel = "tonemap.cl"
    params = ("exposure_scale", "gamma")
    function = "tonemap_u8"
    program = "tonemap"      # its own: exposure and operator sweeps reuse the frame program
    buffers = (Buffer("png_u8", "uchar4", per="pixel"), Buffer("display", per="pixel"))

    fills = ("png",)

    def runs(self, scene, fx):
        return any(p.lower().endswith(".png") for p in scene.data["output"]["frame"])

    def defines(self, scene, fx):
        e = scene.data["effects"]
        d = {"TONEMAP": TONEMAP_IDS[e["tonemap"]], "OUTPUT_SRGB": int(e["output_transfer"] == "srgb")}
        if scene.data["output"]["dither"]:
            d["DITHER"] = 1
        return d

    def scene_inputs(self, scene):
        e = scene.data["effects"]
        return {**{k: e[k] for k in DISPLAY_KEYS}, "dither": scene.data["output"]["dither"]}

    def run(self, ctx):
        t, e = ctx.table, ctx.scene.data["effects"]
        ctx.launch(self, (t["npix"],), exposure_scale=2.0 ** e["exposure"], gamma=e["gamma"], n=t["npix"])
        ctx.rt.read_into(t["png_u8"], ctx.frame_png[ctx.row0:ctx.row0 + ctx.tile_rows])   # RGBA rows
        return {"operator": e["tonemap"]}
