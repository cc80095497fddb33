"""Spherical-harmonic irradiance of the panorama (`diffuse: sh`; the light outside the irradiance
probes' volume and where no probe is near, and on what has no lightmap). Kernel: kernels/sh.h sh_irradiance."""

from __future__ import annotations

import numpy as np

from iblbake.render.sources.base import Source


class SphericalHarmonics(Source):
    name = "sh"
    header = "sh.h"
    params = ("sh_coeffs",)

    def runs(self, scene, fx):
        return fx.diffuse in ("sh", "probes", "lightmap")

    def defines(self, scene, fx):
        return {"SH_BANDS": scene.data["effects"]["sh_bands"]}

    def reads_bakes(self, scene, fx):
        return ["sh"]

    def args(self, ctx):
        return {"sh_coeffs": ctx.rt.to_device(np.pad(ctx.loaded["sh"], ((0, 0), (0, 1))).astype(np.float32))}

    def placeholders(self, rt):
        return {"sh_coeffs": rt.to_device(np.zeros((1, 4), np.float32))}
