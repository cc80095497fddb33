"""What accuracy costs in time: a scene's converged reference, a ladder of approximations each
timed and measured against it, and the Pareto frontier of error against time.

The lighting is a sum of terms (diffuse + specular), each rendered and judged on its own: a
diffuse rung renders the diffuse term alone (specular off) against the diffuse reference, a
specular rung the specular term against the specular reference. Every rung renders the scene at
the study's resolution with the background hidden and emission off (neither is an approximation),
so the object pixels (full coverage in the G-buffer) are what the metrics read.

Reference: the `reference` modes with visibility, stopped when the frame's relative standard
error (its two replicates, render/passes/reference.py) is below `target_noise` or at
`max_samples`; rendered with two seeds, averaged, and its own noise measured from their
difference (relative RMSE / 2: the noise of their mean). Cached by content (scene lighting,
panorama and mesh contents, kernel sources, settings), so a second study reuses it.
"""

from __future__ import annotations

import csv
import io
import math
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iblbake.errors import InputError
from iblbake.scene import load as scene_load
from iblbake.study import sweep

LUM = np.array([0.2126, 0.7152, 0.0722])
TERMS = ("diffuse", "specular")
# A term alone: the other term off
TERM_ALONE = {"diffuse": [("effects.specular", "off")], "specular": [("effects.diffuse", "off")]}
METRIC_NAMES = ("relative_rmse", "mean_relative_error", "max_relative_error", "flip")
IMPORTANCE_N = (1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 4096)
WARMUP_BELOW_S = 1.0
# GGX lobes this narrow are mirrors (kernels/reference.cl DELTA_ALPHA = 1e-4 on alpha = r^2)
MIRROR_ROUGHNESS = 0.01


@dataclass
class Rung:
    term: str                     # diffuse | specular
    label: str
    values: list                  # [(key path, value)] on top of the scene
    configured: bool = False      # the scene's own setting of this term
    result: dict = field(default_factory=dict)
    frame: object = None          # the last render (render.Frame)


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


def study_resolution(sc, max_side: int) -> list:
    w, h = sc.data["camera"]["resolution"]
    s = min(1.0, max_side / max(w, h))
    return [max(1, round(w * s)), max(1, round(h * s))]


def base_values(sc, settings: Settings) -> list:
    """What every render of the study sets: its resolution, no background, no emission, no AOVs."""
    vals = [("camera.resolution", study_resolution(sc, settings.max_side)),
            ("environment.background", "hide")]
    vals += [(f"materials.{m}.emissive", [0.0, 0.0, 0.0]) for m in sc.data["materials"]]
    vals += [(f"output.{a}", None) for a in ("normal", "albedo", "depth")]
    return vals


def configured_rung(sc, term: str) -> Rung:
    fx = sc.data["effects"]
    if term == "diffuse":
        mode = fx["diffuse"]
        vals = [("effects.diffuse", mode)]
        label = f"SH {fx['sh_bands']} bands" + ("" if fx["sh_window"] == "none" else f" {fx['sh_window']}") \
            if mode == "sh" else mode
    else:
        mode = fx["specular"]
        vals = [("effects.specular", mode)]
        label = {"importance": f"importance N={fx['samples']}", "lobe": f"lobe K={fx['lobe']['samples']}"}.get(mode, mode)
    return Rung(term, f"configured: {label}", vals, configured=True)


# FIS chain bakes per sample count: N = 1024 over render's 13 lobe-sized levels is a 2-minute bake
# on a 2-core CPU (no more accurate than spectral): GPUs only by default, --ladder elsewhere
FIS_SAMPLES = {"GPU": (64, 256, 1024), "CPU": (64, 256)}


def default_ladder(sc, fx, device_kind: str = "GPU") -> list:
    """The rungs of the terms the scene calls for (fx: plan.effect_modes of the scene): a
    diffuse-only scene runs only diffuse rungs. One factor at a time around the defaults."""
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
    lights = sc.data["lights"]
    for term in TERMS:                   # every light's shadows at once: none, hard, soft at 4 and 16
        if getattr(fx, term) != "off" and lights:
            for label, mode, n in (("none", "none", 16), ("hard", "hard", 16), ("soft 4", "soft", 4),
                                   ("soft 16", "soft", 16)):
                rungs.append(Rung(term, f"shadows {label}", [v for i in range(len(lights)) for v in (
                    (f"lights.{i}.shadows", mode), (f"lights.{i}.shadow_samples", n))]))
    for term in TERMS:                   # AO on the approximate IBL (the reference has visibility)
        if getattr(fx, term) in ("sh", "importance", "prefiltered", "lobe"):
            rungs.append(Rung(term, "ao gtao", [("effects.ao", "gtao")]))
            for n in (16, 64):
                rungs.append(Rung(term, f"ao raytraced {n}", [("effects.ao", "raytraced"), ("effects.ao_samples", n)]))
    for term in TERMS:                   # fewer reference samples: Monte Carlo's own trade
        if getattr(fx, term) != "off":
            for n in (16, 64, 256):
                rungs.append(Rung(term, f"reference {n} spp", [
                    (f"effects.{term}", "reference"), ("effects.reference.max_samples", n),
                    ("effects.reference.target_noise", 0.0), ("effects.reference.seed", 7)]))
    return rungs


def ladder_from_file(path, sc, fx) -> list:
    """rungs: a list of axes in the sweep syntax ({key, values}, {key, range}, {steps}), each
    with an optional `term:` (default: diffuse where it sets effects.diffuse or effects.sh_*, else
    specular) and `with:` ({KEY.PATH: value} set on each of its rungs)."""
    import yaml

    where = str(path)
    try:
        doc = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except OSError as e:
        raise InputError(f"{where}: cannot read the ladder ({e.strerror})") from None
    except yaml.YAMLError as e:
        raise InputError(f"{where}: not valid YAML ({' '.join(str(e).split())[:160]})") from None
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


# --- metrics -----------------------------------------------------------------------------------

def object_mask(hdr) -> np.ndarray:
    """Pixels fully covered by objects (coverage 1 in every sample of the G-buffer)."""
    return hdr[..., 3] >= 1.0


def error_metrics(got, ref, mask, flip: bool = True) -> dict:
    """Over the mask, luminance-based except relative RMSE (RGB, metrics.relative_rmse):
    mean and max of |L - L_ref| / (L_ref + eps), eps = 1% of the mean reference luminance (so
    black pixels do not divide by zero), and mean HDR-FLIP over the mask."""
    from iblbake.core.metrics import relative_rmse

    g, r = got[..., :3][mask].astype(np.float64), ref[..., :3][mask].astype(np.float64)
    lg, lr = g @ LUM, r @ LUM
    eps = 0.01 * max(lr.mean(), 1e-30)
    rel = np.abs(lg - lr) / (lr + eps)
    out = {"relative_rmse": relative_rmse(g, r), "mean_relative_error": float(rel.mean()),
           "max_relative_error": float(rel.max()), "flip": None}
    if flip:
        out["flip"] = hdr_flip(got, ref, mask)
    return out


def hdr_flip(got, ref, mask) -> float:
    import flip_evaluator

    a = np.ascontiguousarray(np.clip(ref[..., :3], 0, None), np.float32)
    b = np.ascontiguousarray(np.clip(got[..., :3], 0, None), np.float32)
    if min(a.shape[:2]) < 2:
        return float(np.abs(a - b)[mask].mean())
    err = flip_evaluator.evaluate(a, b, "HDR", applyMagma=False)[0]     # the per-pixel error map
    return float(np.asarray(err).reshape(mask.shape)[mask].mean())


def error_image(got, ref, mask, top: float = 0.5) -> np.ndarray:
    """An 8-bit heat map (magma) of |L - L_ref| / (L_ref + eps), 0 .. top; black off the mask."""
    from matplotlib import colormaps

    lg, lr = got[..., :3] @ LUM, ref[..., :3] @ LUM
    eps = 0.01 * max(float(lr[mask].mean()) if mask.any() else 0.0, 1e-30)
    rel = np.clip(np.abs(lg - lr) / (lr + eps) / top, 0, 1)
    rgb = (colormaps["magma"](rel)[..., :3] * 255 + 0.5).astype(np.uint8)
    rgb[~mask] = 0
    return rgb


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


# --- running -------------------------------------------------------------------------------------

class Study:
    """One scene's study: the rungs' scenes, the reference per term, every rung's times and errors."""

    def __init__(self, scene_path, overrides, settings: Settings, *, runtime, bakes, warn=None, progress=None):
        from iblbake.render.plan import effect_modes

        self.path, self.overrides, self.settings = scene_path, tuple(overrides), settings
        self.rt, self.bakes = runtime, bakes
        self.warn = warn or (lambda _m: None)
        self.progress = progress or (lambda *_: None)
        self.scene = scene_load.load(scene_path, overrides, ["study.png"])
        self.base = base_values(self.scene, settings)
        self.fx = effect_modes(self.scene)
        self.terms = [t for t in TERMS if getattr(self.fx, t) != "off"]
        if not self.terms:
            raise InputError(f"{scene_path}: the scene lights nothing (no objects, or diffuse and specular "
                             f"both off): there is no approximation to study")
        self.reference: dict = {}          # term -> {"hdr", "noise", ...}
        self._mirrors = None
        self.times = {"reference_s": 0.0, "rungs_s": 0.0, "bakes_s": 0.0}

    def load(self, values, origin="ladder"):
        return scene_load.load(self.path, self.overrides, ["study.png"], values=self.base + values, origin=origin)

    def ref_batch(self) -> int:
        if self.settings.batch:
            return self.settings.batch
        # a GPU pass at a small batch is read-back-bound (one read per batch); a CPU's is not
        return 256 if self.rt.info.kind == "GPU" else 64

    def reference_values(self, term: str, seed: int) -> list:
        s = self.settings
        return TERM_ALONE[term] + [(f"effects.{term}", "reference"),
                                   ("effects.reference.visibility", s.visibility),
                                   ("effects.reference.max_samples", s.max_samples),
                                   ("effects.reference.target_noise", s.target_noise),
                                   ("effects.reference.batch", self.ref_batch()),
                                   ("effects.reference.seed", seed)]

    def _reference_key(self, sc, seed) -> str:
        from iblbake.bake.cache import content_key
        from iblbake.device.runtime import source_hash
        from iblbake.render.passes.base import lighting_inputs

        inputs = lighting_inputs(sc)
        return "reference-" + content_key({
            "kind": "reference", "v": 1, "scene": inputs, "seed": seed,
            "files": [self.bakes.file_sha256(f) for f in scene_load.input_files(sc)[1:]],
            "kernels": source_hash(("gbuffer.cl", "reference.cl", "resolve.cl"))})

    def reference_seed(self, term: str, seed: int):
        """(hdr, manifest, cached): one seed of the term's reference, rendered into the cache or
        read back from it."""
        from iblbake import render
        from iblbake.bake import cache
        from iblbake.io import images

        sc = self.load(self.reference_values(term, seed), origin="accuracy reference")
        t0 = time.perf_counter()
        holder = {}

        def build(tmp: Path):
            fr = render.render(sc, runtime=self.rt, cache=self.bakes, warn=self.warn)
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
            raise InputError(f"{self.path}: at {w}x{h} no pixel is fully covered by an object; raise --max-side "
                             f"or move the camera closer")
        from iblbake.core.metrics import relative_rmse
        between = relative_rmse(frames[0][..., :3][mask], frames[1][..., :3][mask]) if mask.any() else 0.0
        mean = frames[0].copy()
        mean[..., :3] = 0.5 * (frames[0][..., :3] + frames[1][..., :3])
        out = {"hdr": mean, "mask": mask, "noise": between / 2, "noise_each": between / math.sqrt(2),
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
        from iblbake import render

        vals = [("effects.diffuse", "off"), ("effects.specular", "off"), ("output.albedo", "study-roughness.exr")]
        vals += [(f"materials.{m}.base_color", [float(v["roughness"])] * 3)
                 for m, v in self.scene.data["materials"].items()]
        fr = render.render(self.load(vals, origin="accuracy"), runtime=self.rt, cache=self.bakes, warn=self.warn)
        return object_mask(fr.hdr) & (fr.aovs["albedo"][..., 0] < MIRROR_ROUGHNESS)

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
        reference sees (visibility), unless it sets it."""
        vis = [] if any(k == "effects.reference.visibility" for k, _ in rung.values) else \
            [("effects.reference.visibility", self.settings.visibility)]
        return TERM_ALONE[rung.term] + vis + rung.values

    def run_rung(self, rung: Rung) -> dict:
        """Render the rung `repeats` times (kernel builds and bakes happen in the first and are
        reported apart); time = median over the renders of its lighting pass (shade or
        reference); frame = median of the whole render."""
        from iblbake import render

        sc = self.load(self.rung_values(rung))
        t0 = time.perf_counter()
        lighting, whole, frame = [], [], None
        builds_before = len(self.rt.builds)
        bakes = []
        while len(lighting) < self.settings.repeats:
            first = frame is None
            fr = render.render(sc, runtime=self.rt, cache=self.bakes, warn=self.warn)
            light = sum(p["seconds"] for p in fr.report["passes"] if p["name"] in ("importance", "shade", "reference"))
            if first:
                bakes = [b for b in fr.report["bakes"] if b["name"] not in ("geometry", "read_environment")]
            frame = fr
            # The first launch of a program pays its specialisation (PoCL builds the work-group
            # variant then): a warm-up, untimed, unless the pass is long enough not to notice.
            if first and light < WARMUP_BELOW_S:
                continue
            lighting.append(light)
            whole.append(fr.report["elapsed_s"])
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
            "kernel_build_s": round(builds, 4),
            **error_metrics(frame.hdr, ref["hdr"], mask, self.settings.flip)}
        rung.frame = frame
        self.times["rungs_s"] += time.perf_counter() - t0 - builds - rung.result["bake_s"]
        self.times["bakes_s"] += rung.result["bake_s"] + builds
        self.progress()
        return rung.result

    def configured_frame(self) -> dict:
        """The scene as configured (both terms) against the sum of the term references."""
        from iblbake import render

        sc = self.load([])
        fr = render.render(sc, runtime=self.rt, cache=self.bakes, warn=self.warn)
        ref = np.zeros_like(fr.hdr)
        mask = object_mask(fr.hdr)
        for t in self.terms:
            ref[..., :3] += self.reference[t]["hdr"][..., :3]
            mask &= self.metric_mask(t, fr.hdr)
        ref[..., 3] = 1
        return {"label": "configured frame", **error_metrics(fr.hdr, ref, mask, self.settings.flip)}


def frontiers(rows) -> dict:
    """term -> labels on its Pareto frontier of (time, relative RMSE), by increasing time."""
    out = {}
    for t in TERMS:
        sel = [r for r in rows if r["term"] == t]
        if sel:
            out[t] = [sel[i]["label"] for i in pareto([(r["time_s"], r["relative_rmse"]) for r in sel])]
    return out


# --- reports -------------------------------------------------------------------------------------

COLUMNS = (("term", "term"), ("label", "setting"), ("time_ms", "time ms"), ("bake_s", "bake s"),
           ("relative_rmse", "rel. RMSE"), ("mean_relative_error", "mean rel."), ("max_relative_error", "max rel."),
           ("flip", "HDR-FLIP"), ("pareto", "frontier"))


def table_rows(rows, front) -> list:
    out = []
    for r in rows:
        out.append({"term": r["term"], "label": r["label"], "time_ms": r["time_s"] * 1000, "bake_s": r["bake_s"],
                    "relative_rmse": r["relative_rmse"], "mean_relative_error": r["mean_relative_error"],
                    "max_relative_error": r["max_relative_error"], "flip": r["flip"],
                    "pareto": r["label"] in front.get(r["term"], [])})
    return out


def _fmt(key, v) -> str:
    if v is None:
        return "-"
    if key == "pareto":
        return "*" if v else ""
    if key in ("relative_rmse", "mean_relative_error", "max_relative_error"):
        return f"{100 * v:.2f}%"
    if key == "flip":
        return f"{v:.4f}"
    if key == "time_ms":
        return f"{v:.3g}"
    if key == "bake_s":
        return f"{v:.3f}"
    return str(v)


def markdown(rows, front) -> str:
    lines = ["| " + " | ".join(h for _, h in COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in table_rows(rows, front):
        lines.append("| " + " | ".join(_fmt(k, r[k]) for k, _ in COLUMNS) + " |")
    return "\n".join(lines) + "\n"


def text_table(rows, front) -> str:
    cells = [[h for _, h in COLUMNS]] + [[_fmt(k, r[k]) for k, _ in COLUMNS] for r in table_rows(rows, front)]
    widths = [max(len(c[i]) for c in cells) for i in range(len(COLUMNS))]
    return "\n".join("  ".join(c[i].ljust(widths[i]) if i < 2 else c[i].rjust(widths[i]) for i in range(len(c)))
                     for c in cells) + "\n"


def csv_text(rows, front) -> str:
    buf = io.StringIO()
    keys = [k for k, _ in COLUMNS]
    wr = csv.DictWriter(buf, fieldnames=keys + ["frame_s", "kernel_build_s"], lineterminator="\n")
    wr.writeheader()
    for r, t in zip(rows, table_rows(rows, front)):
        wr.writerow({**t, "frame_s": r["frame_s"], "kernel_build_s": r["kernel_build_s"]})
    return buf.getvalue()


PLOT_SIZE = (1400, 640)          # pixels


def plot(rows, front, path, title: str) -> None:
    """plot_figure written to `path` (PNG, atomic)."""
    import matplotlib.pyplot as plt

    fig = plot_figure(rows, front, title)
    from iblbake.io.atomic import atomic_path
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=fig.dpi, format="png")
    plt.close(fig)


def plot_figure(rows, front, title: str):
    """Log-log error (relative RMSE) against time per frame of the lighting pass, a panel per
    term, each point labelled; the Pareto frontier drawn as a line through its points."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import ticker

    terms = [t for t in TERMS if any(r["term"] == t for r in rows)]
    dpi = 100
    fig, axes = plt.subplots(1, len(terms), figsize=(PLOT_SIZE[0] / dpi, PLOT_SIZE[1] / dpi), dpi=dpi, squeeze=False)
    for ax, t in zip(axes[0], terms):
        sel = [r for r in rows if r["term"] == t]
        on = set(front.get(t, []))
        for r in sel:
            x, y = max(r["time_s"] * 1000, 1e-3), max(r["relative_rmse"], 1e-5)
            ax.scatter([x], [y], s=36 if r["label"] in on else 14,
                       color="tab:red" if r["label"] in on else ("tab:green" if r["configured"] else "tab:gray"),
                       zorder=3)
            ax.annotate(r["label"], (x, y), fontsize=6, xytext=(3, 2), textcoords="offset points",
                        color="black" if r["label"] in on else "dimgray")
        fr = [r for r in sel if r["label"] in on]
        fr.sort(key=lambda r: r["time_s"])
        ax.plot([max(r["time_s"] * 1000, 1e-3) for r in fr], [max(r["relative_rmse"], 1e-5) for r in fr],
                color="tab:red", lw=1.2, zorder=2, label="Pareto frontier")
        ax.set_xscale("log")
        ax.set_yscale("log")
        for axis in (ax.xaxis, ax.yaxis):  # labels at 1, 2, 5 per decade only: a narrow range
            axis.set_major_locator(ticker.LogLocator(base=10, subs=(1.0, 2.0, 5.0)))  # gets a few,
            axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))     # never a pile
            axis.set_minor_formatter(ticker.NullFormatter())
        ax.set_xlabel("time of the lighting pass per frame (ms, median)")
        ax.set_ylabel("relative RMSE against the reference")
        ax.set_title(f"{t}", fontsize=11)
        ax.grid(True, which="both", alpha=0.3)
    # one legend under the panels, where it hides no point
    fig.legend(handles=[plt.Line2D([], [], color="tab:red", lw=1.2, marker="o", label="Pareto frontier"),
                        plt.Line2D([], [], color="tab:green", lw=0, marker="o", label="configured"),
                        plt.Line2D([], [], color="tab:gray", lw=0, marker="o", label="other rungs")],
               loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=12)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    return fig


def error_sheet(study: Study, rungs, title: str) -> np.ndarray:
    """A contact sheet (the sheet code's layout): per term, the reference, then the best
    approximation and the worst rung (lowest and highest relative RMSE; fewer reference samples
    count as an approximation only where nothing else ran), each beside its error map."""
    from iblbake.core import tonemap
    from iblbake.render.frame import Frame
    from iblbake.study import sheet

    fx = study.scene.data["effects"]
    columns = sweep.Axis("columns", "rung", [sweep.Step([], s) for s in
                                             ("reference", "best", "best: error", "worst", "worst: error")])
    rows = sweep.Axis("rows", "term", [])
    results = []
    for i, t in enumerate(study.terms):
        sel = [r for r in rungs if r.term == t and r.result]
        if not sel:
            continue
        rows.steps.append(sweep.Step([], t))
        ref = study.reference[t]
        ref_png = tonemap.to_u8(tonemap.tonemap(ref["hdr"][..., :3], fx["tonemap"], fx["exposure"],
                                                fx["output_transfer"], fx["gamma"]))
        approx = [r for r in sel if r.result["mode"] != "reference"] or sel
        best = min(approx, key=lambda r: r.result["relative_rmse"])
        worst = max(sel, key=lambda r: r.result["relative_rmse"])
        row = len(rows.steps) - 1
        cells = [(ref_png, f"{ref['samples_per_pixel'][0]} spp, noise {100 * ref['noise']:.2f}%")]
        for r in (best, worst):
            mask = study.metric_mask(t, r.frame.hdr)
            cells.append((r.frame.png, f"{r.label}: {100 * r.result['relative_rmse']:.1f}%"))
            cells.append((error_image(r.frame.hdr, ref["hdr"], mask), "|dL| / L, 0 .. 50%"))
        for j, (png, label) in enumerate(cells):
            results.append(sheet.CellResult(sweep.Cell(row, j, [], label),
                                            Frame(np.zeros(png.shape[:2] + (4,), np.float32), png, {}, {})))
    # small study frames (--max-side 64) are enlarged by whole pixels until every header and
    # caption fits under its cell, rather than cutting the words
    w = results[0].frame.png.shape[1] if results else 1
    need = max([sheet.text_width(s.label, sheet.AXIS_PT) for s in columns.steps]
               + [sheet.text_width(r.cell.label, sheet.CAPTION_PT) for r in results])
    k = max(1, math.ceil(need / w))
    if k > 1:
        for r in results:
            r.frame.png = np.repeat(np.repeat(r.frame.png, k, axis=0), k, axis=1)
    lay = sheet.layout(results, rows, columns, title, "values")
    return sheet.assemble(results, rows, columns, title, "values", lay)
