"""Local reflection probes, read by the split sum where they reach (render/reflection_probes.py
captures them). Kernel: kernels/reflection_probes.h reflection_probes."""

from __future__ import annotations

import numpy as np

from iblbake.errors import IblbakeError
from iblbake.render.sources.base import Source
from iblbake.render.twin.reflection_probes import marches, own_masks

PARAMS = ("rp_chain", "rp_off", "rp_lw", "rp_lh", "rp_nlev", "rp_count", "rp_info", "rp_excl")


def reflects_locally(scene, fx) -> bool:
    """Whether the scene's reflection probes are read: by the split sum (`prefiltered`)."""
    return (fx.specular == "prefiltered" and bool(scene.data["reflection_probes"])
            and scene.data["effects"]["reflection_probes"])


class ReflectionProbes(Source):
    name = "reflection_probes"
    header = "reflection_probes.h"
    params = PARAMS
    sections = ("reflection_probes",)

    def runs(self, scene, fx):
        return reflects_locally(scene, fx)

    def defines(self, scene, fx):
        return {"HAS_REFLECTION_PROBES": 1}

    def reads_bakes(self, scene, fx):
        return ["reflection_probes"]

    def args(self, ctx):
        return rprobe_args(ctx.rt, ctx.loaded["reflection_probes"], ctx.bakes, len(ctx.scene.data["objects"]))

    def placeholders(self, rt):
        return rprobe_args(rt, None)


def rprobe_args(rt, captured, bakes=None, nobj: int = 0) -> dict:
    """RPROBE_PARAMS of the reflection probes' chains (the reflection_probes unit, render/units.py), placeholders
    without them. Every probe's chain has the same level sizes (one capture size and prefilter). rp_excl: the
    probes excluding each of the scene's nobj objects (own_masks)."""
    zf, zi = rt.to_device(np.zeros(4, np.float32)), rt.to_device(np.zeros(4, np.int32))
    if not captured:
        return {"rp_chain": zf, "rp_off": zi, "rp_lw": zi, "rp_lh": zi, "rp_nlev": 1, "rp_count": 0,
                "rp_info": rt.to_device(np.zeros((4, 4), np.float32)),
                "rp_excl": rt.to_device(np.zeros(4, np.uint32))}
    sizes = [[lv.shape[:2] for lv in c["levels"]] for c in captured]
    if any(s != sizes[0] for s in sizes):
        raise IblbakeError("reflection_probes: every probe needs the same size (their chains share one table)")

    def upload():
        flat = np.concatenate([np.asarray(lv[..., :3], np.float32).reshape(-1) for c in captured
                               for chain in probe_chains(c) for lv in chain])
        counts = [h * w for h, w in sizes[0]] * (4 * len(captured))   # each probe: radiance, coverage, sky, distance
        off = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int32)
        return (rt.to_device(flat), rt.to_device(off), rt.to_device(np.array([w for _h, w in sizes[0]], np.int32)),
                rt.to_device(np.array([h for h, _w in sizes[0]], np.int32)))
    chains = tuple(lv for c in captured for chain in probe_chains(c) for lv in chain)
    chain, off, lw, lh = bakes.on_device(rt, chains, upload) if bakes is not None else upload()
    # the settings each frame's own: probes of other settings (blend, box, taps) can share chains of
    # the same content, and with them the memo's upload
    return {"rp_chain": chain, "rp_off": off, "rp_lw": lw, "rp_lh": lh, "rp_nlev": len(sizes[0]),
            "rp_count": len(captured), "rp_info": rt.to_device(rprobe_info(captured)),
            "rp_excl": rt.to_device(own_masks(captured, nobj))}


def probe_chains(c: dict) -> tuple:
    """A probe's four chains in the table (kernels/reflection_probes.h): radiance, coverage, sky and
    distance (zeros where the probe has none: rp_info says so)."""
    depth = c.get("depth") or [np.zeros_like(lv) for lv in c["levels"]]
    return c["levels"], c["coverage"], c["sky"], depth


def tap_code(st: dict) -> int:
    """rp_info's fourth z: `taps` over the whole lobe where set, else minus `grazing_taps` (taps
    where the view grazes the surface alone; kernels/reflection_probes.h rprobe_grazing)."""
    return int(st["taps"]) if st["taps"] else -int(st.get("grazing_taps", 0))


def rprobe_info(captured) -> np.ndarray:
    """rp_info (kernels/reflection_probes.h): 4 float4 per probe from its settings."""
    info = np.zeros((len(captured), 4, 4), np.float32)
    for k, c in enumerate(captured):
        st = c["settings"]
        box = st["shape"] == "box"
        info[k, 0] = [*st["position"], 0.0 if box else 1.0]
        info[k, 1] = [*(st["min"] if box else st["position"]), st["blend"]]
        info[k, 2] = [*(st["max"] if box else st["position"]), 0.0 if box else st["radius"]]
        info[k, 3, 0] = 1.0 if st["parallax"] else 0.0
        info[k, 3, 1] = np.pi / st["size"]          # the capture's texel, in radians (its rows)
        info[k, 3, 2] = tap_code(st)                # the lobe's taps (rprobe_taps, rprobe_grazing)
        info[k, 3, 3] = 1.0 if marches(c) else 0.0      # a distance chain to march (rprobe_hit)
    return info.reshape(-1, 4)
