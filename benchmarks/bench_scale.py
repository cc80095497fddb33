"""Sheets beyond one process: a 64-cell sheet (8 x 8, 256x256 cells, importance N = 64, city)
rendered serially and with `--jobs 2`, whole `iblbake sheet` processes with warm bake caches (the
cell cache is not read: no --resume), median of --runs, side by side in one run; cells per second
and the ratio to serial. With --pthreads, each worker's PoCL runs that many threads
(POCL_MAX_PTHREAD_COUNT), so two workers do not fight over the same cores.

    python benchmarks/bench_scale.py [--runs 3] [--device SPEC] [--jobs 2] [--pthreads N]
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "examples" / "sheets" / "spheres.yaml"
AXES = ["--rows", "materials.ball.metallic=0:1:8", "--columns", "materials.ball.roughness=0:1:8",
        "--cell-size", "256x256", "--set", "effects.specular=importance", "--set", "effects.samples=64"]


def run(cache, out, jobs, device, env):
    cmd = [sys.executable, "-m", "iblbake.cli", "sheet", str(SCENE), "-o", str(out), "--cache", str(cache),
           "-q", "--jobs", str(jobs), *AXES] + (["--device", device] if device else [])
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        sys.exit(p.stderr.strip())
    return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--device", default=None)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--pthreads", type=int, default=None)
    args = ap.parse_args()
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        run(tmp / "c", tmp / "warm.png", 1, args.device, env)          # bakes and kernel builds
        rows = []
        for jobs in (1, args.jobs):
            e = dict(env)
            if jobs > 1 and args.pthreads:
                e["POCL_MAX_PTHREAD_COUNT"] = str(args.pthreads)
            times = [run(tmp / "c", tmp / f"j{jobs}.png", jobs, args.device, e) for _ in range(args.runs)]
            rows.append((jobs, statistics.median(times)))
        same = (tmp / "j1.png").read_bytes() == (tmp / f"j{args.jobs}.png").read_bytes()
    serial = rows[0][1]
    print("| sheet of 64 cells | wall s | cells/s | throughput / serial |")
    print("|---|---|---|---|")
    for jobs, t in rows:
        print(f"| --jobs {jobs} | {t:.2f} | {64 / t:.1f} | {serial / t:.2f} |")
    print(f"\nmedian of {args.runs} whole processes; the sheets {'are identical' if same else 'DIFFER'}; "
          f"{os.cpu_count()} cores")


if __name__ == "__main__":
    main()
