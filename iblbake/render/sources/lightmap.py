"""The scene's lightmap (`diffuse: lightmap`): the `lightmap` bake (render/lightmaps) read at each
hit's UV1, which the G-buffer pass finds (passes/gbuffer.py binds uv_tables()); a hit without one
reads the irradiance probes where the scene has a `probes` section, else the panorama's SH, and
lm_stats counts both. What a texel holds is `lightmap.basis`: the irradiance, L1 SH, or a basis of
the probes' registry (core/bases/probes.py PROBE_BASES), packed by the registry and evaluated by its
kernel function (kernels/lightmap.h). `specular: lightmap` (LightmapSpecular): the split sum with the
radiance along the warped GGX lobe from the texels' second set, fitted for the radiance (a basis
that carries a lobe: sg, ambient dice), the distant chain on what has none, lm_stats[2..3] counting
both. Twin: render/lightmaps/read.py."""

from __future__ import annotations

import numpy as np

from iblbake.core import sh
from iblbake.render.buffers import Buffer
from iblbake.render.sources.base import Source

PARAMS = ("lm_atlas", "lm_width", "lm_height")
UV_PARAMS = ("lm_prims", "lm_tris")


def reads(fx) -> bool:
    """Whether a frame of these effects (plan.Effects) reads the lightmap (its UV1, its atlases)."""
    return "lightmap" in (fx.diffuse, fx.specular)


def fallback_probes(scene) -> bool:
    """Whether what has no lightmap reads the irradiance probes: some object has none (an infinite
    plane) and the scene has a `probes` section (else the panorama's SH: no probes are baked)."""
    from iblbake.render.lightmaps.uv import charted
    return "probes" in (scene.raw or {}) and not all(charted(o) for o in scene.data["objects"])


def uv_defines() -> dict:
    """What the G-buffer's UV1 lookup compiles with (kernels/lightmap.h lightmap_uv)."""
    from iblbake.render.lightmaps.uv import SPHERE_SEGMENTS
    return {"HAS_LIGHTMAP": 1, "LM_SPHERE_AROUND": SPHERE_SEGMENTS[0], "LM_SPHERE_BANDS": SPHERE_SEGMENTS[1]}


def basis_of(settings: dict):
    """(the registry's entry or None for the lightmap's own irradiance and sh_l1, its options)."""
    from iblbake.core.bases.probes import PROBE_BASES
    b = PROBE_BASES.get(settings["basis"])
    return b, (b.options(settings) if b is not None else {})


def basis_defines(settings: dict) -> dict:
    """kernels/lightmap.h's switches for lightmap.basis: which texel reading, its rows a texel."""
    name = settings["basis"]
    b, opts = basis_of(settings)
    if name == "irradiance":
        return {"LIGHTMAP_IRRADIANCE": 1, "LM_ROWS": 1}
    if b is None or not b.directional:                 # sh_l1, or the registry's SH irradiance
        k = 4 if b is None else b.floats(opts)
        return {"LIGHTMAP_SH": 1, "LIGHTMAP_SH_COEFFS": k, "LM_ROWS": k}
    return {**b.m.defines(opts), "LIGHTMAP_BASIS": 1, "BASIS_SPACE": "__global", "LM_ROWS": b.rows(opts)}


def texels_of(lm: dict, settings: dict) -> np.ndarray:
    """The atlas' float4 rows, LM_ROWS a texel in row-major texel order, as the kernel reads them:
    the irradiance; the L1 SH as irradiance coefficients (E_lm = Ahat_l L_lm); a registry basis as
    its entry packs a probe's block."""
    name = settings["basis"]
    b, opts = basis_of(settings)
    h, w = lm["layout"].height, lm["layout"].width
    if name == "irradiance":
        return np.pad(np.asarray(lm[name], np.float32).reshape(-1, 3), ((0, 0), (0, 1)))
    if b is None:
        e = np.asarray(lm[name], np.float64) * sh.ahat(2)[:, None]
        return np.pad(e.reshape(-1, 3), ((0, 0), (0, 1))).astype(np.float32)
    return b.pack(np.asarray(lm[name]).reshape(h * w, -1, 3), opts)


def uv_tables(lay, arrays) -> tuple:
    """(lm_prims (records, 4) int32, lm_tris (atlas triangles, 5, 4) float32) of a layout over the
    scene's records (kernels/lightmap.h): per sphere, plane and triangle (BVH order) record its first
    atlas triangle and their count (0: none); a mesh triangle's found by its corners, among copies of
    the atlas' triangles sorted by them (a surface lit on both sides has one a side, together)."""
    ints = lambda a: np.asarray(a, np.float32).view(np.int32)
    tris = np.zeros((max(len(lay.uv), 1), 5, 4), np.float32)
    tris[:len(lay.uv), :3, :3] = lay.corners
    tris[:len(lay.uv), 3] = lay.uv[:, :2].reshape(-1, 4)
    tris[:len(lay.uv), 4, :2] = lay.uv[:, 2]
    first = {int(o): int(np.flatnonzero(lay.objects == o)[0]) for o in np.unique(lay.objects)}
    count = {o: int((lay.objects == o).sum()) for o in first}
    ns, npl, nt = len(arrays.spheres), len(arrays.planes), len(arrays.tris)
    prims = np.zeros((max(ns + npl + nt, 1), 4), np.int32)
    for i, obj in enumerate(ints(arrays.spheres[:, 1, 1]) if ns else []):
        prims[i, :2] = (first[obj], count[obj]) if obj in first else (0, 0)
    for i, obj in enumerate(ints(arrays.planes[:, 1, 3]) if npl else []):
        prims[ns + i, :2] = (first[obj], count[obj]) if obj in first else (0, 0)
    if nt:
        # a scene triangle's atlas triangles (one a lit side: two for a surface seen from both,
        # uv.py) found by their corners, then copied after the layout's so that they lie together
        mine = np.isin(ints(arrays.tris[:, 1, 3]), list(first))
        atlas, scene = _corner_keys(lay.corners), _corner_keys(arrays.tris[:, :3, :3])
        order = np.argsort(atlas, kind="stable")
        lo = np.searchsorted(atlas[order], scene, "left")
        hi = np.searchsorted(atlas[order], scene, "right")
        found = mine & (hi > lo)
        prims[ns + npl:][found, 0] = len(tris) + lo[found]
        prims[ns + npl:][found, 1] = (hi - lo)[found]
        tris = np.concatenate([tris, tris[order]])
    return prims, tris


def _corner_keys(corners) -> np.ndarray:
    """Each triangle's corners (n, 3, 3) as one key independent of their order (xatlas may rotate
    them): their float32 bytes, the three corners sorted."""
    c = np.ascontiguousarray(np.asarray(corners, np.float32)).view(np.dtype((np.void, 12))).reshape(len(corners), 3)
    return np.ascontiguousarray(np.sort(c, axis=1)).view(np.dtype((np.void, 36))).ravel()


def uv_args(rt, lm, arrays, bakes=None) -> dict:
    """lm_prims and lm_tris on the device (placeholders without a lightmap)."""
    if lm is None:
        return {"lm_prims": rt.to_device(np.zeros((1, 4), np.int32)),
                "lm_tris": rt.to_device(np.zeros((1, 4), np.float32))}

    def upload():
        return tuple(rt.to_device(a) for a in uv_tables(lm["layout"], arrays))
    prims, tris = bakes.on_device(rt, (lm["layout"].uv, arrays.tris, arrays.spheres, arrays.planes), upload) \
        if bakes is not None else upload()
    return {"lm_prims": prims, "lm_tris": tris}


class Lightmap(Source):
    name = "lightmap"
    header = "lightmap.h"
    params = PARAMS
    sections = ("lightmap", "probes")
    # [0] the samples the lightmap lit, [1] those of surfaces without one (the probes or the panorama's
    # SH); [2], [3] the same of the specular lobe (LightmapSpecular; the distant chain)
    buffers = (Buffer("lm_stats", "int", per="frame", count=4, when="HAS_LIGHTMAP"),)

    def runs(self, scene, fx):
        return fx.diffuse == "lightmap"

    def defines(self, scene, fx):
        d = {**uv_defines(), **basis_defines(scene.data["lightmap"])}
        if fallback_probes(scene):
            d["LIGHTMAP_FALLBACK_PROBES"] = 1
        return d

    def reads_bakes(self, scene, fx):
        return ["lightmap"]

    def args(self, ctx):
        lm, settings = ctx.loaded["lightmap"], ctx.scene.data["lightmap"]
        atlas = ctx.bakes.on_device(ctx.rt, (lm["layout"].uv, lm[settings["basis"]]),
                                    lambda: ctx.rt.to_device(texels_of(lm, settings)))
        return {"lm_atlas": atlas, "lm_width": lm["layout"].width, "lm_height": lm["layout"].height}

    def placeholders(self, rt):
        return {"lm_atlas": rt.to_device(np.zeros((1, 4), np.float32)), "lm_width": 1, "lm_height": 1}


class LightmapSpecular(Source):
    """`specular: lightmap`: the split sum's DFG table times the radiance along the warped GGX lobe
    read from the texels' second set (the bake's `specular`, fitted for the radiance: NNLS,
    render/lightmaps/bases.py project_specular), as `specular: probes` reads the probes'; the
    distant prefiltered chain on what has no lightmap (lm_stats[3]). Binds the lightmap's size
    itself: a frame of metals has no diffuse term. Kernel: kernels/lightmap.h lightmap_specular."""
    name = "lightmap_specular"
    header = "lightmap.h"
    params = ("lm_spec", "lm_width", "lm_height", "basis_table", "chain", "off", "lw", "lh", "nlev", "dfg",
              "dfg_size")
    sections = ("lightmap",)

    def runs(self, scene, fx):
        return fx.specular == "lightmap"

    def defines(self, scene, fx):
        settings = scene.data["lightmap"]
        b, opts = basis_of(settings)
        spec = specular_options(settings)
        from iblbake.render.sources.prefiltered import split_sum_defines
        return {**uv_defines(), **b.m.defines(spec), "BASIS_SPACE": "__global", "LIGHTMAP_SPECULAR": 1,
                "LM_SPEC_ROWS": b.rows(spec), **split_sum_defines(scene)}

    def reads_bakes(self, scene, fx):
        return ["lightmap", "prefiltered", "dfg"]

    def args(self, ctx):
        from iblbake.render.sources.basis import table_args
        from iblbake.render.sources.prefiltered import split_sum_args
        lm, settings = ctx.loaded["lightmap"], ctx.scene.data["lightmap"]
        b, spec = basis_of(settings)[0], lm["specular_options"]
        h, w = lm["layout"].height, lm["layout"].width
        atlas = ctx.bakes.on_device(ctx.rt, (lm["layout"].uv, lm["specular"]),
                                    lambda: ctx.rt.to_device(b.pack(np.asarray(lm["specular"]).reshape(h * w, -1, 3),
                                                                    spec)))
        return {"lm_spec": atlas, "lm_width": w, "lm_height": h, **table_args(ctx.rt, settings["basis"], spec),
                **split_sum_args(ctx)}

    def placeholders(self, rt):
        return {"lm_spec": rt.to_device(np.zeros((1, 4), np.float32))}


def specular_options(settings: dict) -> dict:
    """The options of the texels' second set, the lobe's (render/lightmaps/bases.py specular_options)."""
    from iblbake.render.lightmaps.bases import specular_options as options
    b, opts = basis_of(settings)
    return options(b.name, opts)
