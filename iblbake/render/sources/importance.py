"""Importance-sampled specular (`specular: importance`): the importance pass's two sums per sample
(passes/importance.py), combined here with the sample's f0 and f90. Kernel: kernels/importance.h
importance_specular."""

from __future__ import annotations

from iblbake.render.sources.base import Source


class ImportanceSampled(Source):
    name = "importance"
    header = "importance.h"

    def runs(self, scene, fx):
        return fx.specular == "importance"
