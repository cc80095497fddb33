"""Render benchmark: the 1280x720 sphere grid in every specular mode and the 102,400-triangle mesh
scene, and the corpus' window_room under its reflection probe read once a lobe, at its default (taps at grazing views) or in 16, 32 or 64
taps (128x96 and 256x192); per configuration the median of 3 warm runs (caches baked and kernels built by a first run)
of the end-to-end render and of each pass, Mpixel-samples/s of the lighting pass, primary rays/s,
and BVH build time. Targets (2-core CPU): prefiltered < 1 s end to end, importance N=40 < 3 s.

    python benchmarks/bench_render.py [--runs 3] [--device SPEC] [--only NAME]
    python benchmarks/bench_render.py --baseline DIR    # against another source checkout, side by side

--baseline runs every configuration in this checkout and in DIR (an older iblbake source tree,
e.g. `git worktree add DIR REV`, with DIR/iblbake/kernels linking to DIR/kernels), alternately,
each in its own process, and prints the ratio of the medians (this / baseline).
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

ROOT = Path(os.environ.get("IBLBAKE_BENCH_SOURCE") or Path(__file__).resolve().parents[1])
sys.path.insert(0, str(ROOT))
SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"    # the same scenes for both sides

from iblbake.render import Bakes, render  # noqa: E402
try:
    import iblbake.scene.load as scene  # noqa: E402
except ImportError:                           # a baseline from before the layered package
    from iblbake import scene  # noqa: E402

SUN = "lights=[{directional: {direction: [0.5, -1, -0.4], illuminance: 3, angular_diameter: 2}, "
CONFIGS = [
    ("prefiltered", "sphere_grid.yaml", ["effects.specular=prefiltered"]),
    ("importance N=1", "sphere_grid.yaml", ["effects.specular=importance", "effects.samples=1"]),
    ("importance N=8", "sphere_grid.yaml", ["effects.specular=importance", "effects.samples=8"]),
    ("importance N=40", "sphere_grid.yaml", ["effects.specular=importance", "effects.samples=40"]),
    ("importance N=128", "sphere_grid.yaml", ["effects.specular=importance", "effects.samples=128"]),
    ("lobe K=1", "sphere_grid.yaml", ["effects.specular=lobe", "effects.lobe.samples=1"]),
    ("lobe K=4", "sphere_grid.yaml", ["effects.specular=lobe", "effects.lobe.samples=4"]),
    ("lobe K=16", "sphere_grid.yaml", ["effects.specular=lobe", "effects.lobe.samples=16"]),
    ("reference 64 spp", "sphere_grid.yaml", ["effects.specular=reference", "effects.diffuse=reference",
                                               "effects.reference.max_samples=64", "effects.reference.target_noise=0",
                                               "effects.reference.batch=32"]),
    ("reference 64 spp, unoccluded", "sphere_grid.yaml",
     ["effects.specular=reference", "effects.diffuse=reference", "effects.reference.max_samples=64",
      "effects.reference.target_noise=0", "effects.reference.batch=32", "effects.reference.visibility=false"]),
    ("mesh 102k tris", "mesh.yaml", []),
    ("mesh, sun hard shadows", "mesh.yaml", [SUN + "shadows: hard}]"]),
    ("mesh, sun soft shadows 4", "mesh.yaml", [SUN + "shadows: soft, shadow_samples: 4}]"]),
    ("mesh, sun soft shadows 16", "mesh.yaml", [SUN + "shadows: soft, shadow_samples: 16}]"]),
    ("mesh, gtao", "mesh.yaml", ["effects.ao=gtao", "effects.ao_radius=1"]),
    ("mesh, raytraced AO 16", "mesh.yaml", ["effects.ao=raytraced", "effects.ao_samples=16", "effects.ao_radius=1"]),
    ("mesh, raytraced AO 64", "mesh.yaml", ["effects.ao=raytraced", "effects.ao_samples=64", "effects.ao_radius=1"]),
    # the tiled torus of examples/make_textured.py with its own five maps, and the same mesh untextured
    ("textured mesh, 5 maps", "textured.yaml", []),
    ("textured mesh, untextured", "textured.yaml", ["objects.0.material=plain"]),
    # the corpus' window_room under its parallax reflection probe: one read a lobe everywhere, the
    # default (64 taps at grazing views, reflection_probes.N.grazing_taps), taps everywhere
    # (reflection_probes.N.taps), each pixel that reflects in the probe's box paying them
] + [(f"reflection probe {res}, {label}", "../corpus/window_room.yaml",
      [f"camera.resolution=[{res.replace('x', ',')}]", *sets])
     for res in ("128x96", "256x192")
     for label, sets in [("one read", ["reflection_probes.0.taps=0", "reflection_probes.0.grazing_taps=0"]),
                         ("default", ["reflection_probes.0.taps=0"])]
     + [(f"{n} taps", [f"reflection_probes.0.taps={n}"]) for n in (16, 32, 64)]]
# keys a baseline from before them does not know (its scene loader refuses them); without them it
# renders what they switch off
NEWER_KEYS = ("effects.reference.visibility", "effects.lobe.samples", "lights=", "effects.ao",
              "reflection_probes.0.grazing_taps")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--device", default=None)
    ap.add_argument("--only", default=None)
    ap.add_argument("--cache", default=None)
    ap.add_argument("--json", action="store_true", help="one JSON line per configuration")
    ap.add_argument("--baseline", default=None, metavar="DIR")
    ap.add_argument("--rounds", type=int, default=3, help="with --baseline: alternating rounds per configuration")
    args = ap.parse_args()
    if args.baseline:
        return compare(args)
    cache = Path(args.cache or tempfile.mkdtemp(prefix="iblbake-bench-"))
    if not args.json:
        print("| configuration | end to end s | one runtime s | gbuffer s | lighting s | lights + ao s | Mpixel-samples/s | "
              "primary Mrays/s | BVH build s |")
        print("|---|---|---|---|---|---|---|---|---|")
    device = None
    totals = {}                       # per configuration: median of its passes' sum, one-runtime frame, textures
    for name, file, sets in CONFIGS:
        if args.only and args.only != name and (args.json or args.only not in name):
            continue
        try:
            sc = scene.load(SCENES / file, sets)
        except Exception:             # a baseline from before these keys: without them
            if ROOT == SCENES.parents[1]:
                raise
            sc = scene.load(SCENES / file, [s for s in sets if not s.startswith(NEWER_KEYS)])
        first = render(sc, device=args.device, cache_root=cache)   # bake + build
        ends, passes = [], {}
        for _ in range(args.runs):
            t0 = time.perf_counter()
            f = render(sc, device=args.device, cache_root=cache)
            ends.append(time.perf_counter() - t0)
            for p in f.report["passes"]:
                passes.setdefault(p["name"], []).append(p)
            geo = next(b for b in f.report["bakes"] if b["name"] == "geometry")
            device = f.report["device"]
        reused = []                   # the same frame with one runtime and bake store kept (a sheet's cells)
        if hasattr(render, "Bakes"):
            from iblbake.device.runtime import Runtime
            rt, bakes = Runtime(args.device), Bakes(cache)
            render(sc, runtime=rt, cache=bakes)
            for _ in range(args.runs):
                t0 = time.perf_counter()
                render(sc, runtime=rt, cache=bakes)
                reused.append(time.perf_counter() - t0)
        med = lambda k: statistics.median(p["seconds"] for p in passes.get(k, [])) if k in passes else 0.0
        # lighting: the reference pass, or shade and the importance pass sampling for it
        light_s = med("reference") if "reference" in passes else med("importance") + med("shade")
        n = sc["camera"]["resolution"][0] * sc["camera"]["resolution"][1] * sc["camera"]["spp"]
        samples = passes["reference"][0].get("samples_per_pixel", 1) if "reference" in passes else \
            sc["effects"]["samples"] if sc["effects"]["specular"] == "importance" else 1
        mps = n * samples / max(light_s, 1e-9) / 1e6
        if args.json:
            print(json.dumps({"name": name, "end_s": statistics.median(ends), "light_s": light_s,
                              "lights_s": med("lights"), "gbuffer_s": med("gbuffer")}), flush=True)
            continue
        totals[name] = {"passes": sum(med(k) for k in passes), "one": statistics.median(reused) if reused else None,
                        "materials": med("materials"),
                        "textures": next((b for b in first.report["bakes"] if b["name"] == "textures"), None)}
        one = f"{statistics.median(reused):.3f}" if reused else "-"
        print(f"| {name} | {statistics.median(ends):.3f} | {one} | {med('gbuffer'):.3f} | {light_s:.3f} | "
              f"{med('lights') + med('ao') + med('gtao'):.4f} | {mps:.1f} | "
              f"{n / max(med('gbuffer'), 1e-9) / 1e6:.2f} | {geo.get('bvh_build_s', 0):.3f} |", flush=True)
    if args.json:
        return
    tex, plain = totals.get("textured mesh, 5 maps"), totals.get("textured mesh, untextured")
    if tex and plain:
        t = tex["textures"] or {}
        print(f"\ntextured / untextured (the same mesh): passes {tex['passes']:.3f} / {plain['passes']:.3f} s = "
              f"{tex['passes'] / plain['passes']:.2f}x (the materials pass {tex['materials']:.3f} s)"
              + (f", one runtime {tex['one']:.3f} / {plain['one']:.3f} s = {tex['one'] / plain['one']:.2f}x"
                 if tex["one"] and plain["one"] else "")
              + f"; textures: {t.get('textures')} decoded with their mip pyramids in {t.get('decode_and_mips_s')} s "
                f"(first render), {t.get('device_bytes', 0) / 2**20:.1f} MiB on the device")
    print(f"\ndevice: {device}; median of {args.runs} warm runs; end to end = render() incl. reading the "
          f"panorama, loading cached bakes and the mesh, all passes and read-back")


def _run_one(source, name, args, cache):
    env = dict(os.environ, IBLBAKE_BENCH_SOURCE=str(source), PYTHONPATH=str(source))
    cmd = [sys.executable, str(Path(__file__).resolve()), "--json", "--only", name, "--runs", str(args.runs),
           "--cache", str(cache)] + (["--device", args.device] if args.device else [])
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def compare(args):
    here = Path(__file__).resolve().parents[1]
    cache = Path(args.cache or tempfile.mkdtemp(prefix="iblbake-bench-"))
    print("| configuration | end to end s (this / baseline) | ratio | lighting s (this / baseline) | ratio |")
    print("|---|---|---|---|---|")
    for name, _, _ in CONFIGS:
        if args.only and args.only not in name:
            continue
        # the two sides alternate, round after round, so that a busy spell of a shared machine falls on
        # both; each side's figure is the median over rounds of its per-round medians
        rounds = [(_run_one(here, name, args, cache / "this"), _run_one(args.baseline, name, args, cache / "base"))
                  for _ in range(args.rounds)]
        a, b = ({k: statistics.median(r[i][k] for r in rounds) for k in ("end_s", "light_s")} for i in (0, 1))
        print(f"| {name} | {a['end_s']:.3f} / {b['end_s']:.3f} | {a['end_s'] / b['end_s']:.2f} | "
              f"{a['light_s']:.3f} / {b['light_s']:.3f} | {a['light_s'] / max(b['light_s'], 1e-9):.2f} |", flush=True)
    print(f"\nmedians over {args.rounds} alternating rounds of medians of {args.runs} warm runs, each side in its "
          f"own process; baseline: {args.baseline}")


if __name__ == "__main__":
    main()
