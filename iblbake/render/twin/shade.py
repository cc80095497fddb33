"""The shade pass (kernels/shade.cl): SH diffuse, importance-sampled, prefiltered and lobe
specular, emission, with AO's specular occlusion and multi-bounce. numpy twin, float64."""

from __future__ import annotations

import numpy as np

from iblbake.core import bases, brdf
from iblbake.core.bases import common
from iblbake.core.bases.probes import PROBE_BASES
from iblbake.core import conventions
from iblbake.bake.dfg import dfg_lookup
from iblbake.bake import radiance
from iblbake.core import sampling
from iblbake.core import sh
from iblbake.render.twin import probes as probe_twin
from iblbake.render.twin import reflection_probes as rp_twin
from iblbake.render.twin.surface import diffuse_weight, material_occlusion, surface, to_env


def shade(gb, arrays, effects: dict, env: dict, *, sh_coeffs=None, chain=None, prefiltered=None, dfg=None,
          ao=None, probes=None, reflection_probes=None, ssr_out=None, basis_coeffs=None, lightmap=None):
    """Per-sample radiance of the `shade` pass, with the `importance` pass's sums for it (hits
    only; misses are 0); `ao` the ambient occlusion of every sample (ambient_occlusion) where
    effects.ao is on. The importance estimate is summed with Fresnel inside, which the kernels
    split around f0: the same sum, to float rounding. `probes`: the sampled probe volume
    (render/probes sampled) where effects.diffuse is probes, sh_coeffs then the panorama's SH
    that takes over outside it. `lightmap`: (the `lightmap` bake, the scene's lightmap section) where
    diffuse is lightmap (render/lightmaps/read.py), the probes (`probes`) or the panorama's SH
    (`sh_coeffs`) on what has none. `basis_coeffs`: the `basis` bake where diffuse is a directional basis. `reflection_probes`: the captured probes [{settings, levels}]
    (the reflection_probes bake) where specular is prefiltered. `ssr_out` (a dict) receives the
    reflected environment's weight and radiance per hit sample ("w", "li"), as HAS_SSR writes
    ssr_env for the ssr pass (twin/ssr.py)."""
    hit = gb["hit"]
    out = np.zeros((len(hit), 3))
    v, n, nov, (base, metallic, emissive, rough, f0, f90) = surface(gb, arrays)
    alpha = rough ** 2
    rot, scale = env["rotation_y"], env["intensity"]
    color = np.zeros_like(emissive)
    occ = ao[hit] if ao is not None else np.ones(len(n))
    spec_occ = specular_occlusion(nov, occ, rough)[:, None]
    if effects["diffuse"] == "sh":
        e = np.maximum(sh.evaluate(sh_coeffs, to_env(n, rot), effects["sh_bands"]), 0.0)
        diff_occ = ao_multibounce(occ, base * (1 - metallic[:, None])) if effects["ao_multibounce"] else occ[:, None]
        color += diff_occ * diffuse_weight(base, metallic, rough, f0, f90, nov) * scale * e
    elif effects["diffuse"] in bases.DIFFUSE:
        m = bases.BASES[effects["diffuse"]]
        e = m.irradiance(basis_coeffs, to_env(n, rot), bases.options_of(effects["diffuse"], effects))
        color += occ[:, None] * diffuse_weight(base, metallic, rough, f0, f90, nov) * scale * e
    elif effects["diffuse"] == "probes":
        p = gb["pos"][hit]
        wv = probe_twin.volume_weight(probes, p)[:, None]
        sky = scale * np.maximum(sh.evaluate(sh_coeffs, to_env(n, rot), effects["sh_bands"]), 0.0)
        e, source = probe_twin.irradiance_and_source(probes, p, n, v, visibility=probes["visibility"],
                                                     classification=probes["classification"])
        e = wv * np.where((source == probe_twin.SOURCE_NONE)[:, None], sky, e) + (1 - wv) * sky
        diff_occ = ao_multibounce(occ, base * (1 - metallic[:, None])) if effects["ao_multibounce"] else occ[:, None]
        color += diff_occ * diffuse_weight(base, metallic, rough, f0, f90, nov) * e
    elif effects["diffuse"] == "lightmap":
        color += occ[:, None] * diffuse_weight(base, metallic, rough, f0, f90, nov) * lightmap_irradiance(
            gb, arrays, lightmap, n, v, probes, scale * np.maximum(sh.evaluate(sh_coeffs, to_env(n, rot),
                                                                                effects["sh_bands"]), 0.0))
    if effects["specular"] == "importance":
        nsamp = effects["samples"]
        pts = sampling.hammersley(nsamp).astype(np.float32).astype(np.float64)
        t, b = conventions.tangent_frame(n)
        h0, w0 = chain[0].shape[:2]
        acc = np.zeros((len(n), 3))
        accepted = np.zeros(len(n))
        for u in pts:
            noh, voh, l, nol = sampling.reflect_ggx_half(u, t, b, n, v, alpha)
            ok = (nol > 0) & (voh > 0)
            le = to_env(l, rot)
            if effects["force_mip0"]:
                lod = np.zeros(len(n))
            else:
                pdf = brdf.d_ggx(noh, alpha) * noh / (4 * np.maximum(voh, 1e-30))
                with np.errstate(divide="ignore"):
                    lod = 0.5 * (np.log2(1.0 / (nsamp * pdf)) - np.log2(radiance.texel_solid_angle_at(w0, h0, le))) \
                        + effects["mip_bias"]
            li = radiance.chain_lookup_twin(chain, le, lod)
            wgt = brdf.v_smith_ggx_correlated(nov, nol, alpha) * 4 * nol * voh / noh
            contrib = li * brdf.f_schlick(voh[:, None], f0, f90) * wgt[:, None]
            acc += np.where(ok[:, None], contrib, 0.0)
            accepted += ok
        div = np.maximum(accepted, 1)[:, None] if effects["normalize"] == "accepted" else nsamp
        color += spec_occ * scale * acc / div
    elif effects["specular"] == "prefiltered":
        r = 2 * (n * v).sum(1, keepdims=True) * n - v
        if effects["prefilter"]["dominant_direction"]:
            r = common.lobe_axis(n, v, alpha)
        pre = radiance.chain_lookup_twin(prefiltered, to_env(r, rot), rough * (len(prefiltered) - 1))
        ab = dfg_lookup(dfg, nov, rough)
        li = scale * pre
        w = spec_occ * (f0 * ab[:, 0:1] + f90 * ab[:, 1:2])           # the split sum's albedo, occluded
        lit = w.sum(1) > 0                                              # what reflects: probes read there
        if reflection_probes and lit.any():
            nlev = len(reflection_probes[0]["levels"])
            from iblbake.render.lightmaps.read import hit_objects
            masks = rp_twin.masks_of(reflection_probes, hit_objects(gb, arrays)[hit][lit])
            li[lit] = rp_twin.blend(reflection_probes, gb["pos"][hit][lit], r[lit], rough[lit] * (nlev - 1), li[lit],
                                    (prefiltered, rot, scale), (n[lit], v[lit], np.flatnonzero(hit)[lit]), masks)
        color += w * li
        if ssr_out is not None:
            ssr_out["w"] = w * material_occlusion(gb)[:, None]
            ssr_out["li"] = li
    elif effects["specular"] == "probes":              # kernels/shade.cl SPECULAR_PROBES
        r = 2 * (n * v).sum(1, keepdims=True) * n - v
        if effects["prefilter"]["dominant_direction"]:
            r = common.lobe_axis(n, v, alpha)
        sky = scale * radiance.chain_lookup_twin(prefiltered, to_env(r, rot), rough * (len(prefiltered) - 1))
        spec = PROBE_BASES[probes["representation"]].specular_weights(
            common.lobe_axis(n, v, alpha), common.warp_sharpness(alpha, nov), probes["settings"])
        li = probe_twin.specular(probes, gb["pos"][hit], n, v, spec, sky)
        ab = dfg_lookup(dfg, nov, rough)
        color += spec_occ * li * (f0 * ab[:, 0:1] + f90 * ab[:, 1:2])
    elif effects["specular"] == "lightmap":            # kernels/shade.cl SPECULAR_LIGHTMAP
        li = lightmap_specular(gb, arrays, lightmap[0], n, v, alpha, nov, effects, prefiltered, rot, scale, rough)
        ab = dfg_lookup(dfg, nov, rough)
        color += spec_occ * li * (f0 * ab[:, 0:1] + f90 * ab[:, 1:2])
    elif effects["specular"] in bases.SPECULAR:         # kernels/shade.cl SPECULAR_BASIS
        name = effects["specular"]
        li = scale * bases.specular_radiance(name, basis_coeffs, to_env(common.lobe_axis(n, v, alpha), rot),
                                             common.warp_sharpness(alpha, nov), bases.options_of(name, effects))
        ab = dfg_lookup(dfg, nov, rough)
        color += spec_occ * li * (f0 * ab[:, 0:1] + f90 * ab[:, 1:2])
    elif effects["specular"] == "lobe":
        color += spec_occ * scale * lobe(v, n, nov, alpha, rough, f0, f90, rot, effects["lobe"]["samples"],
                              effects["lobe"]["spread"], prefiltered, dfg)
    out[hit] = color * material_occlusion(gb)[:, None] + emissive
    return out


def lightmap_irradiance(gb, arrays, lightmap, n, v, probes, sky):
    """The irradiance of the hits (kernels/shade.cl DIFFUSE_LIGHTMAP): the lightmap's at their UV1
    (read.py), the probes' (or `sky`, the panorama's SH) on what has none."""
    from iblbake.render.lightmaps import read
    lm, settings = lightmap
    from iblbake.render.sources.lightmap import basis_of
    hit = gb["hit"]
    e, found = read.irradiance(lm, read.hit_objects(gb, arrays)[hit], gb["pos"][hit], n, settings["basis"],
                               basis_of(settings)[1])
    rest = ~found
    if probes is not None and rest.any():
        p = gb["pos"][hit][rest]
        wv = probe_twin.volume_weight(probes, p)[:, None]
        pe, source = probe_twin.irradiance_and_source(probes, p, n[rest], v[rest], visibility=probes["visibility"],
                                                      classification=probes["classification"])
        sky[rest] = wv * np.where((source == probe_twin.SOURCE_NONE)[:, None], sky[rest], pe) + (1 - wv) * sky[rest]
    return np.where(found[:, None], e, sky)


def lightmap_specular(gb, arrays, lm, n, v, alpha, nov, effects, prefiltered, rot, scale, rough):
    """The radiance along the hits' lobes (kernels/shade.cl SPECULAR_LIGHTMAP): the lightmap's second
    set at their UV1 (read.py specular), the distant chain's on what has none."""
    from iblbake.render.lightmaps import read
    hit = gb["hit"]
    li, found = read.specular(lm, read.hit_objects(gb, arrays)[hit], gb["pos"][hit], n, common.lobe_axis(n, v, alpha),
                              common.warp_sharpness(alpha, nov))
    r = 2 * (n * v).sum(1, keepdims=True) * n - v
    if effects["prefilter"]["dominant_direction"]:
        r = common.lobe_axis(n, v, alpha)
    sky = scale * radiance.chain_lookup_twin(prefiltered, to_env(r, rot), rough * (len(prefiltered) - 1))
    return np.where(found[:, None], li, sky)


def specular_occlusion(nov, ao, roughness):
    """Twin of shade.cl specular_occlusion (Lagarde and de Rousiers 2014)."""
    return np.clip((nov + ao) ** np.exp2(-16 * roughness - 1) - 1 + ao, 0, 1)


def ao_multibounce(ao, albedo):
    """Twin of shade.cl ao_multibounce (Jimenez et al. 2016, eq. 10)."""
    a, b, c = 2.0404 * albedo - 0.3324, -4.7951 * albedo + 0.6417, 2.7552 * albedo + 0.6903
    v = ao[:, None]
    return np.maximum(v, ((v * a + b) * v + c) * v)


def lobe(v, n, nov, alpha, rough, f0, f90, rot, k, spread, prefiltered, dfg):
    """Twin of shade.cl's SPECULAR_LOBE block (see the comment there): K visible-normal samples,
    each reading the prefiltered chain at its share of the lobe, their weighted mean times the
    DFG table's albedo."""
    pts = sampling.lobe_points(k).astype(np.float32).astype(np.float64)
    t, b = conventions.tangent_frame(n)
    g1 = sampling.g1_smith(nov, alpha)
    nlev = len(prefiltered)
    num = np.zeros((len(n), 3))
    den = np.zeros((len(n), 3))
    for u in pts:
        hz, voh, l, nol = sampling.reflect_ggx_vndf(u, t, b, n, v, nov, alpha)
        ok = (nol > 0) & (voh > 0)
        pdf = g1 * brdf.d_ggx(hz, alpha) / (4 * nov)
        a = np.minimum(np.sqrt(spread / (4 * np.pi * k * pdf)), alpha)
        w = brdf.f_schlick(voh[:, None], f0, f90) * (brdf.v_smith_ggx_correlated(nov, nol, alpha) * 4 * nov * nol / g1)[:, None]
        w = np.where(ok[:, None], w, 0.0)
        num += w * radiance.chain_lookup_twin(prefiltered, to_env(l, rot), np.sqrt(a) * (nlev - 1))
        den += w
    r = 2 * nov[:, None] * n - v
    fallback = radiance.chain_lookup_twin(prefiltered, to_env(r, rot), rough * (nlev - 1))
    li = np.where(den[:, :1] > 0, num / np.where(den > 0, den, 1.0), fallback)
    ab = dfg_lookup(dfg, nov, rough)
    return li * (f0 * ab[:, 0:1] + f90 * ab[:, 1:2])
