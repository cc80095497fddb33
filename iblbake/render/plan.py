"""The effect set of a scene: which lighting modes it resolves to, and which passes run.

effect_modes() reads what the scene asks for and what can have an effect (no objects: no
lighting; every material metallic or black: no diffuse). plan() then asks every pass whether it
runs and collects what the running passes read (bakes) and compile (defines): nothing else
decides what is baked, compiled or run.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field

from iblbake.core import bases
from iblbake.core.bases.probes import PROBE_BASES
from iblbake.scene import materials
from iblbake.scene.load import AOVS, Scene


# a scene naming the removed key effects.reference.paths renders as before, with this note (scene/schema.py)
UNREAD_LIGHTMAP = ("lightmap: not read: effects.diffuse {diffuse} lights the frame; effects.diffuse: lightmap "
                   "bakes and reads it (docs/manual.md 'Lightmaps')")
UNREAD_PROBES = ("probes: not read: effects.diffuse {diffuse} and specular {specular} light the frame; "
                 "effects.diffuse: probes bakes and reads them (docs/manual.md 'iblbake probes')")
REMOVED_PATHS = ("effects.reference.paths is removed and changes nothing: every reference runs the megakernel "
                 "(the wavefront engine, slower on every device measured, is retired); delete the key")

# The modes that approximate image-based light (runtime and baked estimates): AO occludes them,
# the study's AO rungs apply to them. The reference traces true visibility instead.
APPROXIMATE_MODES = {"diffuse": ("sh", "probes", "lightmap") + bases.DIFFUSE,
                     "specular": ("importance", "prefiltered", "lobe", "probes", "lightmap") + bases.SPECULAR}


@dataclass
class Effects:
    diffuse: str          # off | sh | probes | lightmap | reference | a basis of core/bases (DIFFUSE)
    specular: str         # off | importance | prefiltered | lobe | probes | lightmap | reference | a basis (SPECULAR)
    background: str       # hide | show | color | blur
    emissive: bool
    notes: list = field(default_factory=list)
    bounces: int = 1      # the reference's scattering events per path (0: unbounded); 1: direct light

    def approximate(self, term: str) -> bool:
        """Whether `term` (diffuse | specular) is computed by an approximate IBL mode."""
        return getattr(self, term) in APPROXIMATE_MODES[term]

    @property
    def any_approximate(self) -> bool:
        return self.approximate("diffuse") or self.approximate("specular")


def effect_modes(scene: Scene) -> Effects:
    d = scene.data
    fx, env = d["effects"], d["environment"]
    notes = []
    mats = materials.used(scene)             # the scene's and the glTF meshes' own
    diffuse, specular = fx["diffuse"], fx["specular"]
    if not d["objects"]:
        if diffuse != "off" or specular != "off":
            notes.append("no objects: no lighting is computed")
        diffuse = specular = "off"
    elif diffuse != "off" and all((m["metallic"] >= 1.0 and not m["maps"].get("metallic_roughness"))
                                  or max(m["base_color"]) == 0.0 for m in mats):
        notes.append(f"diffuse {diffuse} skipped: every material is metallic or black (kD = 0)")
        diffuse = "off"
    if specular != "prefiltered":            # what only the split sum reads, said where it goes unread
        if fx["ssr"] == "on":
            notes.append(f"effects.ssr: on does nothing with specular {specular}: screen-space reflections replace the "
                         "split sum's reflected environment (effects.specular: prefiltered)")
        if d["reflection_probes"] and fx["reflection_probes"] and specular != "reference":   # the truth: said of none
            notes.append(f"reflection_probes: {len(d['reflection_probes'])} not read with specular {specular}: the "
                         "split sum reads them (effects.specular: prefiltered)")
    notes += unread_basis_options(scene, diffuse, specular)
    bg = env["background"]
    if isinstance(bg, list):
        background = "color"
    elif bg == "show":
        background = "blur" if env["blur"] > 0 else "show"
    else:
        background = "hide"
    emissive = any(max(m["emissive"]) > 0 for m in mats)     # an emissive map multiplies the factor
    bounces = reference_bounces(scene, diffuse, specular, notes)
    if "paths" in (((scene.raw or {}).get("effects") or {}).get("reference") or {}):
        notes.append(REMOVED_PATHS)
    # a section the frame does not read, said, but not of the reference (trial76: noise beside the truth)
    real_time = diffuse != "reference" and specular != "reference"
    if "lightmap" in (scene.raw or {}) and "lightmap" not in (diffuse, specular) and real_time:
        notes.append(UNREAD_LIGHTMAP.format(diffuse=diffuse))
    if "probes" in (scene.raw or {}) and "probes" not in (diffuse, specular) and real_time:
        notes.append(UNREAD_PROBES.format(diffuse=diffuse, specular=specular))
    return Effects(diffuse, specular, background, emissive, notes, bounces)


def unread_basis_options(scene: Scene, diffuse: str, specular: str) -> list:
    """Notes for basis options the scene sets that no basis of its frame reads: effects.sg_lobes
    beside diffuse zh3, or beside probes that store SG (their lobes are probes.sg_lobes), and
    probes.ad_fit beside probes storing SG."""
    raw = scene.raw or {}
    notes = []
    fx = scene.data["effects"]
    distant = bases.frame_basis({**fx, "diffuse": diffuse, "specular": specular})
    reads = set(bases.BASES[distant].OPTIONS) if distant else set()
    for k in (raw.get("effects") or {}):
        owner = next((n for n, m in bases.BASES.items() if k in m.OPTIONS), None)
        if owner and k not in reads:
            notes.append(f"effects.{k} is not read: it is an option of the panorama's {owner} basis, which this "
                         f"frame does not use" + (f" (the probes' basis reads probes.{k})" if "probes" in
                                                 (diffuse, specular) and scene.data["probes"]["irradiance"] == owner
                                                 else ""))
    probes_used = "probes" in (diffuse, specular)
    rep = scene.data["probes"]["irradiance"]
    own = set(PROBE_BASES[rep].option_specs)
    for k in (raw.get("probes") or {}):
        owner = next((n for n, m in bases.BASES.items() if k in m.OPTIONS), None)
        if owner and (k not in own or not probes_used) and probes_used:
            notes.append(f"probes.{k} is not read: it is an option of the {owner} basis, and the probes store {rep}")
    return notes


def _light_passes(scene: Scene, diffuse: str, specular: str) -> bool:
    return ("reference" in (diffuse, specular) and scene.data["effects"]["reference"]["visibility"]
            and interreflects(scene))


def reference_bounces(scene: Scene, diffuse: str, specular: str, notes: list) -> int:
    """The reference's bounces (0: unbounded): 1, the direct light, where no light can pass between
    surfaces (visibility off lights every object alone; one plane, or one sphere seen from outside,
    never sees itself), so that no path code is compiled or run for it. Bounces 1 is the direct
    light of the environment as before paths: no emissive surface lights another there."""
    ref = scene.data["effects"]["reference"]
    if "reference" not in (diffuse, specular):
        return 1
    asked = 0 if ref["bounces"] == "unbounded" else ref["bounces"]
    if asked == 1:
        return 1
    if not ref["visibility"]:
        if asked > 1:                    # a count asked for (unbounded is the default: no note)
            notes.append("reference bounces: 1, as visibility is off (every object lit as if alone)")
        return 1
    return asked if _light_passes(scene, diffuse, specular) else 1


def interreflects(scene: Scene) -> bool:
    """Whether light can leave one surface of the scene and reach another (or the same one): not
    for a lone plane, nor a lone sphere every camera ray starts outside of."""
    objs = scene.data["objects"]
    if len(objs) != 1 or "mesh" in objs[0]:
        return len(objs) > 0
    if "plane" in objs[0]:
        return False
    s, cam = objs[0]["sphere"], scene.data["camera"]
    kind = "perspective" if "perspective" in cam else "orthographic"
    reach = 0.0
    if kind == "orthographic":             # the view's half diagonal: where its rays start
        w, h = cam["resolution"]
        reach = 0.5 * cam[kind]["width"] * math.hypot(1.0, h / w)
    d = math.dist(cam[kind]["position"], s["center"])
    return d <= s["radius"] + reach


@dataclass
class Plan:
    effects: Effects
    passes: list              # the pass objects that run, in order
    bakes: list               # what they read, in the order of the bakes' reads (render/units.py order)
    defines: dict             # pass name -> its kernel defines
    notes: list
    # one program for every pass: a frame with no series after it (each program costs a load,
    # 25-33 ms on a CPU); a series keeps its passes' programs apart (the tone map's, so that
    # exposure and operator sweeps reuse the frame program)
    one_program: bool = False

    def program(self, p) -> tuple:
        """(kernel files, defines) of the program pass p is built in: every running pass of the
        same program (of any, with one_program), their defines united."""
        group = [q for q in self.passes if q.kernel and (self.one_program or q.program == p.program)]
        defines = {}
        for q in group:
            for k, v in self.defines[q.name].items():
                if defines.setdefault(k, v) != v:
                    raise ValueError(f"passes of program {p.program} disagree on {k}")
        return tuple(dict.fromkeys(q.kernel for q in group)), defines

    @property
    def pass_names(self) -> list:
        return [p.name for p in self.passes]

    def to_json(self) -> dict:
        e = self.effects
        return {"diffuse": e.diffuse, "specular": e.specular, "background": e.background,
                "emissive": e.emissive, "ssr": "ssr" in self.pass_names,
                "reflection_probes": "reflection_probes" in self.bakes, "bakes": self.bakes, "passes": self.pass_names,
                "defines": self.defines, "notes": self.notes}


def lighting_passes(pl: Plan) -> list:
    """The names of the passes that light the frame: those that add into radiance, and those whose
    every output only they read (the importance pass's sums, AO's occlusion): what a study times as
    a rung's lighting."""
    names = {p.name for p in pl.passes if "radiance" in p.writes}
    grew = True
    while grew:
        grew = False
        for p in pl.passes:
            if p.name in names or not p.writes:
                continue
            readers = {q.name for q in pl.passes if q is not p and set(q.reads) & set(p.writes)}
            if readers and readers <= names:
                names.add(p.name)
                grew = True
    return [p.name for p in pl.passes if p.name in names]


def plan(scene: Scene, one_program: bool = False) -> Plan:
    from iblbake.render.passes import PASSES
    from iblbake.render.units import order

    fx = effect_modes(scene)
    running = [p for p in PASSES if p.runs(scene, fx)]
    wanted = {b for p in running for b in p.reads_bakes(scene, fx)}
    notes = list(fx.notes)
    out = scene.data["output"]
    if not out["frame"] and not any(out[a] for a in AOVS):
        notes.append("no output requested (output.frame or -o): rendering without writing")
    return Plan(fx, running, order(wanted),
                {p.name: p.defines(scene, fx) for p in running if p.kernel}, notes, one_program)
