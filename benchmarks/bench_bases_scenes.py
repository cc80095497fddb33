"""The directional bases in scenes, against the converged path-traced reference: every registered
basis and size as the panorama's light (`iblbake accuracy --ladder bases`: diffuse, and specular
where the basis carries a lobe, beside the split sum's chain) on examples/scenes/quick.yaml (two
spheres, gold and red plastic, on a plane: open to the sky), and as what the irradiance probes
store (`--ladder probe_bases`: diffuse, and specular from the probes where the basis carries a
lobe) on examples/corpus/metal_box.yaml (a rough metal cube in an open box of coloured walls),
each under four panoramas (a sun: city; overcast: courtyard; an interior; a studio). One row per
basis and term: bytes (fp16; per probe for the probes), each run's relative RMSE of its term and
their mean, the median lighting time; a plot of the mean error against bytes, one curve per
basis family, diffuse and specular apart (--plot). --json writes every figure.

    .venv/bin/python benchmarks/bench_bases_scenes.py [--panoramas city,courtyard,interior,studio]
        [--max-side 64] [--max-samples 2048] [--target-noise 0.005] [--json out.json] [--plot out.png]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

STUDIES = (("quick", ROOT / "examples" / "scenes" / "quick.yaml", "bases"),
           ("metal_box", ROOT / "examples" / "corpus" / "metal_box.yaml", "probe_bases"))


def study(name, path, ladder_name, panorama, args, rt, bakes) -> dict:
    from iblbake.study import accuracy as acc, ladder

    settings = acc.Settings(max_side=args.max_side, repeats=args.repeats, target_noise=args.target_noise,
                            max_samples=args.max_samples, flip=False)
    pano = ROOT / "examples" / "panoramas" / f"{panorama}.exr"
    st = acc.Study(path, [f"environment.path={pano}", "environment.primaries=keep"], settings, runtime=rt,
                   bakes=bakes, warn=lambda m: print(f"  warning: {m}", file=sys.stderr))
    rungs = ladder.LADDERS[ladder_name](st.scene, st.fx)
    refs = {t: st.render_reference(t) for t in st.terms}
    rows = [st.run_rung(r) for r in rungs]
    return {"scene": name, "panorama": panorama, "ladder": ladder_name,
            "reference_noise": {t: refs[t]["noise"] for t in st.terms},
            "rungs": [{k: r.get(k) for k in ("term", "label", "relative_rmse", "worst_region_error", "time_s",
                                             "bake_s", "bytes")} for r in rows]}


def family(label: str) -> str:
    """A basis family of a rung label, for the plot's curves (sizes and fits apart)."""
    base = label.replace("probes, ", "").replace(" specular", "")
    for prefix in ("SG", "Haar"):
        if base.startswith(prefix):
            fit = " NNLS" if "NNLS" in base else (" LS" if prefix == "SG" else "")
            return f"{'probes ' if label.startswith('probes') else ''}{prefix}{fit}"
    return label


def table(results) -> str:
    """One row per (study, term, setting): bytes, the error under each panorama, their mean, the
    median lighting time."""
    runs = [(r["scene"], r["panorama"]) for r in results]
    keys = {}
    for res in results:
        for row in res["rungs"]:
            keys.setdefault((res["scene"], row["term"], row["label"]), {})[(res["scene"], res["panorama"])] = row
    pans = sorted({p for _, p in runs}, key=[p for _, p in runs].index)
    head = ["scene", "term", "setting", "bytes fp16"] + pans + ["mean", "lighting ms"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for (scene, term, label), by_run in keys.items():
        errs = [by_run[(scene, p)]["relative_rmse"] for p in pans if (scene, p) in by_run]
        any_row = next(iter(by_run.values()))
        b = any_row["bytes"]
        cells = [scene, term, label, "-" if b is None else str(b)]
        cells += [f"{100 * by_run[(scene, p)]['relative_rmse']:.1f}%" if (scene, p) in by_run else "" for p in pans]
        cells += [f"{100 * statistics.mean(errs):.1f}%",
                  f"{1000 * statistics.median(r['time_s'] for r in by_run.values()):.2f}"]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def plot(results, path) -> None:
    """Mean relative RMSE against bytes, one curve per family, one panel per (scene, term)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = {}
    for res in results:
        for row in res["rungs"]:
            if row["bytes"] is None:
                continue
            panels.setdefault((res["scene"], row["term"]), {}).setdefault(row["label"], []).append(row)
    cols = 2
    rows = (len(panels) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(6.4 * cols, 4.8 * rows), squeeze=False)
    for ax in axes.ravel()[len(panels):]:
        ax.set_visible(False)
    for ax, ((scene, term), by_label) in zip(axes.ravel(), panels.items()):
        curves = {}
        for label, rows in by_label.items():
            err = statistics.mean(r["relative_rmse"] for r in rows)
            curves.setdefault(family(label), []).append((rows[0]["bytes"], 100 * err, label))
        colours = plt.cm.tab20.colors
        for i, (fam, pts) in enumerate(sorted(curves.items())):
            pts.sort()
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "os^D"[i // 20 % 4] + "-", label=fam, markersize=4,
                    color=colours[i % 20])
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("bytes (fp16)" + (" per probe" if scene == "metal_box" else ""))
        ax.set_ylabel(f"{term} relative RMSE %, mean over panoramas")
        ax.set_title(f"{scene}: {term}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--panoramas", default="city,courtyard,interior,studio")
    ap.add_argument("--studies", default="quick,metal_box")
    ap.add_argument("--max-side", type=int, default=64)
    ap.add_argument("--max-samples", type=int, default=2048)
    ap.add_argument("--target-noise", type=float, default=0.005)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--device", default=None)
    ap.add_argument("--cache", default=None)
    ap.add_argument("--json", default=None)
    ap.add_argument("--plot", default=None)
    ap.add_argument("--from-json", default=None, help="print (and plot) a --json file's results, rendering nothing")
    args = ap.parse_args()

    if args.from_json:
        doc = json.loads(Path(args.from_json).read_text())
        results, device = doc["results"], doc["device"]
    else:
        from iblbake.device.runtime import Runtime
        from iblbake.render import Bakes

        rt = Runtime(args.device)
        bakes = Bakes(args.cache)
        device = rt.device_label
        results = []
        wanted = args.studies.split(",")
        for name, path, ladder_name in STUDIES:
            if name not in wanted:
                continue
            for pano in args.panoramas.split(","):
                t0 = time.perf_counter()
                results.append(study(name, path, ladder_name, pano, args, rt, bakes))
                print(f"{name} under {pano}: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
                if args.json:             # after every study: a run cut short keeps what it measured
                    Path(args.json).write_text(json.dumps({"device": device, "args": vars(args),
                                                           "results": results}, indent=1) + "\n")
    print(f"device: {device}\n")
    print(table(results))
    if args.plot:
        plot(results, args.plot)


if __name__ == "__main__":
    main()
