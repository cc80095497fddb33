"""A baked lightmap as files an engine loads (`iblbake lightmap`; docs/manual.md "iblbake lightmap",
docs/conventions.md "Lightmaps in files"), every basis the bake holds written the same way:

  lightmap_BASIS.exr / .ktx2      a basis of one coefficient set (the plain irradiance), or
  lightmap_BASIS_K.exr / .ktx2    its coefficient K: fp16 RGBA atlases, RGB the coefficient, A 1 on
                                  the texels an engine may sample (baked or dilated), 0 elsewhere
  lightmap_BASIS.glsl             lightmapIrradiance(uv1, n): the basis' own GLSL (core/bases) fed by
                                  the atlases, bilinearly
  lightmap.json                   the manifest: the atlas, per basis its files, layout, units and how
                                  to evaluate the irradiance at a normal
  lightmap.gltf + lightmap.bin    the static geometry with TEXCOORD_1, its materials and the camera,
                                  the irradiance as lightmap.png named by IBLBAKE_lightmap
  lightmap.png                    the irradiance in 8 bits (what a glTF may hold: E / its scale, gamma 2.2)
  lightmap_specular_K.exr / .ktx2 where the scene's frame reads `effects.specular: lightmap`: the
  lightmap_specular.glsl          basis' second set, fitted for the radiance (its coefficient K), and
                                  lightmapSpecularRadiance(uv1, n, v, roughness), the radiance along
                                  the warped GGX lobe (the basis' table beside it where it reads one)

A basis' description comes from the probes' registry (core/bases/probes.py PROBE_BASES: its
title, units, options, layout and GLSL), so a basis the bake adds needs nothing here; the two
the lightmap bake has of its own (the plain irradiance, the L1 SH of the radiance) are OWN."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from iblbake.core import sh as core_sh
from iblbake.core.bases.probes import IRRADIANCE_UNITS, PROBE_BASES, RADIANCE_UNITS
from iblbake.render.probes.glsl import SH_GLSL

FORMAT, VERSION = "iblbake-lightmap", 1
EXTENSION = "IBLBAKE_lightmap"          # the glTF extension (docs/conventions.md "Lightmaps in files")
STEM = "lightmap"
SPECULAR = "specular"                   # the lobe's set's stem (lightmap_specular_K)
SH_TERMS = tuple(t.replace("d.", "n.") for t in SH_GLSL)      # sh.h's basis at l <= 2, at the normal n
SH_LAYOUT = "coefficient k = l (l + 1) + m, real orthonormal SH, z polar axis, no Condon-Shortley phase, world frame"


@dataclass
class Basis:
    """How one basis' atlases are read: `floats` coefficient sets (RGB each), the units, the layout
    and evaluation in words, the GLSL functions it needs and lightmapIrradiance's body over the
    coefficients c[0..floats-1] (already filled from the atlases)."""
    name: str
    title: str
    floats: int
    units: str
    layout: str
    evaluate: str
    functions: str
    body: str
    options: dict
    fields: dict        # what evaluates it from lightmap.json alone beside its layout (axes, profiles, factors)


def _sh(name, title, bands, convolved):
    """An SH basis: the radiance's (convolved: False, read with Ahat) or the irradiance's."""
    k = bands * bands
    ahat = [1.0] * k if convolved else [float(a) for a in core_sh.ahat(bands)]      # per coefficient
    terms = " +\n               ".join(f"{a!r} * {y} * c[{i}]" for i, (a, y) in enumerate(zip(ahat, SH_TERMS[:k])))
    what = "E(n) = max(0, sum_k ahat[k] c_k Y_k(n)), Y_k conventions.sh_basis"
    return Basis(name, title, k, IRRADIANCE_UNITS if convolved else RADIANCE_UNITS,
                 f"{k} coefficient sets; {SH_LAYOUT}", what, "", f"    return max({terms}, vec3(0.0));", {},
                 {"ahat": ahat})


OWN = {
    "irradiance": lambda s: Basis("irradiance", "irradiance (non-directional)", 1, IRRADIANCE_UNITS,
                                  "one set: the texel's irradiance at its own normal (no direction)",
                                  "E = the texel's RGB, whatever the normal", "", "    return c[0];", {}, {}),
    # the L1 SH of the incoming radiance, its constant term set so the reading at the texel's normal
    # is its irradiance (render/lightmaps/bake.py project())
    "sh_l1": lambda s: _sh("sh_l1", "SH L1 (radiance)", 2, False),
}


def basis(name: str, settings: dict) -> Basis:
    """The description of basis `name` as the lightmap settings choose its options; its units the
    atlases' (halves, where the registry's files hold float32)."""
    b = OWN[name](settings) if name in OWN else _registry(name, settings)
    b.units = b.units.replace("float32", "fp16")
    return b


def _registry(name: str, settings: dict) -> Basis:
    """A basis of the probes' registry, its fields those `iblbake basis` writes (document_fields)."""
    entry = PROBE_BASES[name]
    if not entry.directional:                 # L2 SH irradiance (the probes' `sh`)
        return _sh(name, entry.title, 3, True)
    m, opts = entry.m, entry.options(settings)
    layout = " ".join(m.__doc__.split("Layout:")[1].split())
    fields = dict(m.document_fields(opts)) if hasattr(m, "document_fields") else {}
    what = fields.pop("formula", "docs/conventions.md 'Directional bases'")
    return Basis(name, entry.title, m.floats(opts), entry.units, f"{m.floats(opts)} coefficient sets; {layout}",
                 f"{what} (the GLSL's {m.GLSL_IRRADIANCE})",
                 entry.functions(settings, "the texel's coefficients (lightmapIrradiance)"),
                 f"    for (int k = 0; k < {m.floats(opts)}; ++k) {m.GLSL_COEFFS}[k] = c[k];\n"
                 f"    return {m.GLSL_IRRADIANCE}(n);", opts, fields)


def held(lm: dict) -> list:
    """The bases a baked lightmap holds: its irradiance and its basis (lm['basis']: lightmap.basis),
    in that order, once each."""
    return [b for b in dict.fromkeys(["irradiance", lm.get("basis")]) if b and b in lm]


def expected(settings: dict) -> list:
    """The bases a bake of a lightmap section will hold (its files are checked before it): the
    irradiance and the section's basis (bake.DEFAULT_BASIS where it has none), once each."""
    from iblbake.render.lightmaps.bake import DEFAULT_BASIS
    return list(dict.fromkeys(["irradiance", settings.get("basis", DEFAULT_BASIS)]))


def coefficient_sets(lm: dict, name: str) -> np.ndarray:
    """A basis' atlases (h, w, floats, 3) of the bake."""
    a = np.asarray(lm[name], np.float64)
    return a.reshape(a.shape[0], a.shape[1], -1, 3)


def atlas_names(name: str, floats: int) -> list:
    """The atlas files' stems of a basis of `floats` coefficient sets."""
    return [f"{STEM}_{name}"] if floats == 1 else [f"{STEM}_{name}_{k}" for k in range(floats)]


ENVIRONMENT = f"{STEM}_environment.exr"   # the residual panorama (probes.files ENVIRONMENT_CONVENTION)


def file_names(bases, settings: dict, specular: dict | None = None, environment: bool = False) -> list:
    """Every file write() writes for a bake holding `bases` (and the lobe's set of options
    `specular`, where it holds one; the residual panorama where lights were extracted:
    `environment`), the manifest last."""
    names = [f"{STEM}.gltf", f"{STEM}.bin", f"{STEM}.png", *([ENVIRONMENT] if environment else [])]
    for name in bases:
        stems = atlas_names(name, basis(name, settings).floats)
        names += [f"{s}.{x}" for s in stems for x in ("exr", "ktx2")] + [f"{STEM}_{name}.glsl"]
    if specular is not None:
        names += specular_files(settings, specular)
    return names + [f"{STEM}.json"]


def specular_files(settings: dict, opts: dict) -> list:
    """The files of the lobe's set (`effects.specular: lightmap`): its atlases, its GLSL, the table
    its basis' GLSL reads (ambient dice's)."""
    entry = PROBE_BASES[settings["basis"]]
    stems = atlas_names(SPECULAR, entry.m.floats(opts))
    return [f"{s}.{x}" for s in stems for x in ("exr", "ktx2")] + [f"{STEM}_{SPECULAR}.glsl"] + \
        ([entry.specular_table] if entry.specular_table else [])


def specular_glsl(lm: dict, settings: dict) -> str:
    """lightmap_specular.glsl: lightmapSpecularRadiance(uv1, n, v, roughness) from the lobe's set."""
    entry, opts = PROBE_BASES[lm["basis"]], lm["specular_options"]
    m, k = entry.m, entry.m.floats(opts)
    stems = atlas_names(SPECULAR, k)
    binds = "\n".join(f"//   lightmapSpecular{i}  {s}.ktx2 (or {s}.exr)" for i, s in enumerate(stems))
    table = f"\n//   {entry.glsl_table}  {entry.specular_table} (nearest: the function filters it)" \
        if entry.specular_table else ""
    uniforms = "\n".join(f"uniform sampler2D lightmapSpecular{i};" for i in range(k))
    fill = "\n".join(f"    {m.GLSL_COEFFS}[{i}] = texture(lightmapSpecular{i}, uv1).rgb;" for i in range(k))
    size = f"{lm['layout'].width} x {lm['layout'].height}"
    return f"""// iblbake lightmap, the specular lobe's set: {size} texels, {entry.title} fitted for the
// radiance ({m.label(opts)}); lightmap.json holds the conventions. Bind each atlas
// as a 2D float texture, first (top) row at t = 0, linear filtering, clamped to the edge:
{binds}{table}
// specular = (F0 A + F90 B) (the split sum's DFG table at n.v, roughness)
//            * lightmapSpecularRadiance(uv1, n, v, roughness): n the unit shading normal, v the unit
// vector towards the viewer (world frame), uv1 the mesh's TEXCOORD_1.
{uniforms}
{entry.functions({**settings, **opts}, "the texel's coefficients (lightmapSpecularRadiance)")}
vec3 lightmapSpecularRadiance(vec2 uv1, vec3 n, vec3 v, float roughness) {{
{fill}
    return {m.GLSL_SPECULAR}(n, v, roughness);
}}
"""


def rgba(coeff, valid) -> np.ndarray:
    """One coefficient atlas (h, w, 3) as RGBA float32, A the texels an engine may sample."""
    return np.concatenate([np.asarray(coeff, np.float32), valid[..., None].astype(np.float32)], -1)


def glsl(lm: dict, b: Basis) -> str:
    """lightmap_BASIS.glsl: lightmapIrradiance(uv1, n) from the basis' atlases."""
    lay = lm["layout"]
    stems = atlas_names(b.name, b.floats)
    binds = "\n".join(f"//   lightmapCoefficient{k}  {s}.ktx2 (or {s}.exr)" for k, s in enumerate(stems))
    uniforms = "\n".join(f"uniform sampler2D lightmapCoefficient{k};" for k in range(b.floats))
    fill = "\n".join(f"    c[{k}] = texture(lightmapCoefficient{k}, uv1).rgb;" for k in range(b.floats))
    return f"""// iblbake lightmap: {lay.width} x {lay.height} texels, {b.title} ({b.name}); lightmap.json holds the
// conventions. Bind each atlas as a 2D float texture with its first (top) row at t = 0, linear
// filtering, clamped to the edge:
{binds}
// uv1 is the mesh's TEXCOORD_1 (lightmap.gltf), n the unit shading normal (world frame):
// diffuse = albedo / PI * lightmapIrradiance(uv1, n). Units: {b.units.split(";")[0]}.
{uniforms}
{b.functions}
vec3 lightmapIrradiance(vec2 uv1, vec3 n) {{
    vec3 c[{b.floats}];
{fill}
{b.body}
}}
"""


LIGHTS_CONVENTION = (
    "the lights whose direct light an engine draws per pixel, as the frame does: not in the atlases (a texel's "
    "paths add each at every later vertex, so its bounce is in them, never along their own first ray), neither the "
    "scene's lights (source lights.N) nor those extracted from the panorama (environment.sun: extract; the "
    "panorama the texels saw lacks them); adding them to the lightmap's light counts them twice. ")


def manifest(lm: dict, settings: dict, scale: float, objects=(), lights=(), environment: dict | None = None) -> dict:
    """lightmap.json: the atlas, every basis' files and reading, the glTF's, the bake's report;
    `objects` (gltf_scene.lightmapped) each object's name and glTF node; `lights`
    (probes.light_entries) those an engine draws per pixel; `environment` (probes'
    environment_entry) the residual panorama where lights were extracted."""
    from iblbake.render.probes.files import ENVIRONMENT_CONVENTION, LIGHT_FIELDS
    from iblbake.io.guard import mark
    from iblbake.render.lightmaps import gltf_scene
    from iblbake.render.lightmaps.uv import PADDING
    lay, rep = lm["layout"], lm["report"]
    bases = {}
    for name in held(lm):
        b = basis(name, settings)
        stems = atlas_names(name, b.floats)
        bases[name] = {"title": b.title, "floats": b.floats, "options": b.options, "units": b.units,
                       "layout": b.layout, "irradiance": b.evaluate, "exr": [f"{s}.exr" for s in stems],
                       "ktx2": [f"{s}.ktx2" for s in stems], "glsl": f"{STEM}_{name}.glsl", **b.fields}
    if "specular" in lm:
        entry, opts = PROBE_BASES[lm["basis"]], lm["specular_options"]
        stems = atlas_names(SPECULAR, entry.m.floats(opts))
        bases[SPECULAR] = {
            "title": f"{entry.title} for the specular lobe", "basis": lm["basis"], "floats": entry.m.floats(opts),
            "options": opts, "units": RADIANCE_UNITS.split(";")[0].replace("float32", "fp16"),
            "layout": f"{entry.m.floats(opts)} coefficient sets, the basis' layout (bases.{lm['basis']}) with these "
                      "options, fitted to the radiance over the sphere (the lower hemisphere the upper's mirror)",
            "specular": "(F0 A + F90 B) x the radiance along the warped GGX lobe (the GLSL's "
                        "lightmapSpecularRadiance(uv1, n, v, roughness)); A, B the split sum's DFG table at (n.v, "
                        "roughness): an engine's own, or iblbake mips' dfg.exr (R = A, G = B)",
            "exr": [f"{s}.exr" for s in stems], "ktx2": [f"{s}.ktx2" for s in stems],
            "glsl": f"{STEM}_{SPECULAR}.glsl", **({"table": entry.specular_table} if entry.specular_table else {}),
            # the lobes' own (the set's sharpness is its NNLS options', not the diffuse set's)
            **{k: v for k, v in (entry.m.document_fields(opts) if hasattr(entry.m, "document_fields") else {}).items()
               if k in ("axes", "sharpness")}}
    return {
        "format": FORMAT, "version": VERSION, "generator": mark(),
        "atlas": {"width": lay.width, "height": lay.height, "texels_per_unit": rep["texels_per_unit"],
                  "padding": PADDING, "texels": rep["texels"], "uv_sources": rep["uv_sources"]},
        "bases": bases,
        "objects": [{"index": oid, "name": name, "gltf_node": node} for node, (oid, name) in enumerate(objects)],
        "lights": list(lights),
        **({"environment": environment} if environment else {}),
        "gltf": {"file": f"{STEM}.gltf", "extension": EXTENSION, "image": f"{STEM}.png",
                 "encoding": gltf_scene.ENCODING,
                 "irradiance_scale": scale},
        "conventions": {
            "uv": "TEXCOORD_1 in [0, 1]^2, (0, 0) the atlas' top-left corner (glTF's), texel (i, j) covers "
                  "[i, i + 1] x [j, j + 1] / (width, height), its centre at half-integers (a GPU's linear filter)",
            "channels": "RGB: one coefficient set of the basis (linear, fp16); A: 1 on texels baked or dilated "
                        "(safe to sample), 0 on texels no chart reaches",
            "files": "EXR (OpenEXR, half, channels R G B A, first row at the top) and KTX2 (R16G16B16A16_SFLOAT, "
                     "orientation rd) hold the same values",
            "diffuse": "(1 - F_r(n.v)) (1 - metallic) base_color / pi * E(n), E the basis' irradiance at the "
                       "shading normal n (a normal map's included for a directional basis), F_r the roughness-aware "
                       "Schlick F0 + (max(F90 - roughness, F0) - F0) (1 - n.v)^5 (F0 = mix(specular min(0.04 "
                       "specular_color, 1), base_color, metallic), F90 = mix(specular, 1, metallic): a Lambert "
                       "`specular: 0` surface albedo / pi * E)",
            "linear": "every atlas and light is linear scene radiometry (environment.intensity applied): the "
                      "frame's output.exposure and tone mapping come after shading, an engine's own likewise",
            "frame": "world, right-handed, +y up (the scene's and glTF's)",
            "sh_basis": "Y_k(n), k = l (l + 1) + m: " + "; ".join(SH_TERMS),
            "lights": LIGHTS_CONVENTION + LIGHT_FIELDS,
            **({"environment": ENVIRONMENT_CONVENTION} if environment else {}),
        },
        "settings": {k: v for k, v in settings.items()},
        "report": rep,
    }


def write(lm: dict, sc, folder: Path, batch, lights=(), environment=None) -> dict:
    """Every file of the bake into folder through `batch` (atomic.Batch: replaced together or
    none); the manifest written, with `lights` (manifest); `environment` the residual panorama
    (Bakes.environment's image where lights were extracted: ENVIRONMENT), or None."""
    from iblbake.render.probes.files import environment_entry, write_environment
    from iblbake.io import images, ktx2
    from iblbake.io.guard import mark
    from iblbake.render.lightmaps import gltf_scene
    folder = Path(folder)
    settings = sc.data["lightmap"]
    valid = np.asarray(lm["valid"], bool)
    for name in held(lm):
        b = basis(name, settings)
        sets = coefficient_sets(lm, name)
        for k, stem in enumerate(atlas_names(name, b.floats)):
            img = rgba(sets[..., k, :], valid)
            images.write_exr(folder / f"{stem}.exr", img, half=True, channels=("R", "G", "B", "A"), batch=batch)
            batch.write_bytes(folder / f"{stem}.ktx2", ktx2.image_bytes(img, "rgba16f", writer=mark(),
                                                                           metadata={"iblbake.basis": name}))
        batch.write_text(folder / f"{STEM}_{name}.glsl", glsl(lm, b))
    if "specular" in lm:
        _write_specular(lm, settings, folder, valid, batch)
    scale = gltf_scene.write(lm, sc, folder, STEM, EXTENSION, batch)
    env = None
    if environment is not None:
        write_environment(environment, folder / ENVIRONMENT, batch)
        env = environment_entry(sc.data["environment"], ENVIRONMENT)
    man = manifest(lm, settings, scale, gltf_scene.lightmapped(lm, sc), lights, env)
    batch.write_text(folder / f"{STEM}.json", json.dumps(man, indent=1, allow_nan=False) + "\n")
    return man



def _write_specular(lm: dict, settings: dict, folder: Path, valid, batch) -> None:
    """The lobe's set's atlases, GLSL and table (specular_files) through batch."""
    from iblbake.io import images, ktx2
    from iblbake.io.guard import mark
    entry, opts = PROBE_BASES[lm["basis"]], lm["specular_options"]
    sets = coefficient_sets(lm, SPECULAR)
    for k, stem in enumerate(atlas_names(SPECULAR, entry.m.floats(opts))):
        img = rgba(sets[..., k, :], valid)
        images.write_exr(folder / f"{stem}.exr", img, half=True, channels=("R", "G", "B", "A"), batch=batch)
        batch.write_bytes(folder / f"{stem}.ktx2", ktx2.image_bytes(img, "rgba16f", writer=mark(),
                                                                       metadata={"iblbake.basis": lm["basis"]}))
    batch.write_text(folder / f"{STEM}_{SPECULAR}.glsl", specular_glsl(lm, settings))
    if entry.specular_table:
        images.write_exr(folder / entry.specular_table, entry.table_image(), channels=("R",), batch=batch)
