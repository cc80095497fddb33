"""Megakernel or wavefront: the reference pass's samples per second with its paths run either way
(effects.reference.paths; Laine, Karras and Aila 2013), on the scenes of benchmarks/mitsuba_paths.py
(unbounded paths, courtyard), per device. Each (scene, device): a warm-up render of each way (builds
the programs, loads the bakes), then `--repeats` rounds alternating megakernel and wavefront; a
way's figure is the median over the rounds of G-buffer samples x spp / the reference pass's seconds
(its own timing in the frame's report, not the frame's other passes). The ratio is the wavefront's
rate over the megakernel's (> 1: the wavefront is faster). docs/benchmarks.md "Megakernel or
wavefront" holds the table; AUTO_PATHS in iblbake/render/passes/reference.py follows it.

    .venv/bin/python benchmarks/bench_wavefront.py --devices pocl,intel-cpu --spp 128
    .venv/bin/python benchmarks/bench_wavefront.py --devices gpu --spp 1024 --scale 4        # a GPU (the H200)
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
import mitsuba_paths as mp  # noqa: E402  (its scenes, panorama and iblbake documents)

WAYS = ("megakernel", "wavefront")


def rate(f) -> float:
    """The reference pass's G-buffer samples x spp per second in frame f."""
    ref = next(p for p in f.report["passes"] if p["name"] == "reference")
    n = f.hdr.shape[0] * f.hdr.shape[1]
    return n * ref["samples_per_pixel"] / ref["seconds"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", default=None,
                    help="comma-separated --device specs (pocl,intel-cpu,nvidia); default the device iblbake picks")
    ap.add_argument("--spp", type=int, default=128, help="samples per pixel of each render")
    ap.add_argument("--only", default=None, help="scenes whose name contains this")
    ap.add_argument("--repeats", type=int, default=3, help="rounds (the median is reported)")
    ap.add_argument("--scale", type=int, default=1, help="the frame, times 64x48")
    ap.add_argument("--batch", type=int, default=None, help="effects.reference.batch (default: the device's)")
    args = ap.parse_args()
    from iblbake.device.runtime import Runtime
    from iblbake.render import Bakes, render
    from iblbake.scene import load

    mp.RES = (mp.RES[0] * args.scale, mp.RES[1] * args.scale)
    print("| scene | device | megakernel Msamples/s | wavefront Msamples/s | wavefront / megakernel |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        pano, _spread = mp.panorama_pair(tmp)
        runtimes = [Runtime(d) for d in args.devices.split(",")] if args.devices else [Runtime()]
        bakes = Bakes(tmp / "cache")
        for name, (objects, mats) in mp.scenes(tmp).items():
            if args.only and args.only not in name:
                continue
            scenes = {}
            for way in WAYS:
                doc = mp.iblbake_doc(pano, objects, mats, args.spp, 1, "unbounded", tmp / "depth.exr")
                doc["effects"]["reference"]["paths"] = way
                if args.batch:
                    doc["effects"]["reference"]["batch"] = args.batch
                p = tmp / f"{way}.yaml"
                p.write_text(yaml.safe_dump(doc))
                scenes[way] = load.load(p)
            for rt in runtimes:
                for way in WAYS:                                  # warm: programs, bakes, scene
                    render(scenes[way], runtime=rt, cache=bakes)
                got = {way: [] for way in WAYS}
                for _ in range(args.repeats):
                    for way in WAYS:                              # alternating
                        f = render(scenes[way], runtime=rt, cache=bakes)
                        ref = next(q for q in f.report["passes"] if q["name"] == "reference")
                        assert ref["paths"] == way, ref
                        got[way].append(rate(f))
                mk, wf = (statistics.median(got[w]) for w in WAYS)
                print(f"| {name} | {rt.device_label} | {mk / 1e6:.3f} | {wf / 1e6:.3f} | {wf / mk:.2f} |", flush=True)
    print(f"\n{mp.RES[0]}x{mp.RES[1]}, {args.spp} spp, bounces unbounded; median of {args.repeats} alternating "
          f"rounds after a warm-up")


if __name__ == "__main__":
    main()
