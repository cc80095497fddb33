"""Frame time of the reflection probes' taps (reflection_probes.N.taps) against one read a lobe:
the corpus' window_room (a chrome sphere, a clay sphere and the room's plaster under one
parallax probe) at each resolution, the probe read in 0 (one read), 16, 32 and 64 taps. One
runtime and bake store (the capture baked once, the kernels built by a warm-up frame); the
configurations alternate round after round so that a busy spell of a shared machine falls on
all of them; per configuration the median of its rounds' end-to-end frame time and shade pass.

    python benchmarks/bench_reflection_taps.py [--rounds 5] [--sizes 128x96,256x192] [--taps 0,16,32,64]
"""

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from iblbake.device.runtime import Runtime  # noqa: E402
from iblbake.render import Bakes, render  # noqa: E402
import iblbake.scene.load as scene  # noqa: E402

SCENE = ROOT / "examples" / "corpus" / "window_room.yaml"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--sizes", default="128x96,256x192")
    ap.add_argument("--taps", default="0,16,32,64")
    ap.add_argument("--device", default=None)
    ap.add_argument("--cache", default=None)
    args = ap.parse_args()
    rt, bakes = Runtime(args.device), Bakes(Path(args.cache or tempfile.mkdtemp(prefix="iblbake-taps-")))
    configs = [(s, int(n)) for s in args.sizes.split(",") for n in args.taps.split(",")]
    scenes = {c: scene.load(SCENE, [f"camera.resolution=[{c[0].replace('x', ',')}]",
                                    f"reflection_probes.0.taps={c[1]}"]) for c in configs}
    for c in configs:                          # warm-up: the capture, the kernels
        render(scenes[c], runtime=rt, cache=bakes)
    ends, shades = {c: [] for c in configs}, {c: [] for c in configs}
    for _ in range(args.rounds):
        for c in configs:
            t0 = time.perf_counter()
            f = render(scenes[c], runtime=rt, cache=bakes)
            ends[c].append(time.perf_counter() - t0)
            shades[c].append(sum(p["seconds"] for p in f.report["passes"] if p["name"] == "shade"))
    print("| resolution | taps | frame s | shade pass s | shade / one read |")
    print("|---|---|---|---|---|")
    for c in configs:
        base = statistics.median(shades[(c[0], 0)]) if (c[0], 0) in shades else None
        sh = statistics.median(shades[c])
        ratio = f"{sh / base:.2f}" if base else "-"
        print(f"| {c[0]} | {c[1] or 'one read'} | {statistics.median(ends[c]):.3f} | {sh:.3f} | {ratio} |")
    print(f"\ndevice: {f.report['device']}; medians of {args.rounds} alternating rounds after a warm-up frame")


if __name__ == "__main__":
    main()
