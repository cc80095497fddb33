"""Start-up budget of one call (Makefiles call iblbake once per file): whole processes, median
of --runs, beside a bare `python -c pass` and one that only imports what the command imports.

    python benchmarks/bench_startup.py [--runs 5]

Targets (2-core CPU, city.exr): `python -c "import iblbake"` <= 0.10 s (the whole process; the
import itself is under 2 ms), `sh --bands 5` <= 0.14 s, `mips` cube face 256 (9 levels, a
fresh cache) <= 0.35 s, `render examples/scenes/quick.yaml` warm <= 0.25 s.
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
PY = sys.executable
_EXE = Path(PY).with_name("iblbake")          # the console script, else the module
EXE = [str(_EXE)] if _EXE.exists() else [PY, "-m", "iblbake.cli"]
CITY = str(ROOT / "examples" / "panoramas" / "city.exr")
# as a user's shell runs them: with bytecode caches (a session may set PYTHONDONTWRITEBYTECODE,
# which makes every run compile every module again)
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def timed(cmd, runs, before=None):
    out = []
    for _ in range(runs):
        if before:
            before()
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, env=ENV)
        out.append(time.perf_counter() - t0)
    return statistics.median(out)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="iblbake-startup-"))
    fresh = {"n": 0}

    def new_cache():
        fresh["n"] += 1

    rows = [
        ("python -c pass", [PY, "-c", "pass"], None, None),
        ("import iblbake (the API, loaded lazily)", [PY, "-c", "import iblbake"], None, 0.10),
        ("imports of sh (numpy, click, OpenImageIO)", [PY, "-c", "import numpy, click, OpenImageIO"], None, None),
        ("imports of render (+ pyopencl)", [PY, "-c", "import numpy, click, OpenImageIO, pyopencl"], None, None),
        ("iblbake --help", [*EXE, "--help"], None, None),
        ("iblbake sh city.exr --bands 5", [*EXE, "sh", CITY, "--bands", "5", "-q"], None, 0.14),
        ("iblbake mips city.exr cube face 256, 9 levels, fresh cache",
         lambda: [*EXE, "mips", CITY, "--layout", "cubemap", "--size", "256", "--levels", "9", "--min-size", "1",
                  "--cache", str(tmp / f"c{fresh['n']}"), "--dfg-size", "64", "-q"], new_cache, 0.35),
        ("iblbake render quick.yaml, warm", [*EXE, "render", str(ROOT / "examples/scenes/quick.yaml"), "-o",
                                             str(tmp / "q.png"), "--cache", str(tmp / "warm"), "-q"], None, 0.25),
    ]
    # the DFG table is shared by every panorama and baked once per size: warm it for the mips row
    subprocess.run([*EXE, "mips", CITY, "--only", "dfg", "--dfg-size", "64", "--cache", str(tmp / "dfg"), "-q"],
                   check=True)
    subprocess.run(rows[-1][1], check=True, capture_output=True)          # warm the render's cache
    print("| process | median s | target s | met |")
    print("|---|---|---|---|")
    for name, cmd, before, target in rows:
        if callable(cmd):
            def run_fresh(cmd=cmd):
                c = cmd()
                Path(c[c.index("--cache") + 1]).mkdir(parents=True, exist_ok=True)
                for f in (tmp / "dfg").iterdir():           # the shared DFG entry, as a user has it
                    if f.is_dir():
                        subprocess.run(["cp", "-r", str(f), c[c.index("--cache") + 1]], check=True)
                t0 = time.perf_counter()
                subprocess.run(c, check=True, capture_output=True, env=ENV)
                return time.perf_counter() - t0
            s = []
            for _ in range(args.runs):
                new_cache()
                s.append(run_fresh())
            med = statistics.median(s)
        else:
            med = timed(cmd, args.runs, before)
        met = "" if target is None else ("yes" if med <= target else "no")
        print(f"| {name} | {med:.3f} | {'' if target is None else f'{target:.2f}'} | {met} |", flush=True)
    print(f"\nmedian of {args.runs} whole processes each")


if __name__ == "__main__":
    main()
