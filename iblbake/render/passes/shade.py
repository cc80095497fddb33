"""Shade: the approximate lighting terms, each a lighting source (render/sources/: SH or probe
diffuse; importance, prefiltered or lobe specular, reflection probes, the SSR split), with AO and
emission, added into `radiance` (kernels/shade.cl; twin: iblbake/render/twin/shade.py shade). The
pass composes its sources' declarations: their defines, bakes, arguments and buffers."""

from __future__ import annotations

import numpy as np

from iblbake.render.passes.base import Buffer, Counter, Pass, mode_defines
from iblbake.render.sources import SOURCES
from iblbake.render.sources.lightmap import reads as reads_lightmap


SKY_SAID = 0.1           # the share of a frame's samples with no active probe near (the panorama's SH) said
OUTSIDE_SAID = 0.1       # the share of a frame's samples outside the probe volume that is said
# kernels/shade.cl's probe_stats, in its order: the samples whose cell's probes were all off (the
# nearest probe's or the panorama's light instead), diffuse then specular, those outside the volume,
# and the samples on geometry the diffuse probes shade (the shares said are of these: the
# background's pixels read no probe)
PROBE_STATS = ("probe_fallback_nearest", "probe_fallback_sky", "probe_specular_fallback_nearest",
               "probe_specular_fallback_sky", "probe_outside_volume", "probe_samples")


class Shade(Pass):
    name = "shade"
    kernel = "shade.cl"
    # every lighting pass adds into radiance; each source's own buffers
    buffers = (Buffer("radiance"),) + tuple(b for s in SOURCES for b in s.buffers)
    host_writes = ("probe_stats", "lm_stats")
    # probe_stats summed over the tiles, and the samples they are out of
    counters = (Counter("probe_fallback_nearest", lambda fx: fx.diffuse == "probes"),
                Counter("probe_fallback_sky", lambda fx: fx.diffuse == "probes"),
                Counter("probe_outside_volume", lambda fx: fx.diffuse == "probes"),
                Counter("probe_specular_fallback_nearest", lambda fx: fx.specular == "probes"),
                Counter("probe_specular_fallback_sky", lambda fx: fx.specular == "probes"),
                Counter("probe_samples", lambda fx: fx.diffuse == "probes"),
                # diffuse lightmap: the samples it lit, and those on surfaces without one (kernels/shade.cl lm_stats)
                Counter("lightmap_samples", lambda fx: fx.diffuse == "lightmap"),
                Counter("lightmap_fallback", lambda fx: fx.diffuse == "lightmap"),
                # the same of `specular: lightmap` (its fallback the distant chain)
                Counter("lightmap_specular_samples", lambda fx: fx.specular == "lightmap"),
                Counter("lightmap_specular_fallback", lambda fx: fx.specular == "lightmap"))

    def runs(self, scene, fx):
        return fx.any_approximate or fx.emissive

    def bound_params(self) -> tuple:
        return tuple(dict.fromkeys(p for s in SOURCES for p in s.params))

    def sources(self, scene, fx) -> list:
        return [s for s in SOURCES if s.runs(scene, fx)]

    def reads_bakes(self, scene, fx):
        return list(dict.fromkeys(b for s in self.sources(scene, fx) for b in s.reads_bakes(scene, fx)))

    def defines(self, scene, fx):
        e = scene.data["effects"]
        d = mode_defines(fx)          # shade.cl computes only the terms of its sources
        for s in self.sources(scene, fx):
            d.update(s.defines(scene, fx))
        if fx.emissive:
            d["HAS_EMISSIVE"] = 1
        if e["ao"] != "off" and fx.any_approximate:
            d["HAS_AO"] = 1
            if e["ao_multibounce"] and fx.diffuse in ("sh", "probes"):     # the terms the twin bends too
                d["AO_MULTIBOUNCE"] = 1
        return d

    def setup(self, ctx) -> dict:
        """Per frame (not per tile): every source's arguments, placeholders for those that are off."""
        fx = ctx.plan.effects
        args = {}
        for s in SOURCES:
            args.update(s.placeholders(ctx.rt))
        for s in self.sources(ctx.scene, fx):
            args.update(s.args(ctx))
        return args

    def run(self, ctx):
        n = ctx.table["n"]
        fx = ctx.plan.effects
        probes_in = "probes" in (fx.diffuse, fx.specular)
        if probes_in:
            ctx.rt.cl.enqueue_fill_buffer(ctx.rt.queue, ctx.table["probe_stats"], np.int32(0), 0, 4 * len(PROBE_STATS))
        lightmap = reads_lightmap(fx)
        if lightmap:
            ctx.rt.cl.enqueue_fill_buffer(ctx.rt.queue, ctx.table["lm_stats"], np.int32(0), 0, 16)
        s = self.launch_samples(ctx)
        if lightmap:
            lit, fallback, spec, spec_fallback = ctx.rt.read(ctx.table["lm_stats"], (4,), np.int32).tolist()
            counts = {"lightmap_samples": lit, "lightmap_fallback": fallback} if fx.diffuse == "lightmap" else {}
            if fx.specular == "lightmap":
                counts.update(lightmap_specular_samples=spec, lightmap_specular_fallback=spec_fallback)
            self.count(ctx, **counts)
        lobe = ctx.plan.effects.specular == "lobe"
        k = ctx.args[self.name]["lobe_samples"] if lobe else 1
        extra = {"samples": k} if lobe else {}
        if probes_in:                 # the samples whose cell's probes were all off, summed over tiles
            counts = ctx.rt.read(ctx.table["probe_stats"], (len(PROBE_STATS),), np.int32).tolist()
            tot = self.count(ctx, **dict(zip(PROBE_STATS, counts)))
            last = ctx.tile_index == ctx.tile_count - 1
            if fx.diffuse == "probes":
                sky, outside, samples = tot["probe_fallback_sky"], tot["probe_outside_volume"], tot["probe_samples"]
                # where the bake said the camera's surroundings are finer than the cells, that is the cause
                cause = ctx.loaded["probes"]["report"].get("camera_cramped")
                if last and sky > SKY_SAID * samples and not cause:
                    ctx.warn(f"probes: {100 * sky / samples:.0f}% of the samples on geometry found no active probe "
                             "near them and took the panorama's SH (no light between surfaces there); see the "
                             "bake's report (--report: probes off, by which rule) or give more probes.rays")
                if last and outside > OUTSIDE_SAID * samples:
                    ctx.warn(f"probes: {100 * outside / samples:.0f}% of the samples on geometry lie outside the probe "
                             "volume or on its fading edge and take the panorama's SH there; widen probes.min/max "
                             "(or the scene's bounds) to cover what the camera sees")
        return {"mpixel_samples_per_s": round(n * k / max(s, 1e-9) / 1e6, 2), **extra}
