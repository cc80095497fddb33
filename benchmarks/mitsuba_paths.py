"""The path-traced reference against Mitsuba 3's `path`: Mitsuba's own acceptance test per scene.

Each renderer renders each scene K times with independent seeds; per pixel channel the two means
are compared by a two-sided z-test with both means' variances (from the K renders each), alpha 0.01
with Sidak's correction over the tested pixel channels, and the scene passes where at least 99.75%
of them do (Mitsuba's src/render/tests/test_renders.py, which tests an integrator against a
high-sample reference the same way). Both integrate the pixel's area (Mitsuba's box filter;
iblbake's camera.spp 64, a fixed Hammersley set, so its renders share that part of the error), and
silhouette pixels, where a fixed set of sub-pixel points is least like the area, are left out.

Scenes both renderers express exactly (docs/conventions.md):
- mirror on floor: a mirror sphere (metallic 1, base colour 1, roughness 0: F = 1, Mitsuba's
  `conductor` with material none) resting on a Lambert floor (specular 0 = Mitsuba's `diffuse`)
  of 8 x 8: the sphere's lower half mirrors the lit floor, which a direct-light reference renders black;
- open box: a Lambert sphere in a box of five Lambert rectangles (red and green side walls, open
  towards the camera): colour bleeding between the walls and the sphere.
Panorama: city, box-averaged to 256 x 128 and repeated to 1024 x 512 (each texel 4 x 4), written
back without chromaticities, so that both read the same texels and Mitsuba's bilinear lookup
equals iblbake's piecewise-constant one except within an eighth of a texel of its edges.
Mitsuba's envmap maps u = atan2(x, -z) / 2 pi, v = acos(y) / pi, the same texel as iblbake's
u = 0.5 - atan2(x, z) / 2 pi; its rectangle spans [-1, 1]^2 in its xy plane, normal +z.

    .venv/bin/pip install mitsuba
    .venv/bin/python benchmarks/mitsuba_paths.py [--renders 8] [--spp 256] [--variant scalar_rgb]
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
RES = (64, 48)
EYE, TARGET, FOV = [0.0, 1.6, 4.2], [0.0, 0.6, 0.0], 40.0
PIXEL_SAMPLES = 64


def scenes():
    """name -> (objects as (kind, params, material), materials {name: (bsdf kind, rgb)})"""
    return {
        "mirror on floor": (
            [("sphere", {"center": [0, 0.6, 0], "radius": 0.6}, "mirror"),
             ("rect", {"center": [0, 0, 0], "normal": "+y", "half": [4, 4]}, "floor")],
            {"mirror": ("mirror", [1, 1, 1]), "floor": ("lambert", [0.5, 0.5, 0.5])}),
        "open box": (
            [("sphere", {"center": [0, 0.5, 0], "radius": 0.5}, "white"),
             ("rect", {"center": [0, 0, 0], "normal": "+y", "half": [1.5, 1.5]}, "white"),
             ("rect", {"center": [0, 3, 0], "normal": "-y", "half": [1.5, 1.5]}, "white"),
             ("rect", {"center": [0, 1.5, -1.5], "normal": "+z", "half": [1.5, 1.5]}, "white"),
             ("rect", {"center": [-1.5, 1.5, 0], "normal": "+x", "half": [1.5, 1.5]}, "red"),
             ("rect", {"center": [1.5, 1.5, 0], "normal": "-x", "half": [1.5, 1.5]}, "green")],
            {"white": ("lambert", [0.7, 0.7, 0.7]), "red": ("lambert", [0.8, 0.15, 0.1]),
             "green": ("lambert", [0.15, 0.7, 0.15])}),
    }


AXES = {"+y": [0, 1, 0], "-y": [0, -1, 0], "+z": [0, 0, 1], "-x": [-1, 0, 0], "+x": [1, 0, 0]}


def iblbake_doc(pano: Path, objects, mats, spp: int, seed: int, bounces):
    objs = []
    for kind, p, m in objects:
        if kind == "sphere":
            objs.append({"sphere": p, "material": m})
        else:
            objs.append({"plane": {"point": p["center"], "normal": AXES[p["normal"]],
                                   "size": [2 * p["half"][0], 2 * p["half"][1]]}, "material": m})
    materials = {n: ({"base_color": c, "metallic": 1, "roughness": 0} if k == "mirror"
                     else {"base_color": c, "roughness": 1, "specular": 0}) for n, (k, c) in mats.items()}
    # the pixel's area as Mitsuba's box filter integrates it: PIXEL_SAMPLES camera samples, each
    # with spp / PIXEL_SAMPLES reference samples
    return {"camera": {"perspective": {"position": EYE, "look_at": TARGET, "fov_y": FOV}, "resolution": list(RES),
                       "spp": PIXEL_SAMPLES},
            "environment": {"path": str(pano), "background": "show"},
            "materials": materials, "objects": objs,
            "effects": {"diffuse": "reference", "specular": "reference", "tonemap": "linear",
                        "reference": {"max_samples": max(spp // PIXEL_SAMPLES, 2), "target_noise": 0, "seed": seed,
                                      "bounces": bounces}}}


def mitsuba_dict(mi, pano: Path, objects, mats, max_depth: int, spp: int, seed: int):
    T = mi.ScalarTransform4f
    bsdfs = {n: ({"type": "conductor", "material": "none", "specular_reflectance": {"type": "rgb", "value": c}}
                 if k == "mirror" else {"type": "diffuse", "reflectance": {"type": "rgb", "value": c}})
             for n, (k, c) in mats.items()}
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": max_depth},
         "sensor": {"type": "perspective", "fov": FOV, "fov_axis": "y",
                    "to_world": T().look_at(origin=EYE, target=TARGET, up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": RES[0], "height": RES[1], "rfilter": {"type": "box"},
                             "pixel_format": "rgba"},
                    "sampler": {"type": "multijitter", "sample_count": spp, "seed": seed}},
         "env": {"type": "envmap", "filename": str(pano)}}
    # a rectangle is [-1, 1]^2 in its xy plane, normal +z: turned so that +z becomes the normal
    turn = {"+y": T().rotate([1, 0, 0], -90), "-y": T().rotate([1, 0, 0], 90), "+z": T(),
            "+x": T().rotate([0, 1, 0], 90), "-x": T().rotate([0, 1, 0], -90)}
    for i, (kind, p, m) in enumerate(objects):
        if kind == "sphere":
            d[f"o{i}"] = {"type": "sphere", "center": p["center"], "radius": p["radius"], "bsdf": bsdfs[m]}
        else:
            d[f"o{i}"] = {"type": "rectangle", "bsdf": bsdfs[m],
                          "to_world": T().translate(p["center"]) @ turn[p["normal"]] @ T().scale([p["half"][0], p["half"][1], 1])}
    return d


def z_test_pass_rate(a: np.ndarray, b: np.ndarray, mask: np.ndarray, alpha=0.01) -> tuple:
    """Share of pixel channels (where mask) whose two means agree: a, b (K, H, W, 3) renders."""
    from math import erfc
    ma, mb = a.mean(0), b.mean(0)
    va, vb = a.var(0, ddof=1) / len(a), b.var(0, ddof=1) / len(b)
    z = np.abs(ma - mb) / np.sqrt(np.maximum(va + vb, 1e-30))
    p = np.vectorize(lambda x: erfc(x / math.sqrt(2)))(z[mask])
    level = 1 - (1 - alpha) ** (1 / p.size)        # Sidak
    return float((p > level).mean()), p.size


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--renders", type=int, default=8, help="independent renders per renderer and scene")
    ap.add_argument("--spp", type=int, default=256, help="samples per pixel of each render")
    ap.add_argument("--variant", default="scalar_rgb")
    ap.add_argument("--only", default=None)
    args = ap.parse_args()
    import mitsuba as mi
    mi.set_variant(args.variant)
    from iblbake import render
    from iblbake.device.runtime import Runtime
    from iblbake.io import images
    from iblbake.scene import load

    print("| scene | pixel channels | z-test pass rate | iblbake s / render | Mitsuba s / render |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        img, _ = images.read_panorama(ROOT / "examples" / "panoramas" / "city.exr")
        h, w = img.shape[:2]
        small = img[:, :, :3].reshape(128, h // 128, 256, w // 256, 3).mean((1, 3))   # equal-area rows: close
        pano = tmp / "city.exr"
        images.write_exr(pano, np.repeat(np.repeat(small, 4, 0), 4, 1).astype(np.float32))
        rt, bakes = Runtime(), render.Bakes(tmp / "cache")
        for name, (objects, mats) in scenes().items():
            if args.only and args.only not in name:
                continue
            ib, ib_t = [], []
            for k in range(args.renders):
                p = tmp / f"s{k}.yaml"
                p.write_text(yaml.safe_dump(iblbake_doc(pano, objects, mats, args.spp, 1 + k, "unbounded")))
                sc = load.load(p)
                sc.data["output"]["depth"] = str(tmp / "depth.exr")
                t0 = time.perf_counter()
                f = render.render(sc, runtime=rt, cache=bakes)
                ib_t.append(time.perf_counter() - t0)
                ib.append(f.hdr[..., :3].astype(np.float64))
            ms, ms_t = [], []
            for k in range(args.renders):
                scene = mi.load_dict(mitsuba_dict(mi, pano, objects, mats, 64, args.spp, 1000 + k))
                t0 = time.perf_counter()
                ms.append(np.array(mi.render(scene, spp=args.spp))[..., :3].astype(np.float64))
                ms_t.append(time.perf_counter() - t0)
            ib, ms = np.stack(ib), np.stack(ms)
            # interior pixels: the same surface (depth within 2%) in the 3 x 3 block around them
            depth = np.asarray(f.aovs["depth"])
            mask2 = _interior(depth if depth.ndim == 2 else depth[..., 0])
            mask = np.repeat(mask2[..., None], 3, -1)
            rate, n = z_test_pass_rate(ib, ms, mask)
            print(f"| {name} | {n} | {100 * rate:.2f}% ({'pass' if rate >= 0.9975 else 'FAIL'}) | "
                  f"{statistics.median(ib_t[1:] or ib_t):.3f} | {statistics.median(ms_t[1:] or ms_t):.3f} |", flush=True)
            rel = ib.mean(0)[mask2].mean(0) / ms.mean(0)[mask2].mean(0)
            print(f"|   mean of tested pixels, iblbake / Mitsuba | | {np.round(rel, 4).tolist()} | | |")
    print(f"\n{args.renders} renders x {args.spp} spp per renderer and scene, Mitsuba {mi.__version__} {args.variant} "
          f"`path` max_depth 64 (multijitter), iblbake reference bounces unbounded; {RES[0]}x{RES[1]}")


def _interior(depth: np.ndarray) -> np.ndarray:
    d = np.pad(depth, 1, mode="edge")
    ok = depth > 0
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            nb = d[dy:dy + depth.shape[0], dx:dx + depth.shape[1]]
            ok &= (nb > 0) & (np.abs(nb - depth) < 0.02 * depth)
    return ok | (depth == 0) & (np.pad(depth, 1)[1:-1, 1:-1] == 0)


if __name__ == "__main__":
    main()
