"""The lobe (`specular: lobe`): the split sum's chain and DFG table read along K visible-normal
samples of the real lobe. Kernel: kernels/lobe.h lobe_specular."""

from __future__ import annotations

import numpy as np

from iblbake.core import sampling
from iblbake.render.sources.base import Source
from iblbake.render.sources.prefiltered import CHAIN, dfg_args, no_chain


class Lobe(Source):
    name = "lobe"
    header = "lobe.h"
    params = CHAIN + ("dfg", "dfg_size", "lobe_pts", "lobe_samples", "lobe_spread")

    def runs(self, scene, fx):
        return fx.specular == "lobe"

    def reads_bakes(self, scene, fx):
        return ["prefiltered", "dfg"]

    def args(self, ctx):
        lobe = ctx.scene.data["effects"]["lobe"]
        pts = np.zeros((lobe["samples"], 4), np.float32)
        pts[:, :2] = sampling.lobe_points(lobe["samples"])          # (u1, u2): sample_ggx_vndf
        return {**ctx.chain(ctx.loaded["prefiltered"]), **dfg_args(ctx.rt, ctx.loaded["dfg"]),
                "lobe_pts": ctx.rt.to_device(pts), "lobe_samples": lobe["samples"], "lobe_spread": lobe["spread"]}

    def placeholders(self, rt):
        return {**no_chain(rt), **dfg_args(rt, None), "lobe_pts": rt.to_device(np.zeros((1, 4), np.float32)),
                "lobe_samples": 1, "lobe_spread": 1.0}
