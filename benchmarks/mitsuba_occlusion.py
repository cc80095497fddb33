"""Shadow rays against Mitsuba 3: does the reference's visibility lose light?

The scene of issue 33's report: a Lambert sphere (albedo 0.6, radius 0.6, centre 0.9 above the
floor) over a 6 x 6 floor under studio, seen orthographically from (0, 5, 7) at 112x112. iblbake's
`reference` (diffuse alone) with visibility on and off; Mitsuba 3's `path` at max_depth 2 (direct
light) with the floor and without it. Each renderer's occlusion factor per pixel, on / off and
floor / no floor, cancels what the two BSDFs do differently (iblbake's Fresnel-weighted diffuse
against Mitsuba's Lambert), so their ratio is 1 where the shadow rays agree. Silhouette pixels are
left out (one render mixes the floor behind them, the other the sky).

Conventions: the panorama is read by iblbake (chromaticities as stored) and written back without
them, so both renderers read the same texels; Mitsuba's envmap maps a direction to
u = atan2(x, -z) / 2 pi, v = acos(y) / pi, the same texel as iblbake's u = 0.5 - atan2(x, z) / 2 pi;
its orthographic sensor scaled by half the view's width; its rectangle of half size 3 turned to +y.

Needs Mitsuba 3 beside iblbake: `.venv/bin/pip install mitsuba`, then
`.venv/bin/python benchmarks/mitsuba_occlusion.py [--spp 4096] [--variant scalar_rgb]`.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
RES, WIDTH = 112, 2.6
EYE, TARGET = [0, 5, 7], [0, 0.9, 0]


def iblbake_frames(pano: Path, folder: Path) -> dict:
    from iblbake.render import render
    from iblbake.scene import load

    out = {}
    for name, floor, visibility in (("on", True, True), ("off", True, False), ("alone", False, False)):
        objects = [{"sphere": {"center": TARGET, "radius": 0.6}, "material": "m"}]
        if floor:
            objects.append({"plane": {"point": [0, 0, 0], "size": 6}, "material": "f"})
        doc = {"camera": {"orthographic": {"position": EYE, "look_at": TARGET, "width": WIDTH},
                          "resolution": [RES, RES]},
               "environment": {"path": str(pano)},
               "materials": {"m": {"base_color": [0.6] * 3, "roughness": 1},
                             "f": {"base_color": [0.5] * 3, "roughness": 1}},
               "objects": objects,
               "effects": {"diffuse": "reference", "specular": "off",
                           "reference": {"visibility": visibility, "max_samples": 4096, "target_noise": 0.001}}}
        p = folder / f"{name}.yaml"
        p.write_text(yaml.safe_dump(doc))
        out[name] = render(load.load(p)).hdr
    return out


def mitsuba_frames(pano: Path, variant: str, spp: int) -> dict:
    import mitsuba as mi
    mi.set_variant(variant)
    T = mi.ScalarTransform4f
    out = {}
    for name, floor in (("floor", True), ("nofloor", False)):
        scene = {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
                 "sensor": {"type": "orthographic",
                            "to_world": T().look_at(origin=EYE, target=TARGET, up=[0, 1, 0]) @ T().scale([WIDTH / 2, WIDTH / 2, 1]),
                            "film": {"type": "hdrfilm", "width": RES, "height": RES, "rfilter": {"type": "box"},
                                     "pixel_format": "rgba"},
                            "sampler": {"type": "multijitter", "sample_count": spp}},
                 "env": {"type": "envmap", "filename": str(pano)},
                 "ball": {"type": "sphere", "center": TARGET, "radius": 0.6,
                          "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6] * 3}}}}
        if floor:
            scene["floor"] = {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90) @ T().scale([3, 3, 1]),
                              "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5] * 3}}}
        out[name] = np.array(mi.render(mi.load_dict(scene), spp=spp))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=4096)
    ap.add_argument("--variant", default="scalar_rgb")
    args = ap.parse_args()
    from iblbake.io import images

    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        img, _ = images.read_panorama(ROOT / "examples" / "panoramas" / "studio.exr")
        pano = d / "studio.exr"
        images.write_exr(pano, img)
        ib = iblbake_frames(pano, d)
        ms = mitsuba_frames(pano, args.variant, args.spp)
    lum = lambda a: a[..., :3].mean(-1)                                    # noqa: E731
    sphere = ib["alone"][..., 3] > 0.999
    inner = sphere.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            inner &= np.roll(np.roll(sphere, dy, 0), dx, 1)
    q = (lum(ib["on"]) / lum(ib["off"])) / (lum(ms["floor"]) / lum(ms["nofloor"]))
    bsdf = lum(ib["alone"]) / lum(ms["nofloor"])
    print(f"iblbake alone / Mitsuba alone (the BSDFs' difference): median {np.median(bsdf[inner]):.4f}")
    print(f"occlusion factor, iblbake / Mitsuba, {int(inner.sum())} interior sphere pixels: median "
          f"{np.median(q[inner]):.4f}, p5 {np.percentile(q[inner], 5):.4f}, p95 {np.percentile(q[inner], 95):.4f}")
    print("rows   iblbake on/off   Mitsuba floor/no floor")
    for y in range(0, RES, 8):
        m = inner[y:y + 8]
        if m.sum() > 10:
            a = lum(ib["on"])[y:y + 8][m].sum() / lum(ib["off"])[y:y + 8][m].sum()
            b = lum(ms["floor"])[y:y + 8][m].sum() / lum(ms["nofloor"])[y:y + 8][m].sum()
            print(f"{y:3d}-{y + 7:<3d} {a:14.4f} {b:24.4f}")


if __name__ == "__main__":
    main()
