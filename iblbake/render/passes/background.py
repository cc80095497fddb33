"""Background: what samples that hit nothing see (the panorama, a prefiltered level, a colour),
added into `radiance` (kernels/background.cl)."""

from __future__ import annotations

import numpy as np

from iblbake.render.passes.base import Buffer, Pass
from iblbake.scene.layout import BACKGROUND_MODES


class Background(Pass):
    name = "background"
    kernel = "background.cl"
    params = ("color", "lod", "chain", "off", "lw", "lh", "nlev")
    buffers = (Buffer("radiance"),)      # every lighting pass adds into it

    def runs(self, scene, fx):
        return fx.background != "hide"

    def reads_environment(self, scene, fx):
        return fx.background == "show"     # the panorama as it is (blur reads a bake)

    def reads_bakes(self, scene, fx):
        return ["prefiltered"] if fx.background == "blur" else []

    def defines(self, scene, fx):
        return {"BACKGROUND": BACKGROUND_MODES[fx.background]}

    def setup(self, ctx) -> dict:
        env, mode = ctx.scene.data["environment"], ctx.plan.effects.background
        color = np.zeros(4, np.float32)
        lod = 0.0
        if mode == "color":
            color[:3] = env["background"]
            chain = ctx.no_chain()
        elif mode == "blur":
            levels = ctx.loaded["prefiltered"]
            chain, lod = ctx.chain(levels), env["blur"] * (len(levels) - 1)
        else:
            chain = ctx.chain([ctx.background_image])
        return {"color": color, "lod": lod, **chain}

    def run(self, ctx):
        ctx.launch(self, (ctx.table["n"],), **ctx.args[self.name])
        ctx.rt.finish()
        return {}
