"""The split for screen-space reflections: the split sum writes the reflected environment's weight
and radiance per sample (ssr_env), which the ssr pass (passes/ssr.py) replaces where its rays meet
the frame. Kernel: kernels/ssr_split.h ssr_split."""

from __future__ import annotations

import numpy as np

from iblbake.render.buffers import Buffer
from iblbake.render.sources.base import Source


def screen_space(scene, fx) -> bool:
    """Whether screen-space reflections run: over the split sum's environment (and probes)."""
    return fx.specular == "prefiltered" and scene.data["effects"]["ssr"] == "on"


def extent(arrays, cam: dict) -> float | None:
    """The scene's extent for SSR's auto lengths: the diagonal of the bounds of its geometry (the
    probes' grid's) and the camera; None where nothing is bounded (only infinite planes)."""
    from iblbake.render.probes import scene_bounds
    from iblbake.scene import pack

    b = scene_bounds(arrays)
    if b is None:
        return None
    eye = np.asarray(pack.camera_vectors(cam)[0], np.float64)
    lo, hi = np.minimum(b[0], eye), np.maximum(b[1], eye)
    e = float(np.linalg.norm(hi - lo))
    return e if np.isfinite(e) and e > 0 else None


# auto where nothing is bounded: the unit scene's numbers
UNBOUNDED = {"thickness": 0.1, "ray_length": 50.0}


def march_lengths(settings: dict, arrays, cam: dict) -> dict:
    """ssr_settings.thickness and ray_length in scene units: a number as given, auto from the
    scene's extent E (so that a scene scaled by s gives the same frame): thickness 1% of E, and
    ray_length E (a ray from inside the bounds leaves them within E; only an infinite plane lies
    further)."""
    e = None
    out = {}
    for key, share in (("thickness", 0.01), ("ray_length", 1.0)):
        v = settings[key]
        if v == "auto":
            e = extent(arrays, cam) if e is None else e
            v = UNBOUNDED[key] if e is None else share * e
        out[key] = float(v)
    return out


class ScreenSpaceSplit(Source):
    name = "ssr"
    header = "ssr_split.h"
    buffers = (Buffer("ssr_env", count=2, when="HAS_SSR"),)

    def runs(self, scene, fx):
        return screen_space(scene, fx)

    def defines(self, scene, fx):
        return {"HAS_SSR": 1}
