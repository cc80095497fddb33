"""The real-time GI corpus (examples/corpus/*.yaml) judged against the converged reference: every
scene under each panorama through `iblbake accuracy --ladder realtime` (study/ladder.py
realtime_ladder: SH, SH + GTAO, probes; importance, distant split sum, lobe, SSR, reflection probes),
one row per scene, panorama, term and mode: relative RMSE of the term, the worst object's region
error (its mean colour), and the lighting passes' and whole frame's times. Prints the Markdown table
docs/benchmarks.md holds; --json writes every figure.

    .venv/bin/python benchmarks/bench_corpus.py [--panoramas studio,city] [--max-side 96]
        [--max-samples 8192] [--target-noise 0.005] [--scenes box_out,resting] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def study_scene(path, panorama, args, rt, bakes) -> dict:
    from iblbake.study import accuracy as acc, ladder

    settings = acc.Settings(max_side=args.max_side, repeats=args.repeats, target_noise=args.target_noise,
                            max_samples=args.max_samples, flip=False)
    pano = ROOT / "examples" / "panoramas" / f"{panorama}.exr"
    study = acc.Study(path, [f"environment.path={pano}"], settings, runtime=rt, bakes=bakes,
                      warn=lambda m: print(f"  warning: {m}", file=sys.stderr))
    rungs = ladder.realtime_ladder(study.scene, study.fx)
    refs = {t: study.render_reference(t) for t in study.terms}
    rows = [study.run_rung(r) for r in rungs]
    return {"scene": Path(path).stem, "panorama": panorama,
            "reference_noise": {t: refs[t]["noise"] for t in study.terms},
            "reference_spp": {t: refs[t]["samples_per_pixel"] for t in study.terms},
            "rungs": [{k: r[k] for k in ("term", "label", "relative_rmse", "worst_region_error", "region_errors",
                                         "time_s", "frame_s", "bake_s")} for r in rows]}


def markdown(results) -> str:
    out = ["| scene | panorama | term | mode | rel. RMSE | worst object mean | lighting ms | frame ms |",
           "|---|---|---|---|---|---|---|---|"]
    for res in results:
        for r in res["rungs"]:
            out.append(f"| {res['scene']} | {res['panorama']} | {r['term']} | {r['label']} | "
                       f"{100 * r['relative_rmse']:.1f}% | {100 * r['worst_region_error']:.1f}% | "
                       f"{1000 * r['time_s']:.2f} | {1000 * r['frame_s']:.1f} |")
    return "\n".join(out) + "\n"


DIFFUSE = ("SH", "SH + GTAO", "probes", "probes, L2 SH")
SPECULAR = ("importance N=64", "distant", "lobe K=4", "distant + SSR", "reflection probes", "reflection probes + SSR",
            "reflection probes + SSR over them")


def compact(results) -> str:
    """One row per scene and panorama: each mode's relative RMSE of its term (the best of the
    diffuse and of the specular modes in bold), then the median lighting time of every mode."""
    head = ["scene", "panorama"] + [f"diffuse: {m}" for m in DIFFUSE] + [f"specular: {m}" for m in SPECULAR]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    times = {}
    for res in results:
        rows = {r["label"]: r for r in res["rungs"]}
        cells = [res["scene"], res["panorama"]]
        for group in (DIFFUSE, SPECULAR):
            have = [m for m in group if m in rows]
            best = min((rows[m]["relative_rmse"] for m in have), default=None)
            for m in group:
                if m not in rows:
                    cells.append("")
                    continue
                v = f"{100 * rows[m]['relative_rmse']:.1f}%"
                cells.append(f"**{v}**" if rows[m]["relative_rmse"] == best else v)
                times.setdefault(m, []).append(rows[m]["time_s"])
        out.append("| " + " | ".join(cells) + " |")
    import statistics
    out += ["", "| mode | median lighting ms (scenes) |", "|---|---|"]
    out += [f"| {m} | {1000 * statistics.median(times[m]):.2f} ({len(times[m])}) |" for m in DIFFUSE + SPECULAR
            if m in times]
    return "\n".join(out) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--panoramas", default="studio,city")
    ap.add_argument("--scenes", default=None, help="comma-separated names (default: every corpus scene)")
    ap.add_argument("--max-side", type=int, default=96)
    ap.add_argument("--max-samples", type=int, default=8192)
    ap.add_argument("--target-noise", type=float, default=0.005)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--device", default=None)
    ap.add_argument("--cache", default=None)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()

    from iblbake.render import Bakes
    from iblbake.device.runtime import Runtime

    rt = Runtime(args.device)
    bakes = Bakes(args.cache)
    names = args.scenes.split(",") if args.scenes else None
    paths = [p for p in sorted((ROOT / "examples" / "corpus").glob("*.yaml")) if names is None or p.stem in names]
    results = []
    for path in paths:
        for pano in args.panoramas.split(","):
            t0 = time.perf_counter()
            results.append(study_scene(path, pano, args, rt, bakes))
            print(f"{path.stem} under {pano}: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
            if args.json:                 # after every study: a run cut short keeps what it measured
                Path(args.json).write_text(json.dumps({"device": rt.device_label, "args": vars(args),
                                                       "results": results}, indent=1) + "\n")
    print(f"device: {rt.device_label}; {args.max_side} px on the longer side; reference: two seeds to "
          f"{args.target_noise} or {args.max_samples} samples per pixel\n")
    print(compact(results))
    print(markdown(results))


if __name__ == "__main__":
    main()
