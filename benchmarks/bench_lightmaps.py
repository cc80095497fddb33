"""Lightmaps on the corpus' interiors against the converged reference (issue 62): each scene's
lightmap (iblbake/render/lightmaps) baked at a texel density, read at the camera's primary hits
(render/lightmaps/read.py, the numpy reading; lightmapped objects only) into the diffuse term
(Lambert: base colour x (1 - metallic) x E / pi), and judged as corpus_absolute.py judges the probes:
per object region the ratio of its mean luminance to the reference's diffuse term and the worst
channel's |mean difference| (study/accuracy.py Study.region_metrics), for the non-directional
(irradiance) and the L1 SH atlases; with the bake's time and the atlases' bytes (fp16 as an engine
holds them), and the scene's default irradiance probes beside them (the study's `probes` rung: its
bake's time, bytes and worst region). Prints a Markdown table; --json writes every figure.

    .venv/bin/python benchmarks/bench_lightmaps.py [--scenes corridor,two_storey,...]
        [--panorama studio,city] [--density 8] [--samples 1024] [--max-side 64] [--max-samples 4096]
        [--target-noise 0.01] [--cache DIR] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BOUND = 0.10           # issue 62: within 10% of the reference on every region of static geometry
INTERIORS = ("corridor", "two_storey", "quad_room", "l_room", "probe_box_walls", "window_room")   # the corpus'



def measure(name, panorama, args, rt, bakes) -> dict:
    from iblbake.render import lightmaps
    from iblbake.render.lightmaps import read
    from iblbake.render.units import Job
    from iblbake.study import accuracy as acc

    settings = acc.Settings(max_side=args.max_side, repeats=1, target_noise=args.target_noise,
                            max_samples=args.max_samples, flip=False)
    sets = [f"environment.path={ROOT / 'examples' / 'panoramas' / (panorama + '.exr')}",
            f"lightmap.texels_per_unit={args.density}", f"lightmap.samples={args.samples}",
            "environment.sun=none"]      # the atlas holds the panorama whole: what its reading alone is judged by
    study = acc.Study(ROOT / "examples" / "corpus" / f"{name}.yaml", sets, settings, runtime=rt, bakes=bakes,
                      warn=lambda m: print(f"  warning: {m}", file=sys.stderr))
    t0 = time.perf_counter()
    ref = study.render_reference("diffuse")
    ref_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    said = [-1]

    def progress(f):                     # the bake's fraction traced, on the terminal every 10%
        if int(10 * f) > said[0]:
            said[0] = int(10 * f)
            print(f"  {name}: lightmap {100 * f:.0f}%", file=sys.stderr, flush=True)
    lm = lightmaps.bake(Job(study.scene, rt, bakes), study.scene.data["lightmap"], progress)
    bake_s = time.perf_counter() - t0
    rows = {}
    for basis in lightmaps.BASES:
        hdr = read.diffuse_frame(study.scene, study.bakes.geometry(study.scene), lm, ref["hdr"].shape[:2], basis)
        mask = study.metric_mask("diffuse", hdr)
        m = study.region_metrics(hdr, ref["hdr"], mask)
        rows[basis] = {"region_absolute": m["region_absolute"], "worst_region_absolute": m["worst_region_absolute"],
                       "bytes": lm["report"]["bytes"][basis]}
    return {"scene": name, "panorama": panorama, "density": args.density, "samples": lm["report"]["samples"],
            "atlas": [lm["report"]["width"], lm["report"]["height"]], "texels": lm["report"]["texels"],
            "bake_s": round(bake_s, 2), "reference_s": round(ref_s, 1), "reference_noise": ref["noise"],
            "bases": rows, "probes": probes(study)}


def probes(study) -> dict | None:
    """The scene's default irradiance probes (the study's `probes` rung) beside the lightmap: their
    bake's seconds, bytes and worst region against the same reference."""
    from iblbake.study import ladder
    rung = next((r for r in ladder.realtime_ladder(study.scene, study.fx) if r.label == "probes"), None)
    if rung is None:
        return None
    row = study.run_rung(rung)
    return {"bake_s": round(sum(b["seconds"] for b in row["bakes"]), 2), "bytes": row["bytes"],   # cached: as baked
            "worst_region_absolute": max(e["absolute"] for e in row["region_absolute"].values())}


def table(results) -> str:
    lines = ["| scene | panorama | basis | texels/unit | atlas | bytes | bake s | worst region | regions (ratio to the "
             "reference) | probes: bytes, bake s, worst region |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        p = r.get("probes")
        probe = f"{p['bytes']}, {p['bake_s']:.2f}, {100 * p['worst_region_absolute']:.1f}%" if p else ""
        for basis, b in r["bases"].items():
            regions = ", ".join(f"{n.split(' (objects.')[0].strip(chr(39))} x{e['ratio']:.3f}"
                                for n, e in b["region_absolute"].items())
            lines.append(f"| {r['scene']} | {r['panorama']} | {basis} | {r['density']:g} | {r['atlas'][0]}x{r['atlas'][1]} | "
                         f"{b['bytes']} | {r['bake_s']} | {100 * b['worst_region_absolute']:.1f}% | {regions} | {probe} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default=",".join(INTERIORS))
    ap.add_argument("--panorama", default="studio,city", help="panoramas of examples/panoramas, comma-separated")
    ap.add_argument("--density", type=float, default=8.0)
    ap.add_argument("--samples", type=int, default=1024)
    ap.add_argument("--max-side", type=int, default=64)
    ap.add_argument("--max-samples", type=int, default=4096)
    ap.add_argument("--target-noise", type=float, default=0.01)
    ap.add_argument("--device", default=None)
    ap.add_argument("--cache", default=None)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    from iblbake.device.runtime import Runtime
    from iblbake.render.bakes import Bakes

    rt = Runtime(args.device) if args.device else Runtime()
    bakes = Bakes(Path(args.cache)) if args.cache else Bakes()
    results = []
    for name in args.scenes.split(","):
        for panorama in args.panorama.split(","):
            results.append(measure(name, panorama, args, rt, bakes))
        print(json.dumps({k: v for k, v in results[-1].items() if k != "bases"}), file=sys.stderr)
    print(table(results))
    if args.json:
        from iblbake.io.atomic import write_text
        write_text(Path(args.json), json.dumps(results, indent=1))
    worst = max(b["worst_region_absolute"] for r in results for b in r["bases"].values())
    return 0 if worst <= BOUND else 1


if __name__ == "__main__":
    sys.exit(main())
