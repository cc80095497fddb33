"""SSR: stochastic screen-space reflections over the split sum's (or the lobe's) environment,
after the lighting passes (kernels/ssr.cl; twin: iblbake/render/twin/ssr.py). Each tile marches
through its own depth pyramid: a ray that leaves the tile keeps the environment."""

from __future__ import annotations

import time

import numpy as np

from iblbake.render.passes.base import Buffer, Pass
from iblbake.render.passes.shade import screen_space


def pyramid(width: int, rows: int) -> list:
    """(width, height, offset) of each Hi-Z level, down to 1 x 1."""
    out, off, w, h = [], 0, width, rows
    while True:
        out.append((w, h, off))
        off += w * h
        if w == 1 and h == 1:
            return out
        w, h = (w + 1) // 2, (h + 1) // 2


class ScreenSpaceReflections(Pass):
    name = "ssr"
    kernel = "ssr.cl"
    functions = ("ssr_depth", "ssr_reduce")
    # the lit frame's copy (read while radiance is written) and the depth pyramid (under 3 floats a
    # pixel: 4/3 of the pixels, plus a row and a column a level)
    buffers = (Buffer("radiance"), Buffer("ssr_src"), Buffer("ssr_hiz", "float", per="pixel", count=3))
    host_writes = ("ssr_src",)

    def runs(self, scene, fx):
        return screen_space(scene, fx)

    def defines(self, scene, fx):
        return {"HAS_SSR": 1}

    def setup(self, ctx) -> dict:
        s = ctx.scene.data["effects"]["ssr_settings"]
        return {"max_roughness": s["max_roughness"], "thickness": s["thickness"], "steps": s["steps"],
                "rays": s["rays"], "ray_length": s["ray_length"], "seed": s["seed"]}

    def run(self, ctx):
        rt, t = ctx.rt, ctx.table
        t0 = time.perf_counter()
        levels = pyramid(ctx.width, ctx.tile_rows)
        off = rt.to_device(np.array([o for _w, _h, o in levels], np.int32))
        rt.cl.enqueue_copy(rt.queue, t["ssr_src"], t["radiance"], byte_count=16 * t["n"])
        ctx.launch(self, (t["npix"],), "ssr_depth")
        for (sw, sh, so), (dw, dh, do) in zip(levels, levels[1:]):
            ctx.launch(self, (dw * dh,), "ssr_reduce", src=so, sw=sw, sh=sh, dst=do, dw=dw, dh=dh)
        ctx.launch(self, (t["n"],), **ctx.args[self.name], hiz_off=off, nlev=len(levels))
        rt.finish()
        return {"levels": len(levels), "rays_per_sample": ctx.args[self.name]["rays"],
                "mrays_per_s": round(t["n"] * ctx.args[self.name]["rays"] / max(time.perf_counter() - t0, 1e-9) / 1e6, 2)}
