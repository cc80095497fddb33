"""Irradiance probe benchmark: the bake of a 16 x 8 x 16 grid at 256 rays per probe (relocation,
classification and the projection into the atlases included) in the open box of
examples/sheets/bounces.yaml and in the knot scene (examples/scenes/mesh.yaml, 102k triangles),
and the frame with `diffuse: probes` against SH with GTAO, side by side in one run, at the
study's 320-pixel side. Medians of --runs after a warm-up (PoCL specialises a program at its
first launch); every bake into a fresh cache folder.

    python benchmarks/bench_probes.py [--runs 3] [--device SPEC] [--json]

The accuracy of each (its relative RMSE against the converged reference) is the study's:
`iblbake accuracy SCENE --set effects.specular=off` (docs/benchmarks.md "Irradiance probes").
"""

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from iblbake.render import render  # noqa: E402
from iblbake.device.runtime import Runtime  # noqa: E402
from iblbake.render.bakes import Bakes  # noqa: E402
from iblbake.render.units import Job  # noqa: E402
from iblbake.scene import load as scene  # noqa: E402

SCENES = {"open box": ROOT / "examples" / "sheets" / "bounces.yaml", "knot": ROOT / "examples" / "scenes" / "mesh.yaml",
          "two spheres (sun extracted)": ROOT / "examples" / "scenes" / "quick.yaml"}
GRID = ["probes.counts=[16, 8, 16]", "probes.rays=256"]
FRAME = ["camera.resolution=[320, 200]", "effects.specular=off", "environment.background=hide"]


def bake_once(rt, path, extra, root):
    sc = scene.load(path, [*GRID, *extra], [])         # the probes unit, whatever the effects say
    bakes = Bakes(root)
    bakes.runtime = rt
    job = Job(sc, rt, bakes)
    job.panorama()                      # read, and the scene put on the device, before the timing
    assert job.device_scene is not None
    t0 = time.perf_counter()
    vol, _cached, _extra = bakes.load("probes", job)
    return time.perf_counter() - t0, vol


def frame_time(rt, bakes, path, values, runs):
    sc = scene.load(path, [*FRAME, *values], [])
    render(sc, runtime=rt, cache=bakes)                 # bakes, builds, the first launch
    return statistics.median(render(sc, runtime=rt, cache=bakes).report["elapsed_s"] for _ in range(runs))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--device", default=None)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rt = Runtime(args.device)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in SCENES.items():
            extra = ["environment.sun=extract"] if "sun" in name else []
            bake_once(rt, path, extra, Path(tmp) / "warm")             # builds and the first launch
            times = []
            for k in range(args.runs):
                s, vol = bake_once(rt, path, extra, Path(tmp) / f"{name}-{k}")
                times.append(s)
            rep = vol["report"]
            shared = Bakes(Path(tmp) / "frames")
            sh_gtao = frame_time(rt, shared, path, [*extra, "effects.diffuse=sh", "effects.ao=gtao"], args.runs)
            probe = frame_time(rt, shared, path, [*extra, "effects.diffuse=probes"], args.runs)
            rows.append({"scene": name, "probes": rep["probes"], "rays_traced": rep["rays_traced"],
                         "bake_s": round(statistics.median(times), 3),
                         "mrays_per_s": round(rep["rays_traced"] / statistics.median(times) / 1e6, 3),
                         "inactive": rep["inactive"], "relocated": rep["relocated"],
                         "frame_sh_gtao_ms": round(sh_gtao * 1000, 2), "frame_probes_ms": round(probe * 1000, 2),
                         "frame_ratio": round(probe / sh_gtao, 2)})
    if args.json:
        print(json.dumps({"device": rt.device_label, "rows": rows}, indent=2))
        return
    print(f"device: {rt.device_label}; bake: 16 x 8 x 16 probes, 256 rays; frames at 320 px, diffuse only")
    print(f"{'scene':<30} {'bake s':>8} {'Mrays/s':>8} {'inactive':>8} {'SH+GTAO ms':>11} {'probes ms':>10} {'ratio':>6}")
    for r in rows:
        print(f"{r['scene']:<30} {r['bake_s']:>8.3f} {r['mrays_per_s']:>8.3f} {r['inactive']:>8} "
              f"{r['frame_sh_gtao_ms']:>11.2f} {r['frame_probes_ms']:>10.2f} {r['frame_ratio']:>6.2f}")


if __name__ == "__main__":
    main()
