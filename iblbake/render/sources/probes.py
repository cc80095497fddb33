"""Irradiance probes (`diffuse: probes`): the DDGI volume baked by render/probes/, sampled as
RTXGI does, with its fallbacks counted in probe_stats. Kernel: kernels/probes.h probes_diffuse."""

from __future__ import annotations

import numpy as np

from iblbake.render import probes
from iblbake.render.buffers import Buffer
from iblbake.render.sources.base import Source
from iblbake.scene.layout import pack_probe_volume

PARAMS = ("probe_data", "probe_irr", "probe_dist", "probe_volume")


class IrradianceProbes(Source):
    name = "probes"
    header = "probes.h"
    params = PARAMS
    sections = ("probes",)
    # the samples that fell back: [0] to the nearest active probes, [1] to the panorama's SH; [2],
    # [3] the same of the probes' specular (ProbeSpecular); [4] those outside the volume (or on its
    # fading edge), which take the panorama's SH; [5] the samples on geometry the diffuse probes shade
    buffers = (Buffer("probe_stats", "int", per="frame", count=6, when="PROBE_STATS"),)

    def runs(self, scene, fx):
        from iblbake.render.sources.lightmap import fallback_probes
        # with a lightmap, for what has none
        return fx.diffuse == "probes" or (fx.diffuse == "lightmap" and fallback_probes(scene))

    def defines(self, scene, fx):
        return {**probe_defines(scene.data["probes"]), "PROBE_STATS": 1}

    def reads_bakes(self, scene, fx):
        return ["probes"]

    def args(self, ctx):
        return probe_args(ctx.rt, probes.sampled(ctx.loaded["probes"], ctx.scene.data["probes"]), ctx.bakes)

    def placeholders(self, rt):
        return probe_args(rt, None)


def probe_defines(settings: dict) -> dict:
    """kernels/probes.h's switches for a scene's probes section."""
    from iblbake.core.bases.probes import PROBE_BASES
    d = dict(PROBE_BASES[settings["irradiance"]].defines(settings))
    if settings["visibility"]:
        d["PROBE_VISIBILITY"] = 1
    if settings["classification"]:
        d["PROBE_CLASSIFICATION"] = 1
    return d


def probe_args(rt, vol, bakes=None) -> dict:
    """PROBE_PARAMS of a sampled volume (render/probes/volume.py sampled), placeholders without one. With
    `bakes` (render.Bakes) its atlases go up once per runtime (a series of frames, a study's rungs)."""
    if vol is None:
        z = rt.to_device(np.zeros((1, 4), np.float32))
        none = {"counts": (1, 1, 1), "origin": (0, 0, 0), "spacing": (1, 1, 1), "normal_bias": 0, "view_bias": 0,
                "irradiance_texels": 1, "distance_texels": 1}
        return {"probe_data": z, "probe_irr": z, "probe_dist": z, "probe_volume": rt.to_device(pack_probe_volume(none))}

    def upload():
        basis = probes.basis_of(vol)           # each probe's block as its basis packs it
        irr = basis.pack(vol["irradiance"], basis.options(vol["settings"]))
        dist = np.asarray(vol["distance"], np.float32)
        return (rt.to_device(np.asarray(vol["data"], np.float32)),
                rt.to_device(irr),
                rt.to_device(np.pad(dist, ((0, 0), (0, 0), (0, 2))).reshape(-1, 4)))
    data, irr, dist = bakes.on_device(rt, (vol["data"], vol["irradiance"], vol["distance"]), upload) \
        if bakes is not None else upload()
    return {"probe_data": data, "probe_irr": irr, "probe_dist": dist,
            "probe_volume": rt.to_device(pack_probe_volume(vol))}


class ProbeSpecular(Source):
    """`specular: probes`: the split sum with the radiance along the warped GGX lobe from probes whose
    basis carries one (core/bases SPECULAR: sg, ambient dice), blended by the irradiance's weights,
    so a rough metal reflects the room without a reflection probe; the distant chain outside the
    volume. Kernel: kernels/probes.h probes_specular."""
    name = "probe_specular"
    header = "probes.h"
    params = PARAMS + ("basis_table", "chain", "off", "lw", "lh", "nlev", "dfg", "dfg_size")
    sections = ("probes",)

    def runs(self, scene, fx):
        return fx.specular == "probes"

    def defines(self, scene, fx):
        from iblbake.render.sources.prefiltered import split_sum_defines
        return {**probe_defines(scene.data["probes"]), "PROBE_STATS": 1, **split_sum_defines(scene)}

    def reads_bakes(self, scene, fx):
        return ["probes", "prefiltered", "dfg"]

    def args(self, ctx):
        from iblbake.render.sources.basis import table_args
        from iblbake.render.sources.prefiltered import split_sum_args
        settings = ctx.scene.data["probes"]
        return {**probe_args(ctx.rt, probes.sampled(ctx.loaded["probes"], settings), ctx.bakes),
                **table_args(ctx.rt, settings["irradiance"], probes.basis_options(settings)), **split_sum_args(ctx)}
