"""The split sum (`specular: prefiltered`, Karis 2013): the prefiltered chain at the (dominant)
reflected direction times the DFG table's F0 A + F90 B. Kernel: kernels/split_sum.h."""

from __future__ import annotations

import numpy as np

from iblbake.render.sources.base import Source

CHAIN = ("chain", "off", "lw", "lh", "nlev")


def dfg_args(rt, table) -> dict:
    dfg = table.astype(np.float32) if table is not None else np.zeros((2, 2, 2), np.float32)
    return {"dfg": rt.to_device(dfg.reshape(-1, 2)), "dfg_size": dfg.shape[0]}


def no_chain(rt) -> dict:
    z = rt.to_device(np.zeros(4, np.int32))
    return {"chain": rt.to_device(np.zeros(4, np.float32)), "off": z, "lw": z, "lh": z, "nlev": 1}


def split_sum_defines(scene) -> dict:
    """The split sum's own define: the chain read along the dominant direction where asked."""
    return {"DOMINANT_DIRECTION": 1} if scene.data["effects"]["prefilter"]["dominant_direction"] else {}


def split_sum_args(ctx) -> dict:
    """The split sum's arguments: the prefiltered chain and the DFG table (what `specular:
    prefiltered` binds, and the probes' and the lightmap's lobes beside it)."""
    return {**ctx.chain(ctx.loaded["prefiltered"]), **dfg_args(ctx.rt, ctx.loaded["dfg"])}


class SplitSum(Source):
    name = "prefiltered"
    header = "split_sum.h"
    params = CHAIN + ("dfg", "dfg_size")

    def runs(self, scene, fx):
        return fx.specular == "prefiltered"

    def defines(self, scene, fx):
        return split_sum_defines(scene)

    def reads_bakes(self, scene, fx):
        return ["prefiltered", "dfg"]

    def args(self, ctx):
        return split_sum_args(ctx)

    def placeholders(self, rt):
        return {**no_chain(rt), **dfg_args(rt, None)}
