"""GTAO against ray-traced AO, as XeGTAO was tuned: on the example scenes, the AO image of every
gtao setting against 1024-ray raytraced AO of the same radius, and the cost of each.

The AO image is read off the frame itself: every material white and diffuse, the panorama a
constant, specular off, so each pixel is its SH irradiance times its occlusion, and the frame
divided by the same frame without AO is the AO. Errors on fully covered object pixels: RMSE and
mean (bias) of AO (in [0, 1]), against the reference's own noise and against raytraced AO at 16
and 64 rays. Times: the median of 3 frames with a kept runtime, the AO pass alone.

    python benchmarks/tune_gtao.py [--device SPEC] [--side 640] [--search] [--ref-rays 1024]

Without --search it measures the defaults (and a few named settings); --search walks a grid of
radius_scale x falloff x power x slices/steps and prints the best by mean RMSE over the scenes.
"""

import argparse
import itertools
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SCENES = ROOT / "examples" / "scenes"

from iblbake.render import Bakes, render  # noqa: E402
from iblbake.device.runtime import Runtime  # noqa: E402
from iblbake.io import images  # noqa: E402
from iblbake.scene import load as scene  # noqa: E402
from iblbake.scene.schema import GTAO_DEFAULTS  # noqa: E402


def knot():
    doc = yaml.safe_load((SCENES / "mesh.yaml").read_text())
    doc["objects"][0]["mesh"]["path"] = str((SCENES / doc["objects"][0]["mesh"]["path"]).resolve())
    return "knot on its floor (orthographic)", doc, 0.5


def grid():
    doc = yaml.safe_load((SCENES / "sphere_grid.yaml").read_text())
    doc["objects"].append({"plane": {"point": [0, -2.1, 0], "normal": [0, 1, 0], "size": [14, 8]},
                           "material": "d0"})
    doc["camera"]["perspective"]["position"] = [0, 3, 13]
    return "sphere grid on a plane (perspective)", doc, 1.0


def ao_scene(tmp, doc, radius, side, effects):
    doc = {**doc, "camera": dict(doc["camera"])}
    w, h = doc["camera"].get("resolution", [1280, 720])
    doc["camera"]["resolution"] = [side, max(1, round(side * h / w))]
    doc["environment"] = {"path": str(tmp / "white.exr"), "background": "hide"}
    doc["materials"] = {m: {"base_color": [1, 1, 1], "metallic": 0, "roughness": 1} for m in doc["materials"]}
    doc["effects"] = {"diffuse": "sh", "specular": "off", "ao_radius": radius, **effects}
    doc.pop("output", None)
    p = tmp / "scene.yaml"
    p.write_text(yaml.safe_dump(doc))
    return scene.load(p)


def frame(rt, bakes, sc, runs=1):
    times, fr = [], None
    for _ in range(runs):
        fr = render(sc, runtime=rt, cache=bakes)
        times.append(sum(p["seconds"] for p in fr.report["passes"] if p["name"] in ("ao", "gtao")))
    return fr, statistics.median(times)


def ao_image(rt, bakes, tmp, doc, radius, side, effects, open_frame, runs=1):
    fr, t = frame(rt, bakes, ao_scene(tmp, doc, radius, side, effects), runs)
    with np.errstate(divide="ignore", invalid="ignore"):
        return fr.hdr[..., 0] / open_frame, t


def errors(ao, ref, mask):
    d = (ao - ref)[mask]
    return float(np.sqrt(np.mean(d ** 2))), float(d.mean())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default=None)
    ap.add_argument("--side", type=int, default=640, help="frame width (the scenes' aspect kept)")
    ap.add_argument("--ref-rays", type=int, default=1024)
    ap.add_argument("--search", action="store_true")
    args = ap.parse_args()
    rt = Runtime(args.device)
    print(f"device: {rt.device_label}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        images.write_exr(tmp / "white.exr", np.ones((16, 32, 3), np.float32))
        bakes = Bakes(tmp / "cache")
        cases = []
        for name, doc, radius in (knot(), grid()):
            open_fr, _ = frame(rt, bakes, ao_scene(tmp, doc, radius, args.side, {"ao": "off"}))
            mask = open_fr.hdr[..., 3] == 1
            t0 = time.perf_counter()
            ref, _ = ao_image(rt, bakes, tmp, doc, radius, args.side,
                              {"ao": "raytraced", "ao_samples": args.ref_rays}, open_fr.hdr[..., 0])
            cases.append((name, doc, radius, open_fr.hdr[..., 0], mask, ref))
            print(f"{name}: reference {args.ref_rays} rays in {time.perf_counter() - t0:.1f} s, "
                  f"mean AO {ref[mask].mean():.3f}, {(ref[mask] < 0.95).mean():.0%} of pixels below 0.95")

        def measure(label, effects, runs=3):
            row = [label]
            rmses = []
            for name, doc, radius, open_img, mask, ref in cases:
                ao, t = ao_image(rt, bakes, tmp, doc, radius, args.side, effects, open_img, runs)
                rmse, bias = errors(ao, ref, mask)
                rmses.append(rmse)
                row += [f"{rmse:.4f}", f"{bias:+.4f}", f"{t * 1e3:.1f}"]
            return statistics.mean(rmses), row

        print("\n| AO | " + " | ".join(f"{c[0]}: RMSE | bias | AO pass ms" for c in cases) + " |")
        print("|---|" + "---|---|---|" * len(cases))
        for n in (16, 64):
            print("| " + " | ".join(measure(f"raytraced {n} rays", {"ao": "raytraced", "ao_samples": n})[1]) + " |")
        print("| " + " | ".join(measure("gtao defaults " + str(GTAO_DEFAULTS), {"ao": "gtao"})[1]) + " |")
        for slices, steps in ((1, 6), (2, 3), (2, 4), (3, 4), (4, 8)):
            g = {**GTAO_DEFAULTS, "slices": slices, "steps": steps}
            print("| " + " | ".join(measure(f"gtao {slices} slices x {steps} steps", {"ao": "gtao", "gtao": g})[1]) + " |")
        if not args.search:
            return
        results = []
        for rs, fo, pw, (sl, st), dn, res in itertools.product((1.5, 2.0, 2.5), (0.3, 0.6),
                                                               (1.0, 1.3, 1.6), ((2, 6),), (1, 2),
                                                               ("half", "full")):
            g = {"slices": sl, "steps": st, "radius_scale": rs, "falloff": fo, "power": pw, "denoise": dn,
                 "resolution": res}
            score, row = measure(str(g), {"ao": "gtao", "gtao": g}, runs=1)
            results.append((score, row))
        results.sort(key=lambda r: r[0])
        print("\nbest of the search (mean RMSE over the scenes):")
        for score, row in results[:8]:
            print(f"{score:.4f} | " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
