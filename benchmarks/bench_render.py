"""Render benchmark: the 1280x720 sphere grid in every specular mode and the 102,400-triangle mesh
scene; per configuration the median of 3 warm runs (caches baked and kernels built by a first run)
of the end-to-end render and of each pass, Mpixel-samples/s of the lighting pass, primary rays/s,
and BVH build time. Targets (2-core CPU): prefiltered < 1 s end to end, importance N=40 < 3 s.

    python benchmarks/bench_render.py [--runs 3] [--device SPEC] [--only NAME]
"""

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from iblbake import render
from iblbake.scene import load as scene  # noqa: E402

CONFIGS = [
    ("prefiltered", "sphere_grid.yaml", ["effects.specular=prefiltered"]),
    ("importance N=1", "sphere_grid.yaml", ["effects.specular=importance", "effects.samples=1"]),
    ("importance N=8", "sphere_grid.yaml", ["effects.specular=importance", "effects.samples=8"]),
    ("importance N=40", "sphere_grid.yaml", ["effects.specular=importance", "effects.samples=40"]),
    ("importance N=128", "sphere_grid.yaml", ["effects.specular=importance", "effects.samples=128"]),
    ("reference 64 spp", "sphere_grid.yaml", ["effects.specular=reference", "effects.diffuse=reference",
                                               "effects.reference.max_samples=64", "effects.reference.target_noise=0",
                                               "effects.reference.batch=32"]),
    ("mesh 102k tris", "mesh.yaml", []),
]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--device", default=None)
    ap.add_argument("--only", default=None)
    ap.add_argument("--cache", default=None)
    args = ap.parse_args()
    cache = Path(args.cache or tempfile.mkdtemp(prefix="iblbake-bench-"))
    print("| configuration | end to end s | gbuffer s | lighting s | Mpixel-samples/s | primary Mrays/s | BVH build s |")
    print("|---|---|---|---|---|---|---|")
    device = None
    for name, file, sets in CONFIGS:
        if args.only and args.only not in name:
            continue
        sc = scene.load(ROOT / "examples" / "scenes" / file, sets)
        render.render(sc, device=args.device, cache_root=cache)           # bake + build
        ends, passes = [], {}
        for _ in range(args.runs):
            t0 = time.perf_counter()
            f = render.render(sc, device=args.device, cache_root=cache)
            ends.append(time.perf_counter() - t0)
            for p in f.report["passes"]:
                passes.setdefault(p["name"], []).append(p)
            geo = next(b for b in f.report["bakes"] if b["name"] == "geometry")
            device = f.report["device"]
        med = lambda k: statistics.median(p["seconds"] for p in passes.get(k, [])) if k in passes else 0.0
        light = "reference" if "reference" in passes else "shade"
        n = sc["camera"]["resolution"][0] * sc["camera"]["resolution"][1] * sc["camera"]["spp"]
        samples = {"shade": sc["effects"]["samples"] if sc["effects"]["specular"] == "importance" else 1,
                   "reference": passes.get("reference", [{}])[0].get("samples_per_pixel", 1)}[light]
        mps = n * samples / max(med(light), 1e-9) / 1e6
        print(f"| {name} | {statistics.median(ends):.3f} | {med('gbuffer'):.3f} | {med(light):.3f} | {mps:.1f} | "
              f"{n / max(med('gbuffer'), 1e-9) / 1e6:.2f} | {geo.get('bvh_build_s', 0):.3f} |", flush=True)
    print(f"\ndevice: {device}; median of {args.runs} warm runs; end to end = render() incl. reading the "
          f"panorama, loading cached bakes and the mesh, all passes and read-back")


if __name__ == "__main__":
    main()
