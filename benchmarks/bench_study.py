"""The default accuracy study of the sphere-grid example, end to end, as a user runs it: a fresh
process on a fresh bake cache (and again with the reference cached), the split of its time
between reference, rungs and bakes (kernel builds included), against the targets: 5 minutes on
a 2-core CPU, 1 minute on a GPU.

    python benchmarks/bench_study.py [--device SPEC] [--scene PATH]
"""

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def study(scene, cache, device, out):
    cmd = [sys.executable, "-m", "iblbake.cli", "accuracy", str(scene), "--cache", str(cache), "-o", str(out),
           "--json", "-q"] + (["--device", device] if device else [])
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        sys.exit(f"accuracy failed: {p.stderr.strip()}")
    return wall, json.loads(p.stdout)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default=None)
    ap.add_argument("--scene", default=str(ROOT / "examples" / "scenes" / "sphere_grid.yaml"))
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        print("| run | wall s | reference s | rungs s | bakes and builds s | rungs |")
        print("|---|---|---|---|---|---|")
        for run in ("fresh cache", "reference cached"):
            wall, s = study(args.scene, tmp / "cache", args.device, tmp / "out")
            t = s["time_split_s"]
            print(f"| {run} | {wall:.1f} | {t['reference_s']:.1f} | {t['rungs_s']:.1f} | {t['bakes_s']:.1f} | "
                  f"{len(s['rungs'])} |", flush=True)
            if run == "fresh cache":
                first = wall
        target = 60.0 if "GPU" in s["device"] else 300.0
        print(f"\ndevice: {s['device']}; fresh study {first:.0f} s against a target of {target:.0f} s: "
              f"{'met' if first <= target else 'NOT met'}")


if __name__ == "__main__":
    main()
