"""Shade: the approximate lighting terms (SH or probe diffuse; importance specular from the importance
pass's sums, prefiltered or lobe specular; emission), added into `radiance` (kernels/shade.cl;
twin: iblbake/render/twin/shade.py shade)."""

from __future__ import annotations

import numpy as np

from iblbake.core import sampling
from iblbake.render import probes
from iblbake.render.passes.base import Buffer, Pass, mode_defines


class Shade(Pass):
    name = "shade"
    kernel = "shade.cl"
    # every lighting pass adds into radiance; ssr_env: the reflected environment the ssr pass replaces
    buffers = (Buffer("radiance"), Buffer("ssr_env", count=2, when="HAS_SSR"),
               Buffer("probe_stats", "int", per="frame", count=2, when="PROBE_STATS"))
    host_writes = ("probe_stats",)

    def runs(self, scene, fx):
        return fx.any_approximate or fx.emissive

    def reads_bakes(self, scene, fx):
        return {"sh": ["sh"], "probes": ["sh", "probes"]}.get(fx.diffuse, []) + \
            {"prefiltered": ["prefiltered", "dfg"], "lobe": ["prefiltered", "dfg"]}.get(fx.specular, []) + \
            (["reflection_probes"] if reflects_locally(scene, fx) else [])

    def defines(self, scene, fx):
        e = scene.data["effects"]
        d = mode_defines(fx)          # shade.cl computes only the sh, importance, prefiltered terms
        if fx.diffuse in ("sh", "probes"):
            d["SH_BANDS"] = e["sh_bands"]     # probes: the SH outside their volume
        if fx.diffuse == "probes":
            d.update(probe_defines(scene.data["probes"]), PROBE_STATS=1)
        if fx.specular == "prefiltered" and e["prefilter"]["dominant_direction"]:
            d["DOMINANT_DIRECTION"] = 1
        if reflects_locally(scene, fx):
            d["HAS_REFLECTION_PROBES"] = 1
        if screen_space(scene, fx):
            d["HAS_SSR"] = 1
        if fx.emissive:
            d["HAS_EMISSIVE"] = 1
        if e["ao"] != "off" and fx.any_approximate:
            d["HAS_AO"] = 1
            if e["ao_multibounce"] and fx.diffuse == "sh":
                d["AO_MULTIBOUNCE"] = 1
        return d

    def setup(self, ctx) -> dict:
        """Per frame (not per tile): the term's tables as named arguments."""
        e, fx, b = ctx.scene.data["effects"], ctx.plan.effects, ctx.loaded
        args = {"sh_coeffs": ctx.rt.to_device(np.pad(b["sh"], ((0, 0), (0, 1))).astype(np.float32)
                                              if "sh" in b else np.zeros((1, 4), np.float32))}
        chain = b.get("prefiltered") if fx.specular in ("prefiltered", "lobe") else None
        args.update(ctx.chain(chain) if chain is not None else ctx.no_chain())
        nsamp = e["lobe"]["samples"] if fx.specular == "lobe" else 1
        ham = np.zeros((nsamp, 4), np.float32)
        if fx.specular == "lobe":             # (u1, u2): sample_ggx_vndf
            ham[:, :2] = sampling.lobe_points(nsamp)
        args.update(probe_args(ctx.rt, probes.sampled(b["probes"], ctx.scene.data["probes"]) if "probes" in b else None,
                               ctx.bakes))
        args.update(rprobe_args(ctx.rt, b.get("reflection_probes"), ctx.bakes))
        dfg = b["dfg"].astype(np.float32) if "dfg" in b else np.zeros((2, 2, 2), np.float32)
        args.update(hammersley_pts=ctx.rt.to_device(ham), nsamples=nsamp, mip_bias=e["mip_bias"], lobe_spread=e["lobe"]["spread"],
                    dfg=ctx.rt.to_device(dfg.reshape(-1, 2)), dfg_size=dfg.shape[0])
        return args

    def run(self, ctx):
        n, args = ctx.table["n"], ctx.args[self.name]
        probes_in = ctx.plan.effects.diffuse == "probes"
        if probes_in:
            ctx.rt.cl.enqueue_fill_buffer(ctx.rt.queue, ctx.table["probe_stats"], np.int32(0), 0, 8)
        s = self.launch_samples(ctx)
        extra = {"samples": args["nsamples"]} if ctx.plan.effects.specular == "lobe" else {}
        if probes_in:                 # the samples whose cell's probes were all off, summed over tiles
            near, none = ctx.rt.read(ctx.table["probe_stats"], (2,), np.int32).tolist()
            tot = ctx.__dict__.setdefault("probe_fallback", [0, 0])
            tot[0] += near
            tot[1] += none
            extra.update(probe_fallback_nearest=tot[0], probe_fallback_sky=tot[1])
        return {"mpixel_samples_per_s": round(n * args["nsamples"] / max(s, 1e-9) / 1e6, 2), **extra}


def screen_space(scene, fx) -> bool:
    """Whether screen-space reflections run: over the split sum's environment (and probes)."""
    return fx.specular == "prefiltered" and scene.data["effects"]["ssr"] == "on"


def reflects_locally(scene, fx) -> bool:
    """Whether the scene's reflection probes are read: by the split sum (`prefiltered`)."""
    return (fx.specular == "prefiltered" and bool(scene.data["reflection_probes"])
            and scene.data["effects"]["reflection_probes"])


def rprobe_args(rt, captured, bakes=None) -> dict:
    """RPROBE_PARAMS of the reflection probes' chains (Bakes._reflection_probes), placeholders
    without them. Every probe's chain has the same level sizes (one capture size and prefilter)."""
    zf, zi = rt.to_device(np.zeros(4, np.float32)), rt.to_device(np.zeros(4, np.int32))
    if not captured:
        return {"rp_chain": zf, "rp_off": zi, "rp_lw": zi, "rp_lh": zi, "rp_nlev": 1, "rp_count": 0,
                "rp_info": rt.to_device(np.zeros((4, 4), np.float32))}
    sizes = [[lv.shape[:2] for lv in c["levels"]] for c in captured]
    if any(s != sizes[0] for s in sizes):
        from iblbake.errors import IblbakeError
        raise IblbakeError("reflection_probes: every probe needs the same size (their chains share one table)")

    def upload():
        flat = np.concatenate([np.asarray(lv[..., :3], np.float32).reshape(-1) for c in captured
                               for chain in (c["levels"], c["coverage"]) for lv in chain])
        counts = [h * w for h, w in sizes[0]] * (2 * len(captured))      # each probe: radiance, coverage
        off = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int32)
        info = np.zeros((len(captured), 4, 4), np.float32)
        for k, c in enumerate(captured):
            st = c["settings"]
            box = st["shape"] == "box"
            info[k, 0] = [*st["position"], 0.0 if box else 1.0]
            info[k, 1] = [*(st["min"] if box else st["position"]), st["blend"]]
            info[k, 2] = [*(st["max"] if box else st["position"]), 0.0 if box else st["radius"]]
            info[k, 3, 0] = 1.0 if st["parallax"] else 0.0
        return (rt.to_device(flat), rt.to_device(off), rt.to_device(np.array([w for _h, w in sizes[0]], np.int32)),
                rt.to_device(np.array([h for h, _w in sizes[0]], np.int32)), rt.to_device(info.reshape(-1, 4)))
    chain, off, lw, lh, info = bakes.on_device(rt, tuple(lv for c in captured for lv in c["levels"] + c["coverage"]),
                                               upload) \
        if bakes is not None else upload()
    return {"rp_chain": chain, "rp_off": off, "rp_lw": lw, "rp_lh": lh, "rp_nlev": len(sizes[0]),
            "rp_count": len(captured), "rp_info": info}


def probe_defines(settings: dict) -> dict:
    """kernels/probes.h's switches for a scene's probes section."""
    d = {"PROBES_SH": 1} if settings["irradiance"] == "sh" else {}
    if settings["visibility"]:
        d["PROBE_VISIBILITY"] = 1
    if settings["classification"]:
        d["PROBE_CLASSIFICATION"] = 1
    return d


def probe_args(rt, vol, bakes=None) -> dict:
    """PROBE_PARAMS of a sampled volume (render/probes.py sampled), placeholders without one. With
    `bakes` (render.Bakes) its atlases go up once per runtime (a series of frames, a study's rungs)."""
    if vol is None:
        z = rt.to_device(np.zeros((1, 4), np.float32))
        return {"probe_data": z, "probe_irr": z, "probe_dist": z, "probe_origin": np.zeros(4), "probe_spacing": np.ones(4),
                "probe_nx": 1, "probe_ny": 1, "probe_nz": 1, "probe_irr_texels": 1, "probe_dist_texels": 1}

    def upload():
        irr = np.asarray(vol["irradiance"], np.float32)
        dist = np.asarray(vol["distance"], np.float32)
        return (rt.to_device(np.asarray(vol["data"], np.float32)),
                rt.to_device(np.pad(irr, [(0, 0)] * (irr.ndim - 1) + [(0, 1)]).reshape(-1, 4)),
                rt.to_device(np.pad(dist, ((0, 0), (0, 0), (0, 2))).reshape(-1, 4)))
    data, irr, dist = bakes.on_device(rt, (vol["data"], vol["irradiance"], vol["distance"]), upload) \
        if bakes is not None else upload()
    return {"probe_data": data, "probe_irr": irr, "probe_dist": dist,
            "probe_origin": np.array([*vol["origin"], vol["normal_bias"]], np.float32),
            "probe_spacing": np.array([*vol["spacing"], vol["view_bias"]], np.float32),
            **dict(zip(("probe_nx", "probe_ny", "probe_nz"), vol["counts"])),
            "probe_irr_texels": vol["irradiance_texels"], "probe_dist_texels": vol["distance_texels"]}
