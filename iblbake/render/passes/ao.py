"""Ambient occlusion into `ao_buf` (one value per G-buffer sample), which the shade pass applies
to the IBL: `raytraced` (cosine-weighted visibility within ao_radius through the BVH,
kernels/ao.cl; twin: iblbake/render/twin.py ambient_occlusion) or `gtao` (the screen-space
horizon method over the frame's depth buffer, kernels/gtao.cl; twin: twin.gtao, gtao_denoise)."""

from __future__ import annotations

from iblbake.render.passes.base import Pass, geometry_defines, surface_cuts


def occludes_ibl(fx) -> bool:
    """AO occludes the approximate IBL terms; the reference traces true visibility instead."""
    return fx.diffuse == "sh" or fx.specular in ("importance", "prefiltered", "lobe")


class AmbientOcclusion(Pass):
    name = "ao"
    kernel = "ao.cl"
    reads = ("gb_pos", "gb_nrm", "gb_dir", "spheres", "planes", "bvh", "tris")
    writes = ("ao_buf",)

    def runs(self, scene, fx):
        return scene.data["effects"]["ao"] == "raytraced" and occludes_ibl(fx)

    def defines(self, scene, fx):
        return geometry_defines(scene)

    def scene_inputs(self, scene):
        d = scene.data
        return {"camera": d["camera"], "objects": d["objects"], "cut": surface_cuts(scene),
                "ao": {k: d["effects"][k] for k in ("ao", "ao_radius", "ao_samples")},
                "seed": d["effects"]["reference"]["seed"]}

    def setup(self, ctx) -> dict:
        e = ctx.scene.data["effects"]
        return {"ao_seed": e["reference"]["seed"] ^ 0x5A0, "ao_samples": e["ao_samples"], "ao_radius": e["ao_radius"]}

    def run(self, ctx):
        n = ctx.table["n"]
        s = self.launch_samples(ctx)
        k = ctx.args[self.name]["ao_samples"]
        return {"rays_per_sample": k, "rays_per_s": round(n * k / max(s, 1e-9))}


GTAO_LEVELS = 5       # kernels/gtao.cl: the position pyramid's levels beyond the full frame


def pyramid_texels(w: int, h: int) -> int:
    return sum(-(-w // (1 << k)) * -(-h // (1 << k)) for k in range(1, GTAO_LEVELS + 1))


def gtao_step(g: dict) -> int:
    """Pixels per side of the blocks gtao searches once (effects.gtao.resolution)."""
    return {"full": 1, "half": 2}[g["resolution"]]


class GroundTruthAO(Pass):
    """effects.ao: gtao. Per frame (at its first tile) the raw value of every pixel from the
    depth buffer, then per tile each sample's denoised value. The depth buffer is the G-buffer
    itself (each pixel's first sample) when the frame is one tile; a tiled frame first traces
    one sample per pixel over the whole frame with the G-buffer kernel (the same first sample),
    so tiles see their neighbours and the frame equals its untiled render."""
    name = "gtao"
    kernel = "gtao.cl"
    reads = ("cam", "gb_pos", "gb_nrm", "gb_dir")
    writes = ("ao_buf",)

    def runs(self, scene, fx):
        return scene.data["effects"]["ao"] == "gtao" and occludes_ibl(fx)

    def defines(self, scene, fx):
        return {"GTAO_LEVELS": GTAO_LEVELS}

    def scene_inputs(self, scene):
        d = scene.data
        return {"camera": d["camera"], "objects": d["objects"],
                "ao": {k: d["effects"][k] for k in ("ao", "ao_radius", "gtao")}}

    def setup(self, ctx) -> dict:
        e = ctx.scene.data["effects"]
        g = e["gtao"]
        w, h = ctx.scene.data["camera"]["resolution"]
        step = gtao_step(g)
        return {"ao_radius": e["ao_radius"], "gtao_slices": g["slices"], "gtao_steps": g["steps"],
                "gtao_radius_scale": g["radius_scale"], "gtao_falloff": g["falloff"], "gtao_power": g["power"],
                "gtao_denoise_radius": g["denoise"], "gtao_step": step,
                "gtao_raw": ctx.rt.empty(-(-w // step) * -(-h // step) * 4),
                "gtao_levels": ctx.rt.empty(pyramid_texels(w, h) * 16)}

    def run(self, ctx):
        args, t = ctx.args[self.name], ctx.table
        w, h = t["width"], t["height"]
        if ctx.tile_index == 0:
            if ctx.tile_count > 1:      # the whole frame's first samples, as the G-buffer traces them
                depth = {k: ctx.rt.empty(w * h * 16) for k in ("ao_pos", "ao_nrm", "ao_dir")}
                gbuffer = next(p for p in ctx.plan.passes if p.name == "gbuffer")
                ctx.launch(gbuffer, (w * h,), spp=1, pixel0=0, n=w * h, gb_pos=depth["ao_pos"],
                           gb_nrm=depth["ao_nrm"], gb_dir=depth["ao_dir"])
                args.update(depth, ao_stride=1)
            else:
                args.update(ao_pos=t["gb_pos"], ao_nrm=t["gb_nrm"], ao_dir=t["gb_dir"], ao_stride=t["spp"])
            step = args["gtao_step"]
            ctx.launch(self, (pyramid_texels(w, h),), function="gtao_pyramid", width=w, height=h,
                       ao_pos=args["ao_pos"], ao_stride=args["ao_stride"], gtao_levels=args["gtao_levels"])
            ctx.launch(self, (-(-w // step) * -(-h // step),), **args)
        ctx.launch(self, (t["n"],), function="gtao_denoise", **args)
        ctx.rt.finish()
        g = ctx.scene.data["effects"]["gtao"]
        return {"slices": g["slices"], "steps": g["steps"], "denoise": g["denoise"], "resolution": g["resolution"],
                "depth_prepass": ctx.tile_count > 1}
