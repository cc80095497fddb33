"""The panorama's diffuse light from a directional basis (`diffuse:` any of core/bases DIFFUSE:
L1 Geomerics, ZH3, SG, ambient dice, Haar): the `basis` bake's coefficients, packed by the basis, read
by the one header its define selects (kernels/bases.h basis_irradiance); and `specular:` a basis that
carries it, its radiance along the lobe with the split sum's DFG table."""

from __future__ import annotations

import numpy as np

from iblbake.core import bases
from iblbake.render.sources.base import Source


def table_args(rt, name: str | None, opts: dict | None) -> dict:
    """basis_table: the table basis `name` reads its specular weights from (core/bases
    specular_table), a placeholder for one that needs none."""
    t = bases.specular_table(name, opts) if name else None
    return {"basis_table": rt.to_device(t if t is not None else np.zeros(1, np.float32))}


class DirectionalBasis(Source):
    name = "basis"
    header = "bases.h"
    params = ("basis_coeffs", "basis_table")

    def runs(self, scene, fx):
        return fx.diffuse in bases.DIFFUSE

    def _opts(self, scene):
        return bases.options_of(bases.frame_basis(scene.data["effects"]), scene.data["effects"])

    def defines(self, scene, fx):
        return bases.BASES[bases.frame_basis(scene.data["effects"])].defines(self._opts(scene))

    def reads_bakes(self, scene, fx):
        return ["basis"]

    def args(self, ctx):
        name = bases.frame_basis(ctx.scene.data["effects"])
        opts = self._opts(ctx.scene)
        return {"basis_coeffs": ctx.rt.to_device(bases.BASES[name].pack(ctx.loaded["basis"], opts)),
                **table_args(ctx.rt, name, opts)}

    def placeholders(self, rt):
        return {"basis_coeffs": rt.to_device(np.zeros((1, 4), np.float32)), **table_args(rt, None, None)}


class BasisSpecular(DirectionalBasis):
    """`specular: <basis>` (core/bases SPECULAR: sg): the split sum's DFG table times the basis's
    radiance along the warped GGX lobe. It binds the basis's coefficients itself: a frame of
    metals, or the study's specular term alone, has no diffuse term."""
    name = "basis_specular"
    params = ("basis_coeffs", "basis_table", "dfg", "dfg_size")

    def runs(self, scene, fx):
        return fx.specular in bases.SPECULAR

    def reads_bakes(self, scene, fx):
        return ["basis", "dfg"]

    def args(self, ctx):
        from iblbake.render.sources.prefiltered import dfg_args
        return {**super().args(ctx), **dfg_args(ctx.rt, ctx.loaded["dfg"])}

    def placeholders(self, rt):
        from iblbake.render.sources.prefiltered import dfg_args
        return {**super().placeholders(rt), **dfg_args(rt, None)}
