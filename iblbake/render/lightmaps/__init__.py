"""Lightmaps of a scene's static geometry: uv.py the second UV set (TEXCOORD_1, else xatlas) and the
texels it gives; bake.py the texels traced by the path tracer (kernels/paths/lightmap_trace.cl) into an
irradiance atlas and one of a basis (bases.py: L1 SH, or any coefficient basis of the probes'
registry), dilated. docs/manual.md 'Lightmaps'."""

from iblbake.render.lightmaps.bake import BASES, bake, dilate, sh_irradiance
from iblbake.render.lightmaps.bases import NAMES
from iblbake.render.lightmaps.uv import Layout, Texels, layout, texels

__all__ = ["BASES", "NAMES", "Layout", "Texels", "bake", "dilate", "layout", "sh_irradiance", "texels"]
