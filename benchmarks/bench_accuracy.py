"""Where the specular modes' error against the converged reference comes from (issue 4).

Part 1, the renderer: a metal sphere (base 0.95, 48x48, panorama turned 70 degrees, the scene of
tests/test_render.py) per panorama and roughness; relative RMSE over the sphere pixels of
- a second reference with another seed (the reference's own noise),
- `importance` N = 1024 (the tested setting) and 4096, and with force_mip0 at N = 65536
  (no filtered lookups: does the estimator itself converge to the reference?),
- `prefiltered` (the split sum).
Part 2, the split sum with exact integrals (numpy, float64, panorama at 512x256, no chain, no
table, no interpolation): for random normals at fixed NoV, the split-sum product
[sum L w / sum w] * [integral of D V F NoL] against the integral of L D V F NoL (luminance),
with the prefilter weight w = D NoL (Karis, what `mips` bakes) and w = D (unweighted): relative
RMSE over the normals (the metric of part 1) and the mean ratio. Its error is the approximation's
own, the floor of any split-sum renderer.

    python benchmarks/bench_accuracy.py [--env city studio courtyard] [--roughness 0.25 0.5 1]
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from iblbake.core import brdf
from iblbake.core import conventions
from iblbake.io import images
from iblbake.core import metrics
from iblbake.bake import radiance
from iblbake.render import render
from iblbake.scene import load as scene  # noqa: E402

LUMA = np.array([0.2126, 0.7152, 0.0722])


def render_sphere(folder: Path, cache: Path, env: str, r: float, effects: dict):
    doc = {"camera": {"perspective": {"position": [0, 0, 3], "fov_y": 45}, "resolution": [48, 48]},
           "environment": {"path": str(ROOT / "examples" / "panoramas" / f"{env}.exr"),
                           "background": "hide", "rotation_y": 70},
           "materials": {"m": {"base_color": [0.95] * 3, "metallic": 1, "roughness": r}},
           "objects": [{"sphere": {"radius": 1}, "material": "m"}],
           "effects": {"diffuse": "off", **effects}}
    p = folder / "scene.yaml"
    p.write_text(yaml.safe_dump(doc))
    return render(scene.load(p), cache_root=cache).hdr


def renderer_table(envs, roughness, cache: Path):
    def ref_fx(seed):
        return {"specular": "reference",
                "reference": {"max_samples": 4096, "target_noise": 0.003, "batch": 256, "seed": seed}}

    modes = [("importance N=1024", {"specular": "importance", "samples": 1024}),
             ("importance N=4096", {"specular": "importance", "samples": 4096}),
             ("force_mip0 N=65536", {"specular": "importance", "samples": 65536, "force_mip0": True}),
             ("prefiltered", {"specular": "prefiltered"})]
    print("| panorama | r | reference vs reference | " + " | ".join(m for m, _ in modes) + " |")
    print("|---|---|---|" + "---|" * len(modes))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for env in envs:
            for r in roughness:
                ref = render_sphere(tmp, cache, env, r, ref_fx(1))
                hit = ref[..., 3] == 1
                want = ref[..., :3][hit]
                cells = [f"{metrics.relative_rmse(render_sphere(tmp, cache, env, r, ref_fx(2))[..., :3][hit], want):.1%}"]
                for _, fx in modes:
                    got = render_sphere(tmp, cache, env, r, fx)[..., :3][hit]
                    ratio = (got @ LUMA).mean() / (want @ LUMA).mean()
                    cells.append(f"{metrics.relative_rmse(got, want):.1%} (mean x{ratio:.3f})")
                print(f"| {env} | {r:g} | " + " | ".join(cells) + " |", flush=True)


def split_sum_table(envs, roughness, f0=0.95, normals=24):
    print("| panorama | r | NoV | w = D NoL: relative RMSE (mean ratio) | w = D: relative RMSE (mean ratio) |")
    print("|---|---|---|---|---|")
    rng = np.random.default_rng(1)
    ns = rng.normal(size=(normals, 3))
    ns /= np.linalg.norm(ns, axis=1, keepdims=True)
    for env in envs:
        img, _ = images.read_panorama(ROOT / "examples" / "panoramas" / f"{env}.exr")
        img = radiance.downsample_twin(img[..., :3], 512, 256)
        h, w = img.shape[:2]
        dirs = conventions.equirect_texel_dirs(w, h).reshape(-1, 3)
        om = conventions.equirect_solid_angles(w, h).reshape(-1)
        lum = img.reshape(-1, 3) @ LUMA
        for r in roughness:
            a = r * r
            for nov in (1.0, 0.7, 0.4, 0.2):
                split = {"nol": [], "none": []}
                exacts = []
                for n in ns:
                    t = np.cross(n, [0.3, 1.0, 0.1])
                    t /= np.linalg.norm(t)
                    v = nov * n + np.sqrt(1 - nov * nov) * t
                    c = dirs @ n
                    hv = dirs + v
                    hv /= np.linalg.norm(hv, axis=1, keepdims=True)
                    f = np.where(c > 0, brdf.d_ggx(hv @ n, a) * brdf.v_smith_ggx_correlated(nov, c, a)
                                 * brdf.f_schlick(hv @ v, f0) * c, 0.0) * om
                    exact, energy = f @ lum, f.sum()
                    exacts.append(exact)
                    cr = dirs @ (2 * nov * n - v)
                    d = np.where(cr > 0, brdf.d_ggx(np.sqrt(np.maximum(0.5 * (1 + cr), 0)), a), 0.0) * om
                    for name, wgt in (("nol", d * np.maximum(cr, 0)), ("none", d)):
                        split[name].append((wgt @ lum) / wgt.sum() * energy)
                cells = [f"{metrics.relative_rmse(split[k], exacts):.1%} (x{np.mean(split[k]) / np.mean(exacts):.3f})"
                         for k in ("nol", "none")]
                print(f"| {env} | {r:g} | {nov:g} | " + " | ".join(cells) + " |", flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--env", nargs="+", default=["city", "studio", "courtyard"])
    ap.add_argument("--roughness", type=float, nargs="+", default=[0.25, 0.5, 1.0])
    ap.add_argument("--cache", default=None, help="bake cache folder (default: a temporary one)")
    ap.add_argument("--skip-render", action="store_true")
    args = ap.parse_args()
    if not args.skip_render:
        print("Renderer against the converged reference (relative RMSE over sphere pixels; mean luminance ratio)\n")
        if args.cache:
            renderer_table(args.env, args.roughness, Path(args.cache))
        else:
            with tempfile.TemporaryDirectory() as cache:
                renderer_table(args.env, args.roughness, Path(cache))
    print("\nThe split sum with exact integrals (24 random normals per row)\n")
    split_sum_table(args.env, args.roughness)


if __name__ == "__main__":
    main()
