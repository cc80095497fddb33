"""The study's ladder: the rungs of approximations `iblbake accuracy` times and measures, one
factor at a time around the defaults (default_ladder), the scene's own settings
(configured_rung), or a ladder file in the sweep syntax (ladder_from_file)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from iblbake.errors import InputError
from iblbake.study import sweep

TERMS = ("diffuse", "specular")
IMPORTANCE_N = (1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 4096)


@dataclass
class Rung:
    term: str                     # diffuse | specular
    label: str
    values: list                  # [(key path, value)] on top of the scene
    configured: bool = False      # the scene's own setting of this term
    result: dict = field(default_factory=dict)
    frame: object = None          # the last render (render.Frame)


def configured_rung(sc, term: str) -> Rung:
    fx = sc.data["effects"]
    if term == "diffuse":
        mode = fx["diffuse"]
        vals = [("effects.diffuse", mode)]
        label = f"SH {fx['sh_bands']} bands" + ("" if fx["sh_window"] == "none" else f" {fx['sh_window']}") \
            if mode == "sh" else mode
        if mode == "lightmap":           # as its rungs name it (lightmap_rungs)
            lm = sc.data["lightmap"]
            label = f"lightmap {lm['basis']} @ {lm['texels_per_unit']:g}"
    else:
        mode = fx["specular"]
        vals = [("effects.specular", mode)]
        label = {"importance": f"importance N={fx['samples']}", "lobe": f"lobe K={fx['lobe']['samples']}"}.get(mode, mode)
        if mode == "prefiltered" and sc.data["reflection_probes"] and fx["reflection_probes"]:
            label += " + reflection probes"
        if mode == "prefiltered" and fx["ssr"] == "on":          # measured over the lit frame
            vals.append(("effects.ssr", "on"))
            label += " + SSR"
    return Rung(term, f"configured: {label}", vals, configured=True)


# FIS chain bakes per sample count: N = 1024 over render's 13 lobe-sized levels is a 2-minute bake
# on a 2-core CPU (no more accurate than spectral): GPUs only by default, --ladder elsewhere
FIS_SAMPLES = {"GPU": (64, 256, 1024), "CPU": (64, 256)}


def default_ladder(sc, fx, device_kind: str = "GPU", paths: bool = False) -> list:
    """The rungs of the terms the scene calls for (fx: plan.effect_modes of the scene): a
    diffuse-only scene runs only diffuse rungs. One factor at a time around the defaults.
    paths: the study's reference traces interreflection here (Study.paths), so "direct only"
    (the reference at bounces 1) is a rung: what ignoring the light between surfaces costs. A
    scene with a lightmap section: its basis at each density, each basis at its own (lightmap_rungs)."""
    rungs = []
    if fx.diffuse != "off":
        for window in ("none", "hann"):
            for bands in range(1, 9):
                rungs.append(Rung("diffuse", f"SH {bands}" + ("" if window == "none" else f" {window}"),
                                  [("effects.diffuse", "sh"), ("effects.sh_bands", bands),
                                   ("effects.sh_window", window)]))
    if fx.specular != "off":
        imp = [("effects.specular", "importance")]
        for n in IMPORTANCE_N:
            rungs.append(Rung("specular", f"importance N={n}", imp + [("effects.samples", n), ("effects.mip_bias", 1.0)]))
        for n in IMPORTANCE_N[:9]:
            rungs.append(Rung("specular", f"importance N={n} bias 0", imp + [("effects.samples", n),
                                                                            ("effects.mip_bias", 0.0)]))
            rungs.append(Rung("specular", f"importance N={n} mip 0", imp + [("effects.samples", n),
                                                                           ("effects.force_mip0", True)]))
        pre = [("effects.specular", "prefiltered")]
        rungs.append(Rung("specular", "prefiltered", pre))
        rungs.append(Rung("specular", "prefiltered no dominant", pre + [("effects.prefilter.dominant_direction", False)]))
        for size in (64, 128, 256, 512):
            rungs.append(Rung("specular", f"prefiltered size {size}", pre + [("effects.prefilter.size", size)]))
        for levels in (5, 7, 9, 17):
            rungs.append(Rung("specular", f"prefiltered {levels} levels", pre + [("effects.prefilter.levels", levels)]))
        rungs.append(Rung("specular", "prefiltered halving levels", pre + [("effects.prefilter.level_sizes", "halving"),
                                                                          ("effects.prefilter.min_size", 8)]))
        rungs.append(Rung("specular", "prefiltered spectral", pre + [("effects.prefilter.method", "spectral")]))
        for n in FIS_SAMPLES.get(device_kind, FIS_SAMPLES["CPU"]):
            rungs.append(Rung("specular", f"prefiltered fis {n}", pre + [("effects.prefilter.method", "fis"),
                                                                        ("effects.prefilter.samples", n)]))
        for k in (1, 2, 4, 8, 16):
            rungs.append(Rung("specular", f"lobe K={k}", [("effects.specular", "lobe"), ("effects.lobe.samples", k)]))
        # the scene reflected: screen-space reflections, and the scene's own reflection probes
        rungs.append(Rung("specular", "prefiltered + ssr", pre + [("effects.ssr", "on"),
                                                                 ("effects.reflection_probes", False)]))
        if sc.data["reflection_probes"]:
            rungs.append(Rung("specular", "prefiltered + reflection probes", pre + [("effects.reflection_probes", True)]))
            rungs.append(Rung("specular", "prefiltered + reflection probes + ssr",
                              pre + [("effects.reflection_probes", True), ("effects.ssr", "on")]))
            rungs.append(Rung("specular", "prefiltered, distant only", pre + [("effects.reflection_probes", False)]))
    lights = sc.data["lights"]
    for term in TERMS:                   # every light's shadows at once: none, hard, soft at 4 and 16
        if getattr(fx, term) != "off" and lights:
            for label, mode, n in (("none", "none", 16), ("hard", "hard", 16), ("soft 4", "soft", 4),
                                   ("soft 16", "soft", 16)):
                rungs.append(Rung(term, f"shadows {label}", [v for i in range(len(lights)) for v in (
                    (f"lights.{i}.shadows", mode), (f"lights.{i}.shadow_samples", n))]))
    if fx.diffuse != "off" and paths:    # irradiance probes: the light between surfaces, baked
        for label, vals in probe_rungs():
            rungs.append(Rung("diffuse", label, [("effects.diffuse", "probes")] + vals))
    own = sc.data["lightmap"]["basis"]  # the scene's lightmap: its basis at each density, each basis at its own
    rungs += lightmap_rungs(sc, fx, (own,)) + lightmap_rungs(sc, fx, [b for b in LIGHTMAP_BASES if b != own], (1.0,))
    for term in TERMS:                   # AO on the approximate IBL (the reference has visibility)
        if fx.approximate(term):
            rungs.append(Rung(term, "ao gtao", [("effects.ao", "gtao")]))
            for n in (16, 64):
                rungs.append(Rung(term, f"ao raytraced {n}", [("effects.ao", "raytraced"), ("effects.ao_samples", n)]))
            if term == "diffuse" and paths:  # Jimenez et al.'s fit of the bounces AO leaves out
                rungs.append(Rung(term, "ao gtao multibounce", [("effects.ao", "gtao"), ("effects.ao_multibounce", True)]))
    for term in TERMS:                   # fewer reference samples: Monte Carlo's own trade
        if getattr(fx, term) != "off":
            def spp(n):
                return [(f"effects.{term}", "reference"), ("effects.reference.max_samples", n),
                        ("effects.reference.target_noise", 0.0), ("effects.reference.seed", 7)]
            for n in (16, 64, 256):
                rungs.append(Rung(term, f"reference {n} spp", spp(n)))
            if paths:                    # the same samples without the bounces: what they cost and buy
                rungs.append(Rung(term, "direct only 256 spp", spp(256) + [("effects.reference.bounces", 1)]))
    return rungs


def realtime_ladder(sc, fx) -> list:
    """The real-time modes of each term the scene calls for, as shipped (`--ladder realtime`; the
    corpus of docs/benchmarks.md): diffuse SH, SH with GTAO, irradiance probes (octahedral, L2 SH),
    the scene's lightmap section as it is (where it has one);
    specular importance N=64, the split sum with the distant panorama alone, the lobe K=4, the
    split sum with SSR, and with the scene's reflection probes, with and without SSR; the lightmap's
    lobe (`specular: lightmap`) where its basis carries one."""
    rungs = []
    if fx.diffuse != "off":
        rungs += [Rung("diffuse", "SH", [("effects.diffuse", "sh"), ("effects.ao", "off")]),
                  Rung("diffuse", "SH + GTAO", [("effects.diffuse", "sh"), ("effects.ao", "gtao")]),
                  Rung("diffuse", "probes", [("effects.diffuse", "probes"), ("effects.ao", "off")]),
                  Rung("diffuse", "probes, L2 SH", [("effects.diffuse", "probes"), ("effects.ao", "off"),
                                                   ("probes.irradiance", "sh")])]
        if lightmapped(sc):
            rungs.append(Rung("diffuse", "lightmap", [("effects.diffuse", "lightmap"), ("effects.ao", "off")]))
    if fx.specular != "off":
        # every rung says whether SSR runs: a scene's `ssr: on` is not to leak into the rungs without it
        distant = [("effects.specular", "prefiltered"), ("effects.reflection_probes", False), ("effects.ao", "off")]
        rungs += [Rung("specular", "importance N=64", [("effects.specular", "importance"), ("effects.samples", 64),
                                                       ("effects.ao", "off")]),
                  Rung("specular", "distant", distant + [("effects.ssr", "off")]),
                  Rung("specular", "lobe K=4", [("effects.specular", "lobe"), ("effects.lobe.samples", 4),
                                                ("effects.ao", "off")]),
                  Rung("specular", "distant + SSR", distant + [("effects.ssr", "on")])]
        if sc.data["reflection_probes"]:
            local = [("effects.specular", "prefiltered"), ("effects.reflection_probes", True), ("effects.ao", "off")]
            rungs += [Rung("specular", "reflection probes", local + [("effects.ssr", "off")]),
                      Rung("specular", "reflection probes + SSR", local + [("effects.ssr", "on")]),
                      Rung("specular", "reflection probes + SSR over them", local + [
                          ("effects.ssr", "on"), ("effects.ssr_settings.defer_to_probes", False)])]
        from iblbake.core.bases.probes import PROBE_BASES
        if lightmapped(sc) and getattr(PROBE_BASES.get(sc.data["lightmap"]["basis"]), "specular", False):
            rungs.append(Rung("specular", "lightmap lobe", [("effects.specular", "lightmap"), ("effects.ao", "off")]))
    return rungs


def distant_specular_rungs(sc, fx) -> list:
    """The split sum's chain and each basis that carries a specular lobe (core/bases SPECULAR), of
    the panorama, every variant fitted for the lobe (specular_variants): the specular term, AO,
    SSR and reflection probes off."""
    from iblbake.core.bases import BASES, SPECULAR, specular_variants
    if fx.specular == "off":
        return []
    off = [("effects.ao", "off"), ("effects.ssr", "off"), ("effects.reflection_probes", False)]
    return [Rung("specular", "prefiltered (distant)", [("effects.specular", "prefiltered")] + off)] + [
        Rung("specular", f"{BASES[name].label(opts)} specular",
             [("effects.specular", name), *((f"effects.{k}", v) for k, v in opts.items())] + off)
        for name in SPECULAR for opts in specular_variants(name)]


def bases_ladder(sc, fx) -> list:
    """Every registered directional basis and size of the panorama (`--ladder bases`; core/bases,
    the shoot-out of docs/benchmarks.md): the diffuse term of each, AO off, and the specular term
    of those that carry a lobe beside the split sum's chain."""
    from iblbake.core.bases import BASES
    rungs = []
    if fx.diffuse != "off":
        rungs = [Rung("diffuse", m.label(opts), [("effects.diffuse", name),
                                                 *((f"effects.{k}", v) for k, v in opts.items()), ("effects.ao", "off")])
                 for name, m in BASES.items() for opts in m.variants()]
    return rungs + distant_specular_rungs(sc, fx)


def probe_bases_ladder(sc, fx) -> list:
    """Every representation the irradiance probes can store (`--ladder probe_bases`: the octahedral
    map, L2 SH, and each registered basis and size that fits from a probe's rays: core/bases/probes.py
    PROBE_BASES), the scene's probes section otherwise as it is: the probes' diffuse term; and the
    specular term from each basis that carries it (core/bases SPECULAR) beside the split sum's
    chain, of the panorama and of the probes (`specular: probes`). AO off."""
    from iblbake.core.bases import specular_variants
    from iblbake.core.bases.probes import PROBE_BASES
    rungs = []
    if fx.diffuse != "off" and sc.data["objects"]:
        base = [("effects.diffuse", "probes"), ("effects.ao", "off")]
        rungs += [Rung("diffuse", f"probes, {b.label(opts)}",
                       base + [("probes.irradiance", name), *((f"probes.{k}", v) for k, v in opts.items())])
                  for name, b in PROBE_BASES.items() for opts in b.variants()]
    if fx.specular != "off":
        off = [("effects.ao", "off"), ("effects.ssr", "off"), ("effects.reflection_probes", False)]
        rungs += distant_specular_rungs(sc, fx)
        if sc.data["objects"]:          # the same bases in the probes: the room's light along the lobe
            rungs += [Rung("specular", f"probes, {b.label(opts)} specular",
                           [("effects.specular", "probes"), ("probes.irradiance", name),
                            *((f"probes.{k}", v) for k, v in opts.items())] + off)
                      for name, b in PROBE_BASES.items() if b.specular for opts in specular_variants(name)]
    return rungs


# the lightmap's grid: these bases (every name of render/lightmaps NAMES is a valid lightmap.basis)
# at the scene's texels_per_unit times each scale
LIGHTMAP_BASES = ("irradiance", "sh_l1", "sh", "sg")
LIGHTMAP_SCALES = (0.5, 1.0, 2.0)


def lightmapped(sc) -> bool:
    """Whether the scene asks for a lightmap (a `lightmap:` section in its file or a --set): an
    effect it does not ask for is not studied."""
    return "lightmap" in (sc.raw or {})


def lightmap_rungs(sc, fx, bases=LIGHTMAP_BASES, scales=LIGHTMAP_SCALES) -> list:
    """`lightmap BASIS @ DENSITY`: the diffuse term read from the scene's lightmap section baked in
    each of `bases` at its texels_per_unit x each of `scales` (its other keys as they are), AO off;
    none where the scene has no lightmap section or no diffuse term."""
    if fx.diffuse == "off" or not lightmapped(sc):
        return []
    tpu = sc.data["lightmap"]["texels_per_unit"]
    return [Rung("diffuse", f"lightmap {basis} @ {tpu * k:g}",
                 [("effects.diffuse", "lightmap"), ("effects.ao", "off"), ("lightmap.basis", basis),
                  ("lightmap.texels_per_unit", tpu * k)])
            for k in scales for basis in bases]


def lightmaps_ladder(sc, fx) -> list:
    """The lightmap's grid of resolution x basis (`--ladder lightmaps`: lightmap_rungs), each rung's
    atlas bytes and bake time beside its frame time and error. A scene without a lightmap section
    (or a diffuse term) has nothing to study: one line saying so."""
    why = ("no diffuse term (effects.diffuse: off); give effects.diffuse a mode" if lightmapped(sc) else
           "no lightmap: section; add one (`lightmap: {}` takes the defaults; docs/manual.md 'Lightmaps')")
    if fx.diffuse == "off" or not lightmapped(sc):
        raise InputError(f"{sc.source}: the lightmaps ladder studies the scene's lightmap, and it has {why}")
    return lightmap_rungs(sc, fx)


LADDERS = {"realtime": realtime_ladder, "bases": bases_ladder, "probe_bases": probe_bases_ladder,
           "lightmaps": lightmaps_ladder}  # --ladder NAME


def probe_rungs() -> list:
    """(label, values) of the probe rungs: one factor at a time around 8 probes along the longest
    axis, 1024 rays, octahedral irradiance, DDGI's visibility."""
    base = {"counts": 8, "rays": 1024, "irradiance": "octahedral", "visibility": True}
    steps = [("probes 8", {}), ("probes 4", {"counts": 4}), ("probes 16", {"counts": 16}),
             ("probes 8 rays 256", {"rays": 256}), ("probes 8 rays 4096", {"rays": 4096}),
             ("probes 8 sh", {"irradiance": "sh"}), ("probes 8 no visibility", {"visibility": False})]
    return [(label, [(f"probes.{k}", v) for k, v in {**base, **own}.items()]) for label, own in steps]


def ladder_from_file(path, sc, fx, flag: str = "--ladder") -> list:
    """rungs: a list of axes in the sweep syntax ({key, values}, {key, range}, {steps}), each
    with an optional `term:` (default: diffuse where it sets effects.diffuse or effects.sh_*, else
    specular) and `with:` ({KEY.PATH: value} set on each of its rungs). `flag`: what a message
    naming a built-in ladder calls the setting."""
    from iblbake.io import reads
    from iblbake.scene.yaml_lines import MAX_SCENE_BYTES, load_with_lines

    where = str(path)
    if not Path(path).exists():
        import difflib
        near = difflib.get_close_matches(str(path), list(LADDERS), 1, 0.6)
        hint = f"; did you mean {flag} {near[0]}?" if near else f"; or name a built-in one: {', '.join(LADDERS)}"
        raise InputError(f"{where}: cannot read the ladder (no such file){hint}")
    try:       # as a scene is read: bounded, safe, numbers as a user writes them
        doc = load_with_lines(reads.read_text(path, MAX_SCENE_BYTES, "a ladder"), where)[0]
    except UnicodeDecodeError:
        raise InputError(f"{where}: not a UTF-8 text file; a ladder is YAML") from None
    if not isinstance(doc, dict) or set(doc) != {"rungs"} or not isinstance(doc["rungs"], list) or not doc["rungs"]:
        raise InputError(f"{where}: a ladder is {{rungs: [AXIS, ...]}}, each axis as a sweep's "
                         f"({{key, values}}, {{key, range}} or {{steps}}), with term: and with: optional")
    rungs = []
    for i, spec in enumerate(doc["rungs"]):
        w = f"{where}: rungs.{i}"
        if not isinstance(spec, dict):
            raise InputError(f"{w}: expected a map, got {spec!r}")
        spec = dict(spec)
        term = spec.pop("term", None)
        fixed = spec.pop("with", {}) or {}
        if term is not None and term not in TERMS:
            raise InputError(f"{w}.term: {term!r}: use diffuse or specular")
        if not isinstance(fixed, dict):
            raise InputError(f"{w}.with: expected a map of KEY.PATH: value, got {fixed!r}")
        for k in fixed:
            sweep.resolve_key(k, sc.data, f"{w}.with")
        axis = sweep.parse_axis("rows", spec, sc.data, w, "{key}={value}")
        for st in axis.steps:
            vals = list(fixed.items()) + st.values
            keys = [k for k, _ in vals]
            t = term or ("diffuse" if any(k == "effects.diffuse" or k.startswith("effects.sh_") for k in keys)
                         else "specular")
            if getattr(fx, t) == "off" and not any(k == f"effects.{t}" for k in keys):
                continue                 # a term the scene does not call for
            rungs.append(Rung(t, st.label, vals))
    if not rungs:
        raise InputError(f"{where}: none of its rungs is of a term the scene renders")
    return rungs
