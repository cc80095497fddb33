"""The path-traced reference's render time on several source trees side by side: an A/B of kernel
changes on one device, in one run.

Each TREE is a folder holding an iblbake package and its kernels (this checkout, `.`, or another
commit's: `git archive <commit> iblbake kernels benchmarks | tar -x -C TREE`). Each is timed in a
process of its own (its own imports and kernel build), round robin, on one scene of
benchmarks/mitsuba_paths.py (the tree's own copy where it has one) at a fixed sample count, such as
that scene's time to 1% there: warm, the render call only, the median of --reps renders a process,
then each tree's median over --rounds and its time over the first tree's. A hash of each tree's
frame says whether the trees render the same bits (the same seed: they should, unless a change
means to alter the numbers). mitsuba_paths.py's timings interpolate between sample counts and vary
4-8% from one run to the next on a GPU; a change of a few per cent needs this.

    .venv/bin/python benchmarks/paths_ab.py . /tmp/old --scene knot --spp 812 [--scale 4] [--reps 7] [--rounds 3]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def child(tree: Path, scene: str, spp: int, scale: int, reps: int) -> dict:
    """In a process of its own: the tree's iblbake renders the scene reps + 1 times (the first warms
    the kernel build and the bakes)."""
    sys.path[:0] = [str(tree), str(tree / "benchmarks" if (tree / "benchmarks" / "mitsuba_paths.py").exists()
                                   else ROOT / "benchmarks")]
    import yaml
    import mitsuba_paths as mp
    from iblbake.render import Bakes, render
    from iblbake.scene import load
    from iblbake.device.runtime import Runtime
    mp.ROOT, mp.RES = ROOT, (64 * scale, 48 * scale)          # the meshes of this checkout
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        pano, _ = mp.panorama_pair(tmp)
        rt, bakes = Runtime(), Bakes(tmp / "cache")
        matches = [(name, s) for name, s in mp.scenes(tmp).items() if scene in name]
        if len(matches) != 1:
            raise SystemExit(f"--scene {scene!r} names {len(matches)} of mitsuba_paths.py's scenes, not one")
        name, (objects, mats) = matches[0]
        p = tmp / "scene.yaml"
        p.write_text(yaml.safe_dump(mp.iblbake_doc(pano, objects, mats, spp, 1, "unbounded", tmp / "depth.exr")))
        sc = load.load(p)
        f = render(sc, runtime=rt, cache=bakes)
        times = []
        for _ in range(reps):
            t0 = time.perf_counter()
            render(sc, runtime=rt, cache=bakes)
            times.append(time.perf_counter() - t0)
        return {"scene": name, "device": rt.device_label, "median_s": statistics.median(times),
                "hash": hashlib.sha256(f.hdr.tobytes()).hexdigest()[:16]}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trees", nargs="+", type=Path, help="folders holding iblbake/ and kernels/; the first is the base")
    ap.add_argument("--scene", default="knot", help="a part of one mitsuba_paths.py scene's name")
    ap.add_argument("--spp", type=int, default=812, help="samples per pixel of each render")
    ap.add_argument("--scale", type=int, default=4, help="the frame, times 64x48 (mitsuba_paths.py --speed-scale)")
    ap.add_argument("--reps", type=int, default=7, help="timed renders a process")
    ap.add_argument("--rounds", type=int, default=3, help="processes a tree, round robin")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(args.trees[0].resolve(), args.scene, args.spp, args.scale, args.reps)))
        return
    for t in args.trees:
        if not (t / "iblbake").is_dir() or not (t / "kernels").is_dir():
            raise SystemExit(f"{t}: holds no iblbake/ and kernels/ (git archive <commit> iblbake kernels benchmarks)")
    runs = {t: [] for t in args.trees}
    for r in range(args.rounds):
        for t in args.trees:
            out = subprocess.run([sys.executable, __file__, str(t), "--child", "--scene", args.scene,
                                  "--spp", str(args.spp), "--scale", str(args.scale), "--reps", str(args.reps)],
                                 capture_output=True, text=True)
            if out.returncode:
                raise SystemExit(f"{t}: {out.stderr.strip().splitlines()[-1] if out.stderr.strip() else out.returncode}")
            runs[t].append(json.loads(out.stdout.strip().splitlines()[-1]))
            print(f"round {r + 1}, {t}: {runs[t][-1]['median_s']:.4f} s", file=sys.stderr, flush=True)
    first = runs[args.trees[0]]
    base = statistics.median(x["median_s"] for x in first)
    print(f"\n{first[0]['scene']}, {64 * args.scale}x{48 * args.scale}, {args.spp} spp, {first[0]['device']}; "
          f"medians of {args.reps} warm renders a process, {args.rounds} processes a tree\n")
    print("| tree | seconds (each round) | median s | time / first's | frame |")
    print("|---|---|---|---|---|")
    for t, rs in runs.items():
        m = statistics.median(x["median_s"] for x in rs)
        same = "same bits" if rs[0]["hash"] == first[0]["hash"] else f"differs ({rs[0]['hash']})"
        each = ", ".join(f"{x['median_s']:.4f}" for x in rs)
        print(f"| {t} | {each} | {m:.4f} | {m / base:.3f} | {same} |")


if __name__ == "__main__":
    main()
