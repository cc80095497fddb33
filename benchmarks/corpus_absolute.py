"""The real-time GI corpus (examples/corpus/*.yaml) judged in absolute terms against the converged
reference (issue 59): every scene under each panorama, the irradiance probes' diffuse term (and
SH + GTAO's beside it) per object region, as the ratio of its mean luminance to the truth's and
the worst channel's |mean difference| over the truth's mean, and the term's relative RMSE over
the frame (what seams along wall edges and blotches raise while region means hide them) and the
seams as one number (metrics.edge_over_interior: the junctions' one-pixel band over the interior); the
specular term of the reflection probes (and the distant chain's) on each half of each metal
object (study/accuracy.py Study.region_metrics); the specular term only where the scene has
reflection probes. Prints the Markdown tables docs/benchmarks.md
holds; --json writes every figure.

Run it from the source tree to measure, or name one with --tree (its iblbake and its corpus);
the references are cached by content in --cache, so a second tree whose reference kernels are
the same reuses them:

    .venv/bin/python benchmarks/corpus_absolute.py [--tree DIR] [--panoramas studio,city]
        [--max-side 64] [--max-samples 4096] [--target-noise 0.01] [--scenes corridor,l_room,my_room.yaml]
        [--cache DIR] [--json out.json] [--rung-set KEY=VALUE ...]

--rung-set puts a scene key on every real-time rung, the reference left as it is: docs/manual.md's
quality setting for interiors is `--rung-set probes.rays=4096` (`environment.sun: auto`, the
default, already extracts the lamps and sun where the scene has probes).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import yaml

DIFFUSE = ("probes", "SH + GTAO")
SPECULAR = ("reflection probes", "distant")
BASELINES = ("SH + GTAO", "distant")      # what each term's first rung is judged beside
BOUND_REGION = 0.30        # issue 59: default probes within 30% on every region
BOUND_PART = 0.10          # a reflection probe within 10% on every part of the metal object


def study_scene(path, panorama, args, rt, bakes, root) -> dict:
    from iblbake.render.enclosure import DISTANT_NOTE
    from iblbake.study import accuracy as acc, ladder

    settings = acc.Settings(max_side=args.max_side, repeats=1, target_noise=args.target_noise,
                            max_samples=args.max_samples, flip=False)
    pano = Path(panorama) if Path(panorama).suffix else root / "examples" / "panoramas" / f"{panorama}.exr"
    sets = [f"environment.path={pano}"]

    def warn(message: str):
        # the render's note on a room reflecting the distant panorama, which this script's distant rung
        # does by design (a new user read it as a fault of their scene)
        if DISTANT_NOTE not in message:
            print(f"  warning: {message}", file=sys.stderr)

    def make(extra):
        return acc.Study(path, sets + extra, settings, runtime=rt, bakes=bakes, warn=warn)
    study = make([])
    if not study.scene.data["reflection_probes"] and "specular" in study.terms:
        study = make(["effects.specular=off"])     # no reflection probe to judge: no specular reference
    extra = [(k, yaml.safe_load(v)) for k, _, v in (kv.partition("=") for kv in args.rung_set)]
    # the baselines (SH + GTAO, distant) keep their own mode: --rung-set effects.diffuse=lightmap made the
    # "SH + GTAO" columns the lightmap with GTAO (trial75)
    rungs = [ladder.Rung(r.term, r.label, r.values + [(k, v) for k, v in extra
                                                      if not (r.label in BASELINES and k == f"effects.{r.term}")])
             for r in ladder.realtime_ladder(study.scene, study.fx) if r.label in DIFFUSE + SPECULAR]
    refs = {t: study.render_reference(t) for t in study.terms}
    keep = ("term", "label", "relative_rmse", "region_absolute", "worst_region_absolute", "part_absolute",
            "worst_part_absolute", "edge_over_interior", "time_s")
    # what each rung renders its term with, --rung-set's last (trial74: a lightmap rung read "probes")
    modes = {g.label: dict(g.values).get(f"effects.{g.term}") for g in rungs}
    return {"scene": Path(path).stem, "panorama": Path(panorama).stem, "modes": modes,
            "reference_noise": {t: refs[t]["noise"] for t in study.terms},
            "reference_spp": {t: refs[t]["samples_per_pixel"] for t in study.terms},
            "rungs": [{k: r[k] for k in keep if k in r} for r in (study.run_rung(g) for g in rungs)]}


def short(label: str) -> str:
    """'far end' (objects.1) -> far end; 'gold' (objects.7) +x -> gold +x."""
    name, _, rest = label.partition(" (objects.")
    return f"{name.strip(chr(39))} {rest.partition(')')[2].strip()}".strip()


LEGEND = ("'name xR (A%, tint T%; N px)': R the ratio of the region's (or half's) mean luminance, real-time over "
          "the reference; A its worst channel's |mean difference| over the reference's mean luminance, what the "
          "bounds (regions over 30%, halves over 10%) count; T the colour shift once the luminances match, shown "
          "where the worst channel is mostly that; N its pixels (a few pixels' mean is as noisy as a few pixels). "
          "Each region's (half's) luminance ratio: R alone. Halves the camera sees in under 4 pixels are left "
          "out, named beside the count with their pixels. Reference noise: the frame's relative standard error "
          "per pixel; a region's mean has about that over the square root of its pixels.")


def worst(errors: dict) -> str:
    """The worst entry of {name: mean_errors} as 'name x ratio (absolute a%)', its tint (the
    colour shift once the luminances match) where the worst channel is most of it."""
    name, e = max(errors.items(), key=lambda kv: kv[1]["absolute"])
    tint = f", tint {100 * e['tint']:.0f}%" if e.get("channel", 0) > abs(e["ratio"] - 1) and "tint" in e else ""
    px = f"; {e['pixels']} px" if "pixels" in e else ""              # a JSON written before has none
    return f"{short(name)} x{e['ratio']:.2f} ({100 * e['absolute']:.0f}%{tint}{px})"


def ratios(errors: dict) -> str:
    return ", ".join(f"{short(n)} x{e['ratio']:.2f}" for n, e in errors.items())


def frame(rung, noise) -> str:
    """The term's relative RMSE over the frame, and the same less the reference's own noise (in
    quadrature: what the tests bound)."""
    r = rung["relative_rmse"]
    return f"{100 * r:.1f}% ({100 * max(r * r - noise * noise, 0.0) ** 0.5:.1f}%)"


def edge(rung) -> str:
    """The seams' figure (metrics.edge_over_interior), blank in a JSON written before it."""
    e = rung.get("edge_over_interior")
    return "" if e is None else f"{e:.2f}"


def diffuse_table(results) -> str:
    # the probes rung's columns named by what it rendered (--rung-set effects.diffuse=lightmap: lightmap)
    shown = {res.get("modes", {}).get("probes") or "probes" for res in results}
    m = shown.pop() if len(shown) == 1 else "probes (or as --rung-set gives)"
    out = [f"| scene | panorama | {m}: worst region | {m}: regions over 30% | {m}: frame rel. RMSE "
           f"(less noise) | {m}: edge over interior | {m}: each region's luminance ratio | SH + GTAO: worst region | "
           "SH + GTAO: frame rel. RMSE (less noise) | "
           "reference noise |", "|---|---|---|---|---|---|---|---|---|---|"]
    for res in results:
        rows = {r["label"]: r for r in res["rungs"] if r["term"] == "diffuse"}
        if "probes" not in rows:
            continue
        p, s = rows["probes"], rows.get("SH + GTAO")
        noise = res["reference_noise"]["diffuse"]
        over = sum(e["absolute"] > BOUND_REGION for e in p["region_absolute"].values())
        out.append(f"| {res['scene']} | {res['panorama']} | {worst(p['region_absolute'])} | "
                   f"{over} of {len(p['region_absolute'])} | {frame(p, noise)} | {edge(p)} | {ratios(p['region_absolute'])} | "
                   + (f"{worst(s['region_absolute'])} | {frame(s, noise)} | " if s else "| | ")
                   + f"{100 * res['reference_noise']['diffuse']:.1f}% |")
    return "\n".join(out) + "\n"


def specular_table(results) -> str:
    out = ["| scene | panorama | reflection probe: worst half of the metal object | halves over 10% | "
           "each half's luminance ratio | distant: worst half | reflection probe: frame rel. RMSE (less noise) | "
           "reference noise |", "|---|---|---|---|---|---|---|---|"]
    for res in results:
        rows = {r["label"]: r for r in res["rungs"] if r["term"] == "specular"}
        p, d = rows.get("reflection probes"), rows.get("distant")
        if not p or "part_absolute" not in p:
            continue
        parts, noise = p["part_absolute"], res["reference_noise"]["specular"]
        over = sum(e["absolute"] > BOUND_PART for e in parts.values())
        small = p.get("parts_left_out", {})
        left = f" (left out: {', '.join(f'{short(n)} {v} px' for n, v in small.items())})" if small else ""
        out.append(f"| {res['scene']} | {res['panorama']} | {worst(parts)} | {over} of {len(parts)}{left} | "
                   f"{ratios(parts)} | {worst(d['part_absolute']) if d and 'part_absolute' in d else ''} | "
                   f"{frame(p, noise)} | {100 * noise:.1f}% |")
    return "\n".join(out) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", default=None, help="the source tree to measure (default: this script's)")
    ap.add_argument("--panoramas", default="studio,city",
                    help="comma-separated names of examples/panoramas/ or panorama files")
    ap.add_argument("--scenes", default=None,
                    help="comma-separated corpus names or scene files (default: every corpus scene)")
    ap.add_argument("--max-side", type=int, default=64)
    ap.add_argument("--max-samples", type=int, default=4096)
    ap.add_argument("--target-noise", type=float, default=0.01)
    ap.add_argument("--device", default=None)
    ap.add_argument("--cache", default=None)
    ap.add_argument("--json", default=None)
    ap.add_argument("--rung-set", action="append", default=[], metavar="KEY=VALUE",
                    help="a scene key on every real-time rung (not the reference; the baselines SH + GTAO and "
                         "distant keep their own effects.diffuse and effects.specular); repeatable")
    ap.add_argument("--from-json", default=None, help="print the tables of an earlier run's --json, rendering nothing")
    args = ap.parse_args()
    if args.from_json:
        doc = json.loads(Path(args.from_json).read_text())
        print(diffuse_table(doc["results"]))
        print(specular_table(doc["results"]))
        print(LEGEND)
        return
    root = Path(args.tree or Path(__file__).resolve().parents[1]).resolve()
    sys.path.insert(0, str(root))

    from iblbake.device.runtime import Runtime
    from iblbake.render import Bakes

    rt = Runtime(args.device)
    bakes = Bakes(args.cache)
    names = args.scenes.split(",") if args.scenes else None
    corpus = root / "examples" / "corpus"
    # a name of the corpus, or a scene file of one's own (a path with a suffix): its regions judged alike
    paths = ([Path(n) if Path(n).suffix else corpus / f"{n}.yaml" for n in names] if names
             else sorted(corpus.glob("*.yaml")))
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        sys.exit(f"corpus_absolute.py: no scene {missing[0]} (a corpus name: {', '.join(sorted(q.stem for q in corpus.glob('*.yaml')))}; or a scene file)")
    results = []
    for path in paths:
        for pano in args.panoramas.split(","):
            t0 = time.perf_counter()
            results.append(study_scene(path, pano, args, rt, bakes, root))
            print(f"{path.stem} under {pano}: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
            if args.json:                 # after every study: a run cut short keeps what it measured
                Path(args.json).write_text(json.dumps({"device": rt.device_label, "tree": str(root),
                                                       "args": vars(args), "results": results}, indent=1) + "\n")
    print(f"device: {rt.device_label}; tree {root}; {args.max_side} px on the longer side; reference: two seeds "
          f"to {args.target_noise} or {args.max_samples} samples per pixel\n")
    print(diffuse_table(results))
    print(specular_table(results))
    print(LEGEND)


if __name__ == "__main__":
    main()
