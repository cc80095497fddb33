"""The panorama's diffuse light from a directional basis (`diffuse:` any of core/bases DIFFUSE:
L1 Geomerics, ZH3, SG, ambient dice, Haar): the `basis` bake's coefficients, packed by the basis, read
by the one header its define selects (kernels/bases.h basis_irradiance)."""

from __future__ import annotations

import numpy as np

from iblbake.core import bases
from iblbake.render.sources.base import Source


class DirectionalBasis(Source):
    name = "basis"
    header = "bases.h"
    params = ("basis_coeffs",)

    def runs(self, scene, fx):
        return fx.diffuse in bases.DIFFUSE

    def _opts(self, scene):
        return bases.options_of(scene.data["effects"]["diffuse"], scene.data["effects"])

    def defines(self, scene, fx):
        return bases.BASES[fx.diffuse].defines(self._opts(scene))

    def reads_bakes(self, scene, fx):
        return ["basis"]

    def args(self, ctx):
        m = bases.BASES[ctx.scene.data["effects"]["diffuse"]]
        return {"basis_coeffs": ctx.rt.to_device(m.pack(ctx.loaded["basis"], self._opts(ctx.scene)))}

    def placeholders(self, rt):
        return {"basis_coeffs": rt.to_device(np.zeros((1, 4), np.float32))}
