"""Ground-truth ambient occlusion (effects.ao: gtao; Jimenez et al. 2016): the screen-space
horizon search over the frame's depth buffer (kernels/gtao.cl; twin: iblbake/render/twin/gtao.py)
into `ao_buf`, one value per G-buffer sample, which the shade pass applies to the approximate IBL."""

from __future__ import annotations

from dataclasses import dataclass

from iblbake.render.passes.base import Buffer, Pass


GTAO_LEVELS = 5       # kernels/gtao.cl: the position pyramid's levels beyond the full frame


def pyramid_texels(w: int, h: int) -> int:
    return sum(-(-w // (1 << k)) * -(-h // (1 << k)) for k in range(1, GTAO_LEVELS + 1))


def gtao_step(g: dict) -> int:
    """Pixels per side of the blocks gtao searches once (effects.gtao.resolution)."""
    return {"full": 1, "half": 2}[g["resolution"]]


def _blocks(d: dict) -> int:
    w, h = d["camera"]["resolution"]
    step = gtao_step(d["effects"]["gtao"])
    return -(-w // step) * -(-h // step)


@dataclass
class DepthBuffer:
    """The depth buffer gtao searches, chosen at the frame's first tile (its kernels' arguments):
    the G-buffer's first samples (a stride of spp) or a tiled frame's whole-frame prepass (1)."""
    ao_pos: object = None
    ao_nrm: object = None
    ao_dir: object = None
    ao_stride: int = 0


class GroundTruthAO(Pass):
    """effects.ao: gtao. Per frame (at its first tile) the raw value of every pixel from the
    depth buffer, then per tile each sample's denoised value. The depth buffer is the G-buffer
    itself (each pixel's first sample) when the frame is one tile; a tiled frame first traces
    one sample per pixel over the whole frame with the G-buffer kernel (the same first sample),
    so tiles see their neighbours and the frame equals its untiled render."""
    name = "gtao"
    kernel = "gtao.cl"
    params = ("ao_stride", "ao_radius", "gtao_slices", "gtao_steps", "gtao_radius_scale", "gtao_falloff", "gtao_power",
              "gtao_step", "gtao_denoise_radius")
    functions = ("gtao_pyramid", "gtao_denoise")
    keeps = DepthBuffer
    buffers = (Buffer("ao_buf", "float"),
               # the raw value of every block of pixels, and the position pyramid
               Buffer("gtao_raw", "float", per="frame", count=lambda d: _blocks(d)),
               Buffer("gtao_levels", per="frame", count=lambda d: pyramid_texels(*d["camera"]["resolution"])),
               # a tiled frame's depth buffer: one sample per pixel over the whole frame
               *(Buffer(b, per="frame", count=lambda d: d["camera"]["resolution"][0] * d["camera"]["resolution"][1],
                        when="TILED") for b in ("ao_pos", "ao_nrm", "ao_dir")))

    def runs(self, scene, fx):
        return scene.data["effects"]["ao"] == "gtao" and fx.any_approximate

    def defines(self, scene, fx):
        return {"GTAO_LEVELS": GTAO_LEVELS}

    def scene_inputs(self, scene):
        d = scene.data
        return {"camera": d["camera"], "objects": d["objects"],
                "ao": {k: d["effects"][k] for k in ("ao", "ao_radius", "gtao")}}

    def setup(self, ctx) -> dict:
        e = ctx.scene.data["effects"]
        g = e["gtao"]
        return {"ao_radius": e["ao_radius"], "gtao_slices": g["slices"], "gtao_steps": g["steps"],
                "gtao_radius_scale": g["radius_scale"], "gtao_falloff": g["falloff"], "gtao_power": g["power"],
                "gtao_denoise_radius": g["denoise"], "gtao_step": gtao_step(g)}

    def run(self, ctx):
        args, t = ctx.args[self.name], ctx.table
        depth = self.kept(ctx)
        w, h = t["width"], t["height"]
        if ctx.tile_index == 0:
            if ctx.tile_count > 1:      # the whole frame's first samples, as the G-buffer traces them
                from iblbake.render.passes.gbuffer import GBuffer
                from iblbake.render.sources import lightmap
                gb = GBuffer()
                # its lightmap tables, and a frame-sized gb_lm where it writes one (GTAO reads none)
                lm = {"gb_lm": ctx.rt.empty(16 * w * h)} if lightmap.reads(ctx.plan.effects) else {}
                ctx.launch(gb, (w * h,), spp=1, pixel0=0, n=w * h, gb_pos=t["ao_pos"], gb_nrm=t["ao_nrm"],
                           gb_dir=t["ao_dir"], **(ctx.args.get(gb.name) or gb.setup(ctx)), **lm)
                depth.ao_pos, depth.ao_nrm, depth.ao_dir, depth.ao_stride = t["ao_pos"], t["ao_nrm"], t["ao_dir"], 1
            else:
                depth.ao_pos, depth.ao_nrm, depth.ao_dir, depth.ao_stride = (t["gb_pos"], t["gb_nrm"], t["gb_dir"],
                                                                             t["spp"])
            step = args["gtao_step"]
            ctx.launch(self, (pyramid_texels(w, h),), function="gtao_pyramid", width=w, height=h,
                       ao_pos=depth.ao_pos, ao_stride=depth.ao_stride)
            ctx.launch(self, (-(-w // step) * -(-h // step),), **args, **vars(depth))
        ctx.launch(self, (t["n"],), function="gtao_denoise", **args, **vars(depth))
        ctx.rt.finish()
        g = ctx.scene.data["effects"]["gtao"]
        return {"slices": g["slices"], "steps": g["steps"], "denoise": g["denoise"], "resolution": g["resolution"],
                "depth_prepass": ctx.tile_count > 1}
