"""Sheet benchmark: the 5x5 roughness x metallic sheet of 256x256 cells on city, warm caches, in
one `iblbake sheet` process against 25 separate `iblbake render` processes with the same
settings, measured side by side in one run (median of --runs each); prints the ratio and the
per-cell milliseconds by pass. Targets: >= 5x on a 2-core CPU, >= 10x on the H200.

    python benchmarks/bench_sheet.py [--runs 3] [--device SPEC] [--cell 256]
"""

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "examples" / "sheets" / "spheres.yaml"
ROUGH = [0.0, 0.25, 0.5, 0.75, 1.0]
METAL = [0.0, 0.25, 0.5, 0.75, 1.0]
MODES = {"prefiltered": ["effects.specular=prefiltered"],
         "importance N=64": ["effects.specular=importance", "effects.samples=64"]}


# the console script beside this Python, else the module (an install with --target has no script)
_EXE = Path(sys.executable).with_name("iblbake")
IBLBAKE = [str(_EXE)] if _EXE.exists() else [sys.executable, "-m", "iblbake.cli"]


def cli(*args):
    return subprocess.run([*IBLBAKE, *map(str, args)], capture_output=True, text=True, check=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--device", default=None)
    ap.add_argument("--cell", type=int, default=256)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="iblbake-bench-sheet-"))
    dev = ["--device", args.device] if args.device else []
    common = ["--cache", tmp / "cache", "--set", f"camera.resolution=[{args.cell},{args.cell}]", *dev]
    print("| mode | one sheet s | 25 renders s | ratio | per cell ms (sheet) | by pass, per cell ms |")
    print("|---|---|---|---|---|---|")
    for mode, sets in MODES.items():
        s = [a for x in sets for a in ("--set", x)]
        sheet = ["sheet", SCENE, "-o", tmp / "sheet.png", "--json", "-q", "--rows", "materials.ball.metallic=0:1:5",
                 "--columns", "materials.ball.roughness=0:1:5", *common, *s]
        cli(*sheet)                                          # warm: bakes and kernel builds
        t_sheet, t_procs, doc = [], [], None
        for _ in range(args.runs):
            t0 = time.perf_counter()
            doc = json.loads(cli(*sheet).stdout)
            t_sheet.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            for m in METAL:
                for r in ROUGH:
                    cli("render", SCENE, "-o", tmp / "cell.png", "-q", *common, *s,
                        "--set", f"materials.ball.metallic={m}", "--set", f"materials.ball.roughness={r}")
            t_procs.append(time.perf_counter() - t0)
        a, b = statistics.median(t_sheet), statistics.median(t_procs)
        per_pass = {}
        for c in doc["cells"]:
            for name, sec in c["passes"].items():
                per_pass.setdefault(name, []).append(sec)
        passes = ", ".join(f"{k} {1000 * sum(v) / len(v):.1f}" for k, v in per_pass.items())
        print(f"| {mode} | {a:.2f} | {b:.2f} | {b / a:.1f}x | {1000 * a / 25:.0f} | {passes} |", flush=True)
    print(f"\ndevice: {doc['device']}; median of {args.runs}; warm caches; each render a new process")


if __name__ == "__main__":
    main()
