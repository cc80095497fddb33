"""What accuracy costs in time: a scene's converged reference, a ladder of approximations each
timed and measured against it, and the Pareto frontier of error against time.

The lighting is a sum of terms (diffuse + specular), each rendered and judged on its own: a
diffuse rung renders the diffuse term alone (specular off) against the diffuse reference, a
specular rung the specular term against the specular reference. Every rung renders the scene at
the study's resolution with the background hidden and emission off (neither is an approximation),
so the object pixels (full coverage in the G-buffer) are what the metrics read.

Reference: the `reference` modes with visibility and every bounce (`bounces`, default unbounded:
the converged answer, interreflection included), stopped when the frame's relative standard
error (its two replicates, render/passes/reference.py) is below `target_noise` or at
`max_samples`; rendered with two seeds, averaged, and its own noise measured from their
difference (relative RMSE / 2: the noise of their mean). Cached by content (scene lighting,
panorama and mesh contents, kernel sources, settings), so a second study reuses it.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from iblbake.errors import InputError
from iblbake.scene import load as scene_load
from iblbake.scene.layout import DELTA_ALPHA
from iblbake.core.metrics import edge_over_interior, error_metrics, halves, object_mask, region_absolute, region_errors
from iblbake.study.ladder import TERMS, Rung

# A term alone: the other term off
# specular off, with what only the split sum reads (unread, the plan would say so in every rung)
NO_SPECULAR = [("effects.specular", "off"), ("effects.ssr", "off"), ("effects.reflection_probes", False)]
TERM_ALONE = {"diffuse": NO_SPECULAR, "specular": [("effects.diffuse", "off")]}
METRIC_NAMES = ("relative_rmse", "mean_relative_error", "max_relative_error", "flip")
WARMUP_BELOW_S = 1.0
WARMUP_BUILT_BELOW_S = 10.0    # a rung whose first render built its programs
# GGX lobes this narrow are mirrors (layout.DELTA_ALPHA on alpha = r^2: roughness 0.01)
MIRROR_ROUGHNESS = math.sqrt(DELTA_ALPHA)


@dataclass
class Settings:
    max_side: int = 320           # the study's resolution: the scene's, scaled to this longer side
    repeats: int = 3              # timed renders per rung (median)
    target_noise: float = 0.003   # per reference seed (their mean: about 0.002)
    max_samples: int = 4096
    batch: int | None = None      # reference batch (None: sized to the device)
    seeds: tuple = (1, 2)
    flip: bool = True
    visibility: bool = True       # the reference traces occlusion (the approximations do not)
    bounces: object = "unbounded"  # the reference's bounces (1: direct light only)


def study_resolution(sc, max_side: int) -> list:
    w, h = sc.data["camera"]["resolution"]
    s = min(1.0, max_side / max(w, h))
    return [max(1, round(w * s)), max(1, round(h * s))]


def base_values(sc, settings: Settings) -> list:
    """What every render of the study sets: its resolution, no background, no emission, no AOVs."""
    vals = [("camera.resolution", study_resolution(sc, settings.max_side)),
            ("environment.background", "hide")]
    vals += [(f"materials.{m}.emissive", [0.0, 0.0, 0.0]) for m in sc.data["materials"]]
    vals += [(f"output.{a}", None) for a in scene_load.AOVS]
    return vals


def pareto(points) -> list:
    """Indices of the points (time, error) that no other point dominates (no slower-or-equal
    time with no-higher error, one of them strictly better), by increasing time."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


class Study:
    """One scene's study: the rungs' scenes, the reference per term, every rung's times and errors."""

    def __init__(self, scene_path, overrides, settings: Settings, *, runtime, bakes, warn=None, progress=None,
                 names=None):
        """scene_path: a scene file, or a Scene (iblbake.scene.load: validated again with each
        rung's values). names: what messages call the settings they suggest (max_side,
        overrides): the command line's flags unless given."""
        from iblbake.render.plan import effect_modes, interreflects

        self.path, self.overrides, self.settings = scene_path, tuple(overrides), settings
        self.name = scene_path.source if isinstance(scene_path, scene_load.Scene) else scene_path
        self.names = {"max_side": "--max-side", "overrides": "--set", **(names or {})}
        self.rt, self.bakes = runtime, bakes
        self._tell = warn or (lambda _m: None)
        self._said: set = set()            # what was said since the rung began (run_rung)
        self._said_once: set = set()       # the panorama's notes, said once a study
        self.progress = progress or (lambda *_: None)
        self.scene = scene_load.load_any(scene_path, overrides, ["study.png"])
        self.base = base_values(self.scene, settings)
        self.fx = effect_modes(self.scene)
        self.terms = [t for t in TERMS if getattr(self.fx, t) != "off"]
        if not self.terms:
            raise InputError(f"{self.name}: the scene lights nothing (no objects, or diffuse and specular "
                             f"both off): there is no approximation to study")
        self.reference: dict = {}          # term -> {"hdr", "noise", ...}
        # whether the reference traces paths here (else it is the direct light, and a "direct
        # only" rung would be the reference itself)
        self.paths = settings.visibility and settings.bounces != 1 and interreflects(self.scene)
        self._mirrors = None
        self._objects = None
        self._normals = None
        self.times = {"reference_s": 0.0, "rungs_s": 0.0, "bakes_s": 0.0}

    def warn(self, message: str) -> None:
        """Say `message` once per rung: a rung renders twice or more (a warm-up, its repeats, the
        diffuse term alone), and each render said the panorama's chromaticities and the probes'
        share outside their volume again. A note on the panorama file itself (it names the file
        first: its chromaticities) is the same on every rung: once a study (trial72: five times)."""
        scene = getattr(self, "scene", None)
        whole = scene is not None and message.startswith(f"{scene.data['environment']['path']}:")
        said = self._said_once if whole else self._said
        if message not in said:
            said.add(message)
            self._tell(message)

    def load(self, values, origin="ladder"):
        return scene_load.load_any(self.path, self.overrides, ["study.png"], values=self.base + values, origin=origin)

    def ref_batch(self) -> int:
        if self.settings.batch:
            return self.settings.batch
        # a GPU pass at a small batch is read-back-bound (one read per batch); a CPU's is not
        return 256 if self.rt.info.kind == "GPU" else 64

    def reference_values(self, term: str, seed: int) -> list:
        s = self.settings
        return TERM_ALONE[term] + NO_SPECULAR[1:] + [(f"effects.{term}", "reference"),
                                                     ("effects.reference.visibility", s.visibility),
                                                     ("effects.reference.bounces", s.bounces),
                                                     ("effects.reference.max_samples", s.max_samples),
                                                     ("effects.reference.target_noise", s.target_noise),
                                                     ("effects.reference.batch", self.ref_batch()),
                                                     ("effects.reference.seed", seed)]

    def _reference_key(self, sc, seed) -> str:
        from iblbake.bake.cache import content_key
        from iblbake.core import sampling
        from iblbake.device.programs import source_hash
        from iblbake.render.bakes import _code_hash
        from iblbake.render.passes.base import lighting_inputs

        # the reference reads neither kind of probe: their settings do not key it
        inputs = {k: v for k, v in lighting_inputs(sc).items() if k not in ("probes", "reflection_probes")}
        return "reference-" + content_key({
            "kind": "reference", "v": 2, "scene": inputs, "seed": seed,
            "files": list(self.bakes.input_hashes(sc).values()),
            "kernels": source_hash(("gbuffer.cl", "paths/reference.cl", "resolve.cl")),
            "host": _code_hash((sampling,))})      # the panorama's sampling tables the kernels read

    def reference_seed(self, term: str, seed: int):
        """(hdr, manifest, cached): one seed of the term's reference, rendered into the cache or
        read back from it."""
        from iblbake.render import render
        from iblbake.bake import cache
        from iblbake.io import images

        sc = self.load(self.reference_values(term, seed), origin="accuracy reference")
        t0 = time.perf_counter()
        holder = {}

        def build(tmp: Path):
            fr = render(sc, runtime=self.rt, cache=self.bakes, warn=self.warn)
            images.write_exr(tmp / "reference.exr", fr.hdr, channels=("R", "G", "B", "A"))
            holder["frame"] = fr
            ref = next(p for p in fr.report["passes"] if p["name"] == "reference")
            return {"kind": "reference", "files": [{"name": "reference.exr"}], "pass": ref,
                    "seconds": round(time.perf_counter() - t0, 4), "device": fr.report["device"]}

        manifest, hit = cache.get_or_build(self.bakes.root, self._reference_key(sc, seed), build, warn=self.warn)
        hdr = holder["frame"].hdr if "frame" in holder else \
            images.read_exr(self.bakes.root / manifest["key"] / "reference.exr")
        return hdr, manifest, hit

    def render_reference(self, term: str) -> dict:
        """The term's reference (two seeds, cached), its noise and what it cost."""
        frames, reports, cached = [], [], []
        for seed in self.settings.seeds:
            t0 = time.perf_counter()
            hdr, manifest, hit = self.reference_seed(term, seed)
            self.times["reference_s"] += time.perf_counter() - t0
            frames.append(hdr)
            reports.append(manifest)
            cached.append(hit)
            self.progress()
        mask = object_mask(frames[0]) & object_mask(frames[1])
        if not mask.any():
            w, h = study_resolution(self.scene, self.settings.max_side)
            raise InputError(f"{self.name}: at {w}x{h} no pixel is fully covered by an object; raise "
                             f"{self.names['max_side']} or move the camera closer")
        if not np.any(frames[0][..., :3][mask]) and not np.any(frames[1][..., :3][mask]):
            # every relative error divides by the reference (a new user's closed room printed 1.5e301%)
            raise InputError(f"{self.name}: the {term} term's reference is black on every object pixel (no light "
                             f"reaches what the camera sees), so its relative errors are undefined; light the scene, "
                             f"or leave the term out ({self.names['overrides']} effects.{term}=off)")
        from iblbake.core.metrics import bulk_relative_rmse, relative_rmse
        seed_a, seed_b = frames[0][..., :3][mask], frames[1][..., :3][mask]
        between = relative_rmse(seed_a, seed_b)
        mean = frames[0].copy()
        mean[..., :3] = 0.5 * (frames[0][..., :3] + frames[1][..., :3])
        out = {"hdr": mean, "mask": mask, "noise": between / 2, "noise_each": between / math.sqrt(2),
               # the same over the 99% of pixels where the seeds agree best: a caustic's rare bright
               # paths can make most of the two-seed difference (docs/manual.md "Reference")
               "noise_bulk": bulk_relative_rmse(seed_a, seed_b) / 2,
               "seeds": list(self.settings.seeds), "cached": cached,
               "samples_per_pixel": [m["pass"]["samples_per_pixel"] for m in reports],
               "stopped": [m["pass"]["stopped"] for m in reports],
               "seconds": [m["seconds"] for m in reports]}
        self.reference[term] = out
        return out

    def mirror_pixels(self) -> np.ndarray:
        """Pixels showing a mirror (roughness < MIRROR_ROUGHNESS), from one G-buffer render whose
        albedo AOV carries each material's roughness. Excluded from the specular metrics where
        the scene has other surfaces: every mode reads a mirror's one direction exactly, and
        what differs there is the panorama's reconstruction filter (the reference's texels, the
        lookups' bilinear), which a sun turns into most of the frame's RMSE."""
        from iblbake.render import render

        vals = [("effects.diffuse", "off"), *NO_SPECULAR, ("output.albedo", "study-roughness.exr")]
        vals += [(f"materials.{m}.base_color", [float(v["roughness"])] * 3)
                 for m, v in self.scene.data["materials"].items()]
        fr = render(self.load(vals, origin="accuracy"), runtime=self.rt, cache=self.bakes, warn=self.warn)
        return object_mask(fr.hdr) & (fr.aovs["albedo"][..., 0] < MIRROR_ROUGHNESS)

    def object_regions(self) -> np.ndarray:
        """Each pixel's object index (-1: none), from one G-buffer render's object AOV: the regions
        the study's region errors read."""
        from iblbake.render import render

        if self._objects is None:
            vals = [("effects.diffuse", "off"), *NO_SPECULAR, ("output.object", "study-object.exr")]
            fr = render(self.load(vals, origin="accuracy"), runtime=self.rt, cache=self.bakes, warn=self.warn)
            self._objects = np.rint(fr.aovs["object"]).astype(int)
            self._normals = fr.aovs["normal"][..., :3]
        return self._objects

    def metal_objects(self) -> list:
        """Indices of the objects of a metallic material (metallic >= 0.5): those whose parts the
        specular term is judged on."""
        mats = self.scene.data["materials"]
        return [i for i, o in enumerate(self.scene.data["objects"])
                if o.get("material") in mats and mats[o["material"]]["metallic"] >= 0.5]

    def region_metrics(self, hdr, ref, mask, term: str = "diffuse") -> dict:
        """The rung's error per object region, keyed by what messages call the object: its mean
        colour's relative error (metrics.region_errors) and the worst of them; the same in absolute
        terms (metrics.mean_errors: the ratio of mean luminances, the worst channel) and the worst
        |ratio - 1| or channel error. For the specular term, each half of each metal object
        (metrics.halves: the side it faces) in absolute terms too, and the halves too small to judge
        with their pixels (`parts_left_out`). For the diffuse term the seams as one number
        (metrics.edge_over_interior: the junctions' one-pixel band over the interior)."""
        regions = self.object_regions()

        def label(k):
            return scene_load.object_label(self.scene.data, k)
        errs = region_errors(hdr, ref, mask, regions)
        absolute = {label(k): rounded(e) for k, e in region_absolute(hdr, ref, mask, regions).items()}
        out = {"region_errors": {label(k): round(v, 5) for k, v in errs.items()},
               "worst_region_error": max(errs.values(), default=0.0), "region_absolute": absolute,
               "worst_region_absolute": max((e["absolute"] for e in absolute.values()), default=0.0)}
        if term == "diffuse":
            eoi = edge_over_interior(hdr, ref, mask, regions, self._normals)
            out["edge_over_interior"] = None if eoi is None else round(eoi, 4)
        if term == "specular":
            parts, left_out = {}, {}
            for k in self.metal_objects():
                kept = halves(self._normals, regions == k)
                for side, e in region_absolute(hdr, ref, mask, kept).items():
                    parts[f"{label(k)} {side}"] = rounded(e)
                for side, sel in halves(self._normals, regions == k, min_pixels=1).items():
                    if side not in kept:            # too few pixels to judge: said, not judged
                        left_out[f"{label(k)} {side}"] = int(sel.sum())
            if parts:
                out["part_absolute"] = parts
                out["worst_part_absolute"] = max(e["absolute"] for e in parts.values())
            if left_out:
                out["parts_left_out"] = left_out
        return out

    def metric_mask(self, term: str, hdr) -> np.ndarray:
        mask = self.reference[term]["mask"] & object_mask(hdr)
        if term == "specular":
            if self._mirrors is None:
                self._mirrors = self.mirror_pixels()
            if (mask & ~self._mirrors).any():
                mask = mask & ~self._mirrors
        return mask

    def rung_values(self, rung: Rung) -> list:
        """The rung's term alone, with its values; a reference rung sees what the study's
        reference sees (visibility, bounces), unless it sets them."""
        own = {k for k, _ in rung.values}
        ref = [(k, v) for k, v in (("effects.reference.visibility", self.settings.visibility),
                                   ("effects.reference.bounces", self.settings.bounces)) if k not in own]
        if self.reflects_frame(rung):
            return ref + rung.values            # both terms: its rays see the whole lit frame
        return TERM_ALONE[rung.term] + ref + rung.values

    def reflects_frame(self, rung: Rung) -> bool:
        """A specular rung with screen-space reflections (its own `effects.ssr`, else the scene's,
        under the split sum): its rays read the frame's lighting, both terms, so it renders both
        and the study subtracts the diffuse term rendered alone."""
        fx, own = self.scene.data["effects"], dict(rung.values)
        ssr = own.get("effects.ssr", fx["ssr"]) in ("on", True)
        return rung.term == "specular" and ssr and own.get("effects.specular", fx["specular"]) == "prefiltered" \
            and fx["diffuse"] != "off"

    def run_rung(self, rung: Rung) -> dict:
        """Render the rung `repeats` times (kernel builds and bakes happen in the first and are
        reported apart); time = median over the renders of its lighting pass (shade or
        reference); frame = median of the whole render."""
        from iblbake.render import lighting_passes, plan, render

        self._said = set()
        sc = self.load(self.rung_values(rung))
        lighting_names = set(lighting_passes(plan(sc)))
        t0 = time.perf_counter()
        lighting, whole, frame = [], [], None
        builds_before = len(self.rt.builds)
        bakes = []
        while len(lighting) < self.settings.repeats:
            first = frame is None
            fr = render(sc, runtime=self.rt, cache=self.bakes, warn=self.warn)
            light = sum(p["seconds"] for p in fr.report["passes"] if p["name"] in lighting_names)
            if first:
                bakes = [b for b in fr.report["bakes"] if b["name"] not in ("geometry", "read_environment")]
            frame = fr
            # The first launch of a program pays its specialisation (PoCL builds the work-group
            # variant then): a warm-up, untimed, unless the pass is long enough not to notice
            # (a new user's SSR rungs at --repeats 1 timed 1.18 s cold, 8 ms warm).
            built = len(self.rt.builds) > builds_before
            if first and light < (WARMUP_BUILT_BELOW_S if built else WARMUP_BELOW_S):
                continue
            lighting.append(light)
            whole.append(fr.report["elapsed_s"])
        if self.reflects_frame(rung):           # the specular term: the frame less its diffuse term
            alone = [(k, v) for k, v in rung.values if k not in dict(NO_SPECULAR)] + NO_SPECULAR
            diffuse = render(self.load(alone), runtime=self.rt, cache=self.bakes, warn=self.warn)
            hdr = frame.hdr.copy()
            hdr[..., :3] -= diffuse.hdr[..., :3]
            frame.hdr = hdr
            frame.png = display(sc, hdr, frame.png)    # errors.png shows the term measured, not the frame
        builds = sum(b["seconds"] for b in self.rt.builds[builds_before:])
        ref = self.reference[rung.term]
        mask = self.metric_mask(rung.term, frame.hdr)
        rung.result = {
            "term": rung.term, "label": rung.label, "configured": rung.configured,
            "values": {k: v for k, v in rung.values}, "mode": sc.data["effects"][rung.term],
            "time_s": statistics.median(lighting), "frame_s": statistics.median(whole),
            "times_s": [round(x, 5) for x in lighting],
            "bake_s": round(sum(b["seconds"] for b in bakes if not b["cached"]), 4),
            "bakes": [{"name": b["name"], "seconds": b["seconds"], "cached": b["cached"]} for b in bakes],
            "kernel_build_s": round(builds, 4), "bytes": lighting_bytes(sc, rung.term, bakes),
            **lightmap_row(bakes),
            **error_metrics(frame.hdr, ref["hdr"], mask, self.settings.flip),
            **self.region_metrics(frame.hdr, ref["hdr"], mask, rung.term)}
        if rung.result["mode"] == "reference":
            # more samples than the reference it is measured against: its error is the reference's
            # own noise, not its own, so it is kept off the frontier (and the study says so)
            samples = sc.data["effects"]["reference"]["max_samples"]
            rung.result["max_samples"] = samples
            rung.result["above_reference"] = samples > max(ref["samples_per_pixel"])
        rung.frame = frame
        self.times["rungs_s"] += time.perf_counter() - t0 - builds - rung.result["bake_s"]
        self.times["bakes_s"] += rung.result["bake_s"] + builds
        self.progress()
        return rung.result

    def configured_frame(self) -> dict:
        """The scene as configured (both terms) against the sum of the term references."""
        from iblbake.render import render

        sc = self.load([])
        fr = render(sc, runtime=self.rt, cache=self.bakes, warn=self.warn)
        ref = np.zeros_like(fr.hdr)
        mask = object_mask(fr.hdr)
        for t in self.terms:
            ref[..., :3] += self.reference[t]["hdr"][..., :3]
            mask &= self.metric_mask(t, fr.hdr)
        ref[..., 3] = 1
        return {"label": "configured frame", **error_metrics(fr.hdr, ref, mask, self.settings.flip)}


def rounded(d: dict) -> dict:
    return {k: round(v, 5) if isinstance(v, float) else v for k, v in d.items()}


def lighting_bytes(sc, term: str, bakes: list) -> int | None:
    """The bytes an engine stores for the term's light, in fp16 (core/bases probe_bytes): per probe
    for probe modes (the irradiance only: the distance moments are every representation's alike),
    the coefficients for SH and a distant basis, every level of the prefiltered chain for the split
    sum and lobe (the DFG table aside); None for the rest (importance reads the radiance chain,
    the reference the panorama)."""
    from iblbake.core import bases
    fx = sc.data["effects"]
    mode = fx[term]
    if term == "diffuse" and mode == "sh":
        return fx["sh_bands"] ** 2 * 3 * 2
    if mode in bases.BASES and mode != "sh":
        return bases.probe_bytes(mode, bases.options_of(mode, fx), 2)
    if mode == "probes":
        from iblbake.core.bases.probes import PROBE_BASES
        p = sc.data["probes"]
        return PROBE_BASES[p["irradiance"]].stored_bytes(p, 2)
    if mode in ("prefiltered", "lobe"):
        return next((b.get("fp16_bytes") for b in bakes if b["name"] == "prefiltered"), None)
    if mode == "lightmap":              # the atlases of its basis, or of its set for the lobe (bake.bytes_of)
        return next((b["bytes"]["specular" if term == "specular" else b["basis"]] for b in bakes
                     if b["name"] == "lightmap"), None)
    return None


def lightmap_row(bakes: list) -> dict:
    """{'lightmap': the lightmap bake's report row (render/units.py Lightmap): its atlas, texels,
    density, rays a texel, basis, bytes of that basis and the bake's own seconds, also when the
    rung read it from the cache}; {} where the rung reads no lightmap."""
    row = next((b for b in bakes if b["name"] == "lightmap"), None)
    if row is None:
        return {}
    keep = ("atlas", "texels", "texels_per_unit", "samples", "basis", "bake_s", "objects_without")
    return {"lightmap": {**{k: row[k] for k in keep}, "bytes": row["bytes"][row["basis"]]}}


def display(sc, hdr, like) -> np.ndarray:
    """`hdr` tone-mapped as the scene's frames are (its 8-bit PNG values, in the shape of `like`)."""
    from iblbake.core import tonemap
    png = tonemap.display_u8(hdr, sc.data["effects"])
    if like is not None and like.shape[-1] == 4:
        png = np.concatenate([png, like[..., 3:]], axis=-1)
    return png


def above_reference(rows) -> list:
    """The reference rungs with more samples than the study's reference (a --max-samples below
    theirs): measured against a noisier reference than themselves."""
    return [r for r in rows if r.get("above_reference")]


def frontiers(rows) -> dict:
    """term -> labels on its Pareto frontier of (time, relative RMSE), by increasing time; rungs
    with more samples than the reference are left out of it (their error is its noise)."""
    out = {}
    for t in TERMS:
        sel = [r for r in rows if r["term"] == t and not r.get("above_reference")]
        if sel:
            out[t] = [sel[i]["label"] for i in pareto([(r["time_s"], r["relative_rmse"]) for r in sel])]
    return out
