"""Sheets beyond one process: a 64-cell sheet (8 x 8, 256x256 cells, importance N = 64, city)
rendered serially, with `--jobs N` (local worker processes) and with `--scheduler local --jobs N`
(a Dask LocalCluster of N workers, started and stopped inside the process), whole `iblbake
sheet` processes with warm bake caches (the cell cache is not read: no --resume), median of
--runs, interleaved in one run; cells per second, the ratio to serial, and Dask's overhead per
cell over the local pool. With --pthreads, each worker's PoCL runs that many threads
(POCL_MAX_PTHREAD_COUNT), so N workers do not fight over the same cores. With --devices, the
parallel rows give each worker its device (e.g. gpu,cpu,cpu: the GPU worker and CPU workers
together) and the table adds cells per second per worker.

    python benchmarks/bench_scale.py [--runs 3] [--device SPEC] [--jobs 2] [--pthreads N] [--devices LIST]
                                     [--grid 16] [--specular importance|reference] [--samples N] [--resources GPU=1]
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "examples" / "sheets" / "spheres.yaml"


def axes(grid: int, specular: str, samples: int) -> list:
    """A grid x grid sweep of metallic x roughness, 256x256 cells; specular importance at N samples,
    or the reference (diffuse and specular) at that many samples per pixel."""
    out = ["--rows", f"materials.ball.metallic=0:1:{grid}", "--columns", f"materials.ball.roughness=0:1:{grid}",
           "--cell-size", "256x256", "--set", f"effects.specular={specular}"]
    if specular == "reference":
        return out + ["--set", "effects.diffuse=reference", "--set", f"effects.reference.max_samples={samples}",
                      "--set", "effects.reference.target_noise=0"]
    return out + ["--set", f"effects.samples={samples}"]


AXES: list = []


def run(cache, out, extra, device, env):
    cmd = [sys.executable, "-m", "iblbake.cli", "sheet", str(SCENE), "-o", str(out), "--cache", str(cache),
           "--json", *extra, *AXES] + (["--device", device] if device else [])
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        sys.exit(p.stderr.strip())
    return time.perf_counter() - t0, json.loads(p.stdout)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--device", default=None)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--pthreads", type=int, default=None)
    ap.add_argument("--devices", default=None)
    ap.add_argument("--grid", type=int, default=8, help="cells per side (8: 64 cells, 16: 256)")
    ap.add_argument("--specular", choices=["importance", "reference"], default="importance")
    ap.add_argument("--samples", type=int, default=64, help="importance N, or the reference's samples per pixel")
    ap.add_argument("--resources", default=None, help="the Dask row's --resources, e.g. GPU=1")
    args = ap.parse_args()
    AXES[:] = axes(args.grid, args.specular, args.samples)
    cells = args.grid * args.grid
    try:
        import distributed  # noqa: F401
        dask = True
    except ImportError:
        dask = False
    spread = ["--jobs", str(args.jobs)] + (["--devices", args.devices] if args.devices else [])
    modes = {"serial": [], f"--jobs {args.jobs}": spread}
    if dask:
        modes[f"--scheduler local --jobs {args.jobs}"] = ["--scheduler", "local", *spread] + (
            ["--resources", args.resources] if args.resources else [])
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        run(tmp / "c", tmp / "warm.png", [], args.device, dict(os.environ))    # bakes and kernel builds
        times = {m: [] for m in modes}
        docs = {}
        for _ in range(args.runs):                     # interleaved: the host's load hits every mode alike
            for i, (m, extra) in enumerate(modes.items()):
                env = dict(os.environ)
                if extra and args.pthreads:
                    env["POCL_MAX_PTHREAD_COUNT"] = str(args.pthreads)
                t, docs[m] = run(tmp / "c", tmp / f"m{i}.png", extra, args.device, env)
                times[m].append(t)
        sheets = [(tmp / f"m{i}.png").read_bytes() for i in range(len(modes))]
    med = {m: statistics.median(t) for m, t in times.items()}
    serial = med["serial"]
    what = f"importance N = {args.samples}" if args.specular == "importance" else f"reference {args.samples} spp"
    print(f"| sheet of {cells} cells, 256x256, {what} | wall s | cells/s | throughput / serial |")
    print("|---|---|---|---|")
    for m, t in med.items():
        print(f"| {m} | {t:.2f} | {cells / t:.1f} | {serial / t:.2f} |")
    if dask:
        d, j = med[f"--scheduler local --jobs {args.jobs}"], med[f"--jobs {args.jobs}"]
        print(f"\nDask's overhead over the local pool: {1000 * (d - j) / cells:+.1f} ms a cell "
              f"({d - j:+.2f} s a sheet, the LocalCluster's start and stop included)")
    else:
        print("\n(no Dask here: pip install 'iblbake[distributed]' for the --scheduler row)")
    for m, doc in docs.items():
        cell = statistics.median(c["seconds"] for c in doc["cells"])
        passes = statistics.median(c["pass_seconds"] for c in doc["cells"])
        print(f"{m}: a cell {1000 * cell:.1f} ms, of it {1000 * passes:.1f} ms in its passes (device work and "
              f"read-back) and {1000 * (cell - passes):.1f} ms on the host (median)")
    for m, doc in docs.items():
        if "workers" in doc:
            per = ", ".join(f"{w['worker']}: {w['cells']} cells, {w['cells'] / max(w['seconds'], 1e-9):.1f}/s busy"
                            for w in doc["workers"]["workers"])
            print(f"{m}: {per}")
    print(f"\nmedian of {args.runs} whole processes; the sheets "
          f"{'are identical' if all(x == sheets[0] for x in sheets) else 'DIFFER'}; {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
