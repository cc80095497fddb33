"""The split for screen-space reflections: the split sum writes the reflected environment's weight
and radiance per sample (ssr_env), which the ssr pass (passes/ssr.py) replaces where its rays meet
the frame. Kernel: kernels/ssr_split.h ssr_split."""

from __future__ import annotations

from iblbake.render.buffers import Buffer
from iblbake.render.sources.base import Source


def screen_space(scene, fx) -> bool:
    """Whether screen-space reflections run: over the split sum's environment (and probes)."""
    return fx.specular == "prefiltered" and scene.data["effects"]["ssr"] == "on"


class ScreenSpaceSplit(Source):
    name = "ssr"
    header = "ssr_split.h"
    buffers = (Buffer("ssr_env", count=2, when="HAS_SSR"),)

    def runs(self, scene, fx):
        return screen_space(scene, fx)

    def defines(self, scene, fx):
        return {"HAS_SSR": 1}
