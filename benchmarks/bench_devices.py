"""The path-traced reference on each OpenCL CPU runtime, side by side in one run: PoCL against
Intel's CPU runtime (`pip install 'iblbake[intel-cpu]'`), or any devices named.

Per scene, the reference pass (bounces unbounded unless --bounces) at --spp samples per pixel and
--resolution, warm: one round to build and load the programs, then --repeats rounds, the devices
alternating within each round (so a busy spell of a shared machine falls on both); the pass's own
seconds (the frame report's) and the whole render call's, median and range. The frames of the
devices are compared (mean luminance, relative). With --build-log, the vectorisation remarks of
Intel's build log per kernel (a fresh kernel cache, so the programs are built from source). With
--subnormals, each device twice: as iblbake builds (subnormal floats flushed, programs.DENORMS) and
with subnormals kept, alternating, and whether the two frames are equal bit for bit.

    .venv/bin/python benchmarks/bench_devices.py [--devices pocl,intel-cpu] [--repeats 5] [--subnormals]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
KEPT = " (subnormals kept)"           # --subnormals: a device's second entry, built without the flush
SCENES = {"open box (examples/sheets/bounces.yaml)": ROOT / "examples" / "sheets" / "bounces.yaml",
          "knot, 102k triangles (examples/scenes/mesh.yaml)": ROOT / "examples" / "scenes" / "mesh.yaml"}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", default="pocl,intel-cpu", help="comma-separated device specs (--device's)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--spp", type=int, default=128)
    ap.add_argument("--resolution", default="128x96")
    ap.add_argument("--bounces", default="unbounded")
    ap.add_argument("--only", default=None, help="scenes whose name contains this")
    ap.add_argument("--build-log", action="store_true", help="print Intel's vectorisation remarks per kernel")
    ap.add_argument("--subnormals", action="store_true",
                    help="each device also with subnormal floats kept (built without -cl-denorms-are-zero)")
    args = ap.parse_args()
    w, h = map(int, args.resolution.split("x"))
    tmp = Path(tempfile.mkdtemp(prefix="bench-devices-"))
    os.environ["IBLBAKE_KERNEL_CACHE"] = str(tmp / "kernels")      # cold builds: their logs are there

    import iblbake
    from iblbake.device import programs
    from iblbake.device.runtime import Runtime
    from iblbake.render import Bakes, render
    from iblbake.scene.load import AOVS

    flush = programs.DENORMS
    specs = [s + k for s in args.devices.split(",") for k in (("", KEPT) if args.subnormals else ("",))]
    runtimes = {s: Runtime(s.removesuffix(KEPT)) for s in specs}
    kept = {s for s in specs if s.endswith(KEPT)}

    def build_as(s):            # the option is read when a runtime builds a program (its first render)
        programs.DENORMS = "" if s in kept else flush

    def bits(a, b):
        return "equal bit for bit" if np.array_equal(a.view(np.uint32), b.view(np.uint32)) else \
            f"differs (max {np.abs(a.astype(np.float64) - b).max():.2g})"

    bakes = Bakes(tmp / "cache")
    bounces = args.bounces if args.bounces == "unbounded" else int(args.bounces)
    print(f"{w}x{h}, {args.spp} spp, bounces {bounces}; warm, median (min-max) of {args.repeats} rounds, "
          f"devices alternating")
    for s, rt in runtimes.items():
        print(f"  {s}: {rt.device_label}")
    logs = []
    print("\n| scene | device | reference pass s | render call s | mean luminance vs first device | "
          "frame as flushed |")
    print("|---|---|---|---|---|---|")
    for name, path in SCENES.items():
        if args.only and args.only not in name:
            continue
        sc = iblbake.load_scene(str(path), overrides=[
            "effects.diffuse=reference", "effects.specular=reference", f"effects.reference.bounces={bounces}",
            f"effects.reference.max_samples={args.spp}", "effects.reference.target_noise=0",
            f"camera.resolution=[{w},{h}]", "camera.spp=1", "effects.ao=off"])
        for a in AOVS:                    # the frame only (mesh.yaml asks for AOVs)
            sc.data["output"][a] = None
        times = {s: ([], []) for s in specs}
        frames = {}
        built = {s: set(rt._programs) for s, rt in runtimes.items()}
        for r in range(args.repeats + 1):
            for s, rt in runtimes.items():
                build_as(s)
                t0 = time.perf_counter()
                f = render(sc, runtime=rt, cache=bakes)
                total = time.perf_counter() - t0
                ref = sum(p["seconds"] for p in f.report["passes"] if p["name"] == "reference")
                if r:
                    times[s][0].append(ref)
                    times[s][1].append(total)
                frames[s] = f.hdr[..., :3].copy()
        first = frames[specs[0]].astype(np.float64).mean()
        for s in specs:
            ref, total = times[s]
            print(f"| {name} | {s} | {statistics.median(ref):.2f} ({min(ref):.2f}-{max(ref):.2f}) | "
                  f"{statistics.median(total):.2f} ({min(total):.2f}-{max(total):.2f}) | "
                  f"{frames[s].astype(np.float64).mean() / first - 1:+.2%} | "
                  f"{bits(frames[s], frames[s.removesuffix(KEPT)]) if s in kept else '-'} |", flush=True)
        if args.build_log:
            logs.append((name, build_log(runtimes, built)))
    for name, lines in logs:
        print(f"\n{name}, Intel's build log:" + "".join(f"\n  {ln}" for ln in lines))


def build_log(runtimes, before) -> list:
    """Which kernels Intel's CPU runtime vectorised, from the build logs of the programs built
    since `before` ({spec: program keys})."""
    import re
    out = []
    for s, rt in runtimes.items():
        if "Intel" not in rt.info.platform:
            continue
        for key, prg in rt._programs.items():
            if key in before[s]:
                continue
            log = prg.get_build_info(rt.info.device, rt.cl.program_build_info.LOG)
            out += [f"{m.group(1)}: {m.group(2)}" for m in
                    re.finditer(r'Kernel "(\w+)" was (successfully vectorized \(\d+\)|not vectorized)', log)]
    return out


if __name__ == "__main__":
    main()
