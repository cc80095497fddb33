"""The renderer: plan (the effect set), passes (one module each, with its kernel), frame (the
context, tiles and outputs), bakes (what passes read), twin (the numpy renderer)."""

from iblbake.render.bakes import Bakes
from iblbake.render.frame import Frame, Reuse, output_paths, render, write_outputs
from iblbake.render.plan import lighting_passes, plan

__all__ = ["Bakes", "Frame", "Reuse", "lighting_passes", "output_paths", "plan", "render", "write_outputs"]
