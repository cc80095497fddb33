"""SSR: stochastic screen-space reflections over the split sum's environment (and the reflection
probes'), after the lighting passes (kernels/ssr.cl; twin: iblbake/render/twin/ssr.py). Its rays
read the whole frame, so it is a whole-frame pass (render/frame.py): every tile's first samples are
gathered before any ray is marched, and a tiled frame gives the pixels an untiled one does."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from iblbake.render.passes.base import Buffer, Pass
from iblbake.render.sources.reflection_probes import reflects_locally, rprobe_args
from iblbake.render.sources.ssr import march_lengths, screen_space


def pyramid(width: int, rows: int) -> list:
    """(width, height, offset) of each Hi-Z level, down to 1 x 1."""
    out, off, w, h = [], 0, width, rows
    while True:
        out.append((w, h, off))
        off += w * h
        if w == 1 and h == 1:
            return out
        w, h = (w + 1) // 2, (h + 1) // 2


def _pixels(d) -> int:
    w, h = d["camera"]["resolution"]
    return w * h


def _hiz_floats(d) -> int:
    w, h = d["camera"]["resolution"]
    last = pyramid(w, h)[-1]
    return last[2] + last[0] * last[1]


@dataclass
class Traced:
    """What SSR keeps across a frame's tiles: whether the whole frame is traced, its pyramid's levels."""
    gathered: bool = False
    levels: int = 0


class ScreenSpaceReflections(Pass):
    name = "ssr"
    kernel = "ssr.cl"
    params = ("max_roughness", "thickness", "steps", "rays", "ray_length", "seed", "rp_info", "rp_count",
              "rp_excl", "defer_to_probes", "hiz_off", "nlev",
              "src", "sw", "sh", "dst", "dw", "dh")
    functions = ("ssr_gather", "ssr_depth", "ssr_reduce", "ssr_trace", "ssr_resolve")
    whole_frame = True
    keeps = Traced
    # per pixel of the whole frame: its first sample's position and depth, normal and roughness, lit
    # radiance and object (3 float4); the depth pyramid; each pixel's traced and resolved reflection
    buffers = (Buffer("radiance"), Buffer("ssr_pix", per="frame", count=lambda d: 3 * _pixels(d)),
               Buffer("ssr_hiz", "float", per="frame", count=_hiz_floats),
               Buffer("ssr_hit", per="frame", count=_pixels), Buffer("ssr_res", per="frame", count=_pixels))

    def runs(self, scene, fx):
        return screen_space(scene, fx)

    def reads_bakes(self, scene, fx):
        return ["reflection_probes"] if reflects_locally(scene, fx) else []

    def defines(self, scene, fx):
        return {"HAS_SSR": 1, **({"HAS_REFLECTION_PROBES": 1} if reflects_locally(scene, fx) else {})}

    def setup(self, ctx) -> dict:
        s = ctx.scene.data["effects"]["ssr_settings"]
        rp = rprobe_args(ctx.rt, ctx.loaded.get("reflection_probes"), ctx.bakes, len(ctx.scene.data["objects"]))
        lengths = march_lengths(s, ctx.arrays, ctx.scene.data["camera"])
        return {"max_roughness": s["max_roughness"], "thickness": lengths["thickness"], "steps": s["steps"],
                "rays": s["rays"], "ray_length": lengths["ray_length"], "seed": s["seed"], "rp_info": rp["rp_info"],
                "rp_count": rp["rp_count"], "rp_excl": rp["rp_excl"], "defer_to_probes": int(s["defer_to_probes"])}

    def gather(self, ctx):
        """This tile's first samples into the frame's ssr_pix."""
        ctx.launch(self, (ctx.table["npix"],), "ssr_gather")

    def frame_run(self, ctx):
        """Once the whole frame is gathered: the pyramid, every pixel's rays and the resolve."""
        rt, a = ctx.rt, ctx.args[self.name]
        w, h = ctx.scene.data["camera"]["resolution"]
        levels = pyramid(w, h)
        off = rt.to_device(np.array([o for _w, _h, o in levels], np.int32))
        ctx.launch(self, (w * h,), "ssr_depth", npix=w * h)
        for (sw, sh, so), (dw, dh, do) in zip(levels, levels[1:]):
            ctx.launch(self, (dw * dh,), "ssr_reduce", src=so, sw=sw, sh=sh, dst=do, dw=dw, dh=dh)
        ctx.launch(self, (w * h,), "ssr_trace", hiz_off=off, nlev=len(levels), **{k: a[k] for k in (
            "max_roughness", "thickness", "steps", "rays", "ray_length", "seed", "rp_info", "rp_count",
            "rp_excl", "defer_to_probes")})
        ctx.launch(self, (w * h,), "ssr_resolve", max_roughness=a["max_roughness"])
        traced = self.kept(ctx)
        traced.gathered, traced.levels = True, len(levels)

    def run(self, ctx):
        t0 = time.perf_counter()
        traced = self.kept(ctx)
        if not traced.gathered:           # one tile: the frame is this tile
            self.gather(ctx)
            self.frame_run(ctx)
        ctx.launch(self, (ctx.table["n"],))
        ctx.rt.finish()
        w, h = ctx.scene.data["camera"]["resolution"]
        return {"levels": traced.levels, "rays_at_max_roughness": ctx.args[self.name]["rays"],
                "mpixels_per_s": round(w * h / max(time.perf_counter() - t0, 1e-9) / 1e6, 2)}
