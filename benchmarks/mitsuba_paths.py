"""The path-traced reference against Mitsuba 3's `path`: Mitsuba's own acceptance test per scene.

iblbake renders each scene K times with independent seeds; Mitsuba traces a high-sample reference
along the same rays, every pixel's centre (iblbake's camera.spp 1), keeping each pixel's sample
variance. Per pixel channel a two-sided z-test compares iblbake's mean with the reference on the two
means' variances, alpha 0.01 with Sidak's correction over the channels tested, and a scene passes
where at least 99.75% of them do (Mitsuba's src/render/tests/test_renders.py, which tests an
integrator against a high-sample reference with its variance the same way). Through the pixel's
centre both estimate one ray's radiance: no pixel filter enters (with mi.render's box filter a
fixed set of sub-pixel points against random ones decides the test at every sharp reflection).
Every surface pixel is tested; the sky, which iblbake shows through its background pass, is not.
Then the speed at equal error (--no-speed skips it): each renderer's time to 1% relative RMSE
against its own converged image of another seed, warm, the render call only, iblbake's reference
against Mitsuba's `path` with multijitter and ldsampler (speed()).

Scenes both renderers express exactly (docs/conventions.md):
- mirror on floor: a mirror sphere (metallic 1, base colour 1, roughness 0: F = 1, Mitsuba's
  `conductor` with material none) resting on a Lambert floor (specular 0 = Mitsuba's `diffuse`)
  of 8 x 8: the sphere's lower half mirrors the lit floor, which a direct-light reference renders black;
- open box: a Lambert sphere in a box of five Lambert rectangles (red and green side walls, open
  towards the camera): colour bleeding between the walls and the sphere;
- knot on floor: the 102,400-triangle torus knot (examples/meshes/knot.ply, `make meshes`), Lambert,
  resting on a Lambert floor of 6 x 4: the BVH, interpolated normals and light between the loops;
- textured glTF: a torus as a GLB (textured_torus(): its own material, a base colour texture in
  sRGB, KHR_materials_specular specularFactor 0, so Lambert) lying on a Lambert floor, and the
  same triangles, normals and UVs as a PLY for Mitsuba's `diffuse` with a `bitmap` reflectance.
  The texture (16 x 8 texels, each a few pixels wide on screen) is read bilinearly at level 0 by
  both: Mitsuba has no mipmaps, and the GLB's sampler asks for none (minFilter LINEAR); glTF's
  UVs go to the PLY unchanged: both read row 0 of the image at v = 0 (checked with Mitsuba on a
  quad).
Panorama: courtyard (overcast: its brightest texel 34 x the mean at 256 x 128; city's sun is
3500 x), box-averaged to 256 x 128 and interpolated bilinearly to 2048 x 1024, written
back without chromaticities: both read the same texels. Mitsuba interpolates four texels where
iblbake reads one; where that is all that differs (a mirror's reflection of the sky: deterministic
in both), the test allows the range of the texel's neighbours along the same path.
Mitsuba's envmap maps u = atan2(x, -z) / 2 pi, v = acos(y) / pi, the same texel as iblbake's
u = 0.5 - atan2(x, z) / 2 pi; its rectangle spans [-1, 1]^2 in its xy plane, normal +z.

    .venv/bin/pip install mitsuba        # and Debian's libllvm19 for the CPU variant
    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so \
        .venv/bin/python benchmarks/mitsuba_paths.py [--renders 16] [--spp 256] [--ref-spp 8192] \
        [--devices pocl,intel-cpu]       # iblbake's rows on each runtime (IBLBAKE_DEVICE for one)
    ... --no-acceptance --no-speed --variance   # the samples each renderer needs, timing aside
"""

from __future__ import annotations

import argparse
import functools
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
PANO_WIDTH = 2048


def scenes(tmp: Path):
    """name -> (objects as (kind, params, material), materials {name: (bsdf kind, rgb)})"""
    glb, ply, png = textured_torus(tmp)
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
        "knot on floor": (
            [("mesh", {"path": str(ROOT / "examples" / "meshes" / "knot.ply"), "translate": [0, 0.51, 0]}, "clay"),
             ("rect", {"center": [0, 0, 0], "normal": "+y", "half": [3, 2]}, "floor")],
            {"clay": ("lambert", [0.8, 0.55, 0.35]), "floor": ("lambert", [0.6, 0.6, 0.6])}),
        # glossy interreflection: rough metal (GGX, alpha 0.09; F = 1 in both: base colour 1, Mitsuba's
        # roughconductor with material none) on a rough metal floor, in the box's coloured light
        "glossy box": (
            [("sphere", {"center": [0, 0.5, 0], "radius": 0.5}, "metal"),
             ("rect", {"center": [0, 0, 0], "normal": "+y", "half": [1.5, 1.5]}, "brushed"),
             ("rect", {"center": [0, 1.5, -1.5], "normal": "+z", "half": [1.5, 1.5]}, "white"),
             ("rect", {"center": [-1.5, 1.5, 0], "normal": "+x", "half": [1.5, 1.5]}, "red"),
             ("rect", {"center": [1.5, 1.5, 0], "normal": "-x", "half": [1.5, 1.5]}, "green")],
            {"metal": ("metal", [1, 1, 1], 0.3), "brushed": ("metal", [1, 1, 1], 0.5),
             "white": ("lambert", [0.7, 0.7, 0.7]), "red": ("lambert", [0.8, 0.15, 0.1]),
             "green": ("lambert", [0.15, 0.7, 0.15])}),
        "textured glTF": (
            [("gltf", {"path": str(glb), "ply": str(ply), "texture": str(png)}, None),
             ("rect", {"center": [0, 0, 0], "normal": "+y", "half": [3, 2]}, "floor")],
            {"floor": ("lambert", [0.6, 0.6, 0.6])}),
    }


def textured_torus(tmp: Path) -> tuple:
    """A torus lying on y = 0 (radii 0.8 and 0.35; 64 x 32 quads, vertex normals, UVs once round
    each way) as a GLB whose material is a base colour texture (16 x 8 texels of random tile
    colours, sRGB), metallic 0, roughness 1, specularFactor 0; and the same mesh as a PLY."""
    import json
    import trimesh
    from PIL import Image
    from trimesh.visual.material import PBRMaterial
    from iblbake.io.gltf import glb_bytes

    rng = np.random.default_rng(3)
    tex = np.round(rng.uniform(0.15, 0.95, (8, 16, 3)) ** (1 / 2.2) * 255).astype(np.uint8)
    png = tmp / "torus_base.png"
    Image.fromarray(tex).save(png)
    nu, nv, big, small = 64, 32, 0.8, 0.35
    uu, vv = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    a, b = 2 * np.pi * uu, 2 * np.pi * vv
    ring = np.stack([np.cos(a) * np.cos(b), np.sin(b), np.sin(a) * np.cos(b)], -1).reshape(-1, 3)
    centre = np.stack([np.cos(a), np.zeros_like(a), np.sin(a)], -1).reshape(-1, 3) * big
    verts = centre + small * ring + [0, small, 0]
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    v00, v10, v01, v11 = i * (nv + 1) + j, (i + 1) * (nv + 1) + j, i * (nv + 1) + j + 1, (i + 1) * (nv + 1) + j + 1
    faces = np.concatenate([np.stack([v00, v01, v10], -1).reshape(-1, 3),
                            np.stack([v10, v01, v11], -1).reshape(-1, 3)])
    uv = np.stack([uu, vv], -1).reshape(-1, 2)                  # glTF's convention: v = 0 at row 0
    mat = PBRMaterial(baseColorTexture=Image.fromarray(tex), metallicFactor=0.0, roughnessFactor=1.0)
    mesh = trimesh.Trimesh(verts, faces, vertex_normals=ring,
                           visual=trimesh.visual.TextureVisuals(uv=uv * [1, -1] + [0, 1], material=mat), process=False)
    glb = tmp / "torus.glb"
    mesh.export(str(glb))
    data = glb.read_bytes()                                     # add KHR_materials_specular: Lambert
    n = int.from_bytes(data[12:16], "little")
    doc = json.loads(data[20:20 + n])
    binary = data[20 + n + 8:]
    doc["materials"][0].setdefault("extensions", {})["KHR_materials_specular"] = {"specularFactor": 0.0}
    # Mitsuba's bitmap has no mipmaps: the glTF sampler says so too (LINEAR both ways, no mips),
    # which iblbake honours, so both read level 0 bilinearly also where a pixel's footprint is
    # large (silhouettes: with trilinear mips 0.6% of the channels failed there)
    doc["samplers"] = [{"magFilter": 9729, "minFilter": 9729, "wrapS": 10497, "wrapT": 10497}]
    for t in doc["textures"]:
        t["sampler"] = 0
    doc["extensionsUsed"] = sorted(set(doc.get("extensionsUsed", [])) | {"KHR_materials_specular"})
    glb.write_bytes(glb_bytes(doc, binary))
    ply = tmp / "torus.ply"
    with open(ply, "wb") as f:
        f.write(("ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % len(verts)
                 + "".join(f"property float {c}\n" for c in ("x", "y", "z", "nx", "ny", "nz", "u", "v"))
                 + "element face %d\nproperty list uchar int vertex_indices\nend_header\n" % len(faces)).encode())
        f.write(np.concatenate([verts, ring, uv], 1).astype("<f4").tobytes())
        f.write(np.concatenate([np.full((len(faces), 1), 3, np.uint8).view(np.uint8),
                                faces.astype("<i4").view(np.uint8).reshape(len(faces), 12)], 1).tobytes())
    return glb, ply, png


AXES = {"+y": [0, 1, 0], "-y": [0, -1, 0], "+z": [0, 0, 1], "-x": [-1, 0, 0], "+x": [1, 0, 0]}


def iblbake_doc(pano: Path, objects, mats, spp: int, seed: int, bounces, depth: Path):
    objs = []
    for kind, p, m in objects:
        if kind == "sphere":
            objs.append({"sphere": p, "material": m})
        elif kind == "mesh":
            objs.append({"mesh": {"path": p["path"], "translate": p["translate"]}, "material": m})
        elif kind == "gltf":                  # the file's own material
            objs.append({"mesh": {"path": p["path"]}})
        else:
            objs.append({"plane": {"point": p["center"], "normal": AXES[p["normal"]],
                                   "size": [2 * p["half"][0], 2 * p["half"][1]]}, "material": m})
    def material(kind, c, rough=0.0):
        if kind in ("mirror", "metal"):
            return {"base_color": c, "metallic": 1, "roughness": rough}
        return {"base_color": c, "roughness": 1, "specular": 0}
    materials = {n: material(*m) for n, m in mats.items()}
    return {"camera": {"perspective": {"position": EYE, "look_at": TARGET, "fov_y": FOV}, "resolution": list(RES)},
            "environment": {"path": str(pano), "background": "show"},
            "materials": materials, "objects": objs, "output": {"depth": str(depth)},
            "effects": {"diffuse": "reference", "specular": "reference", "tonemap": "linear",
                        "reference": {"max_samples": spp, "target_noise": 0, "seed": seed, "bounces": bounces}}}


def mitsuba_dict(mi, pano: Path, objects, mats, max_depth: int, spp: int, seed: int, sampler="multijitter"):
    T = mi.ScalarTransform4f
    def bsdf(kind, c, rough=0.0):
        if kind == "mirror":
            return {"type": "conductor", "material": "none", "specular_reflectance": {"type": "rgb", "value": c}}
        if kind == "metal":                   # iblbake's alpha = roughness^2
            return {"type": "roughconductor", "material": "none", "distribution": "ggx", "alpha": rough * rough,
                    "specular_reflectance": {"type": "rgb", "value": c}}
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": c}}
    bsdfs = {n: bsdf(*m) for n, m in mats.items()}
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": max_depth},
         "sensor": {"type": "perspective", "fov": FOV, "fov_axis": "y",
                    "to_world": T().look_at(origin=EYE, target=TARGET, up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": RES[0], "height": RES[1], "rfilter": {"type": "box"},
                             "pixel_format": "rgba"},
                    "sampler": {"type": sampler, "sample_count": spp, "seed": seed}},
         "env": {"type": "envmap", "filename": str(pano)}}
    # a rectangle is [-1, 1]^2 in its xy plane, normal +z: turned so that +z becomes the normal
    turn = {"+y": T().rotate([1, 0, 0], -90), "-y": T().rotate([1, 0, 0], 90), "+z": T(),
            "+x": T().rotate([0, 1, 0], 90), "-x": T().rotate([0, 1, 0], -90)}
    for i, (kind, p, m) in enumerate(objects):
        if kind == "sphere":
            d[f"o{i}"] = {"type": "sphere", "center": p["center"], "radius": p["radius"], "bsdf": bsdfs[m]}
        elif kind == "mesh":                  # its vertex normals interpolated, as iblbake's
            d[f"o{i}"] = {"type": "ply", "filename": p["path"], "to_world": T().translate(p["translate"]),
                          "bsdf": bsdfs[m]}
        elif kind == "gltf":                  # its texture in sRGB, decoded to linear as glTF's
            d[f"o{i}"] = {"type": "ply", "filename": p["ply"], "bsdf": {"type": "diffuse", "reflectance": {
                "type": "bitmap", "filename": p["texture"], "filter_type": "bilinear", "wrap_mode": "repeat"}}}
        else:
            d[f"o{i}"] = {"type": "rectangle", "bsdf": bsdfs[m],
                          "to_world": T().translate(p["center"]) @ turn[p["normal"]] @ T().scale([p["half"][0], p["half"][1], 1])}
    return d


def mitsuba_reference(mi, scene, spp: int, seed: int, chunk: int = 256) -> tuple:
    """Mitsuba's `path` along every pixel's centre ray (the ray iblbake's camera.spp 1 traces):
    per pixel channel the mean of spp samples and the variance of that mean (from the samples), in
    wavefronts of chunk samples per pixel."""
    import drjit as dr
    sensor, integrator = scene.sensors()[0], scene.integrator()
    w, h = RES
    s1 = np.zeros((h, w, 3))
    s2 = np.zeros((h, w, 3))
    taken = 0
    while taken < spp:
        n = min(chunk, spp - taken)
        idx = dr.arange(mi.UInt32, w * h * n)
        pix = idx // n
        pos = mi.Vector2f(mi.Float(pix % w) + 0.5, mi.Float(pix // w) + 0.5) / mi.ScalarVector2f(w, h)
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed * 7919 + taken, w * h * n)
        ray, weight = sensor.sample_ray(0.0, 0.0, pos, mi.Point2f(0.5, 0.5))
        spec, _, _ = integrator.sample(scene, sampler, ray)
        v = (np.array(spec * weight).T if np.array(spec).shape[0] == 3 else np.array(spec * weight))
        v = v.reshape(h, w, n, 3)
        s1 += v.sum(2)
        s2 += (v * v).sum(2)
        taken += n
    mean = s1 / spp
    return mean, np.maximum(s2 / spp - mean * mean, 0.0) * spp / (spp - 1) / spp


def z_test_pass_rate(ib: np.ndarray, ref: np.ndarray, ref_var: np.ndarray, mask: np.ndarray, lookup: np.ndarray,
                     alpha=0.01) -> tuple:
    """Mitsuba's acceptance test: the share of pixel channels (where mask) at which iblbake's mean
    over its K renders (ib: (K, H, W, 3)) and Mitsuba's reference agree, a two-sided z-test on the
    two means' variances, alpha with Sidak's correction over the channels tested. `lookup` (H, W, 3)
    bounds what the panorama's lookup convention alone may change at a pixel whose estimate is
    deterministic (iblbake reads a texel, Mitsuba interpolates four): added to the variance as
    lookup^2, else the test would compare two lookups at zero variance."""
    from math import erfc
    var = ib.var(0, ddof=1) / len(ib) + ref_var + lookup ** 2
    z = np.abs(ib.mean(0) - ref) / np.sqrt(np.maximum(var, 1e-30))
    p = np.vectorize(lambda x: erfc(x / math.sqrt(2)))(z[mask])
    level = 1 - (1 - alpha) ** (1 / p.size)
    return float((p > level).mean()), p.size


def panorama_pair(tmp: Path):
    """(the panorama both renderers read, the range image of its texels' neighbours): courtyard
    box-averaged to 256 x 128, interpolated to PANO_WIDTH, no chromaticities."""
    from iblbake.io import images
    img, _ = images.read_panorama(ROOT / "examples" / "panoramas" / "courtyard.exr")
    h, w = img.shape[:2]
    small = img[:, :, :3].reshape(128, h // 128, 256, w // 256, 3).mean((1, 3))
    pano = tmp / "courtyard.exr"
    fine = upsample(small, PANO_WIDTH // 256)
    images.write_exr(pano, fine.astype(np.float32))
    spread = tmp / "range.exr"
    images.write_exr(spread, neighbour_range(fine).astype(np.float32))
    return pano, spread


def acceptance(mi, tmp: Path, pano: Path, spread: Path, objects, mats, renders: int, spp: int, ref_spp: int, rt,
               bakes) -> dict:
    """Mitsuba's acceptance test of one scene: iblbake's `renders` renders of spp samples (seeds 1..)
    against Mitsuba's `path` at ref_spp per pixel centre. {rate, channels, ratio (iblbake's mean
    over Mitsuba's, RGB), deterministic (the share of channels iblbake's estimate does not vary)}."""
    from iblbake.render import render
    from iblbake.scene import load

    ib = []
    for k in range(renders):
        p = tmp / f"s{k}.yaml"
        p.write_text(yaml.safe_dump(iblbake_doc(pano, objects, mats, spp, 1 + k, "unbounded", tmp / "depth.exr")))
        f = render(load.load(p), runtime=rt, cache=bakes)
        ib.append(f.hdr[..., :3].astype(np.float64))
    ib = np.stack(ib)
    # where iblbake's estimate is deterministic (the same in every render: a mirror's view of the
    # sky), the two renderers differ by their lookups alone; bilinear lies within the range of
    # a texel's neighbours, so that range, followed along the same paths (the frame lit by the
    # range image), bounds it
    doc = iblbake_doc(spread, objects, mats, 2, 1, "unbounded", tmp / "depth.exr")
    p.write_text(yaml.safe_dump(doc))
    fixed = (ib.var(0) == 0).all(-1, keepdims=True)
    lookup = np.where(fixed, render(load.load(p), runtime=rt, cache=bakes).hdr[..., :3], 0.0)
    scene = mi.load_dict(mitsuba_dict(mi, pano, objects, mats, 1024, 1, 0))
    ref, ref_var = mitsuba_reference(mi, scene, ref_spp, 1)
    # every surface pixel, silhouettes too (both trace the pixel's centre); not the sky, which
    # iblbake shows through its background pass
    mask = np.repeat((np.asarray(f.aovs["depth"]) > 0)[..., None], 3, -1)
    rate, n = z_test_pass_rate(ib, ref, ref_var, mask, lookup)
    return {"rate": rate, "channels": n, "deterministic": float(np.repeat(fixed, 3, -1)[mask].mean()),
            "ratio": ib.mean(0)[mask].reshape(-1, 3).mean(0) / ref[mask].reshape(-1, 3).mean(0)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--renders", type=int, default=16, help="iblbake's independent renders (seeds) per scene")
    ap.add_argument("--spp", type=int, default=256, help="samples per pixel of each iblbake render")
    ap.add_argument("--ref-spp", type=int, default=8192, help="Mitsuba's samples per pixel (the reference)")
    ap.add_argument("--variant", default="llvm_ad_rgb", help="llvm_ad_rgb (needs DRJIT_LIBLLVM_PATH) or cuda_ad_rgb")
    ap.add_argument("--only", default=None, help="only the scenes whose name contains this (e.g. knot, box)")
    ap.add_argument("--no-speed", action="store_true", help="the acceptance test only")
    ap.add_argument("--no-acceptance", action="store_true", help="the speed comparison only")
    ap.add_argument("--target", type=float, default=0.01, help="relative RMSE the speed comparison times")
    ap.add_argument("--converged", type=int, default=16384, help="samples per pixel of the converged images")
    ap.add_argument("--speed-scale", type=int, default=1, help="the speed comparison's frames, times 64x48")
    ap.add_argument("--devices", default=None,
                    help="iblbake's OpenCL devices, comma-separated --device specs (pocl,intel-cpu): each its "
                         "own rows; default the device iblbake picks")
    ap.add_argument("--variance", action="store_true",
                    help="the variance at --spp of both renderers (8 seeds): the samples each needs, timing aside")
    ap.add_argument("--per-bounce", action="store_true",
                    help="samples per second at each bounce count, both renderers, and where iblbake's time goes")
    args = ap.parse_args()
    import mitsuba as mi
    mi.set_variant(args.variant)
    from iblbake.render import Bakes
    from iblbake.device.runtime import Runtime

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        pano, spread = panorama_pair(tmp)
        runtimes = [Runtime(d) for d in args.devices.split(",")] if args.devices else [Runtime()]
        bakes = Bakes(tmp / "cache")
        if not args.no_acceptance:
            print("| scene | pixel channels | z-test pass rate | iblbake / Mitsuba (mean) | "
                  "deterministic channels (lookup range allowed) |")
            print("|---|---|---|---|---|")
            for rt in runtimes:
                for name, (objects, mats) in scenes(tmp).items():
                    if args.only and args.only not in name:
                        continue
                    res = acceptance(mi, tmp, pano, spread, objects, mats, args.renders, args.spp, args.ref_spp, rt,
                                     bakes)
                    label = f"{name} ({rt.device_label})" if len(runtimes) > 1 else name
                    print(f"| {label} | {res['channels']} | {100 * res['rate']:.2f}% "
                          f"({'pass' if res['rate'] >= 0.9975 else 'FAIL'}) | "
                          f"{np.round(res['ratio'], 4).tolist()} | {100 * res['deterministic']:.1f}% |", flush=True)
            print(f"\niblbake: {args.renders} renders x {args.spp} samples per pixel (seeds 1-{args.renders}), "
                  f"reference bounces unbounded; Mitsuba {mi.__version__} {args.variant} `path` max_depth 1024, "
                  f"{args.ref_spp} samples per pixel centre; {RES[0]}x{RES[1]}")
        if args.per_bounce:
            for rt in runtimes:
                per_bounce(args, mi, tmp, pano, rt, bakes)
        if args.variance:
            variance(args, mi, tmp, pano, runtimes[0], bakes)
        if not args.no_speed:
            speed(args, mi, tmp, pano, runtimes, bakes)


def rel_rmse(img: np.ndarray, converged: np.ndarray, mask: np.ndarray) -> float:
    """RMS over the masked pixels of the luminance error, over the converged image's mean luminance."""
    from iblbake.core.metrics import luminance
    a, b = luminance(img[mask]), luminance(converged[mask])
    return float(np.sqrt(np.mean((a - b) ** 2)) / b.mean())


def time_to_error(render_at, converged, n_converged: int, mask, target, start=4, taken=lambda n: n):
    """(samples per pixel, seconds) at which the relative RMSE against the truth reaches target:
    renders at doubling sample counts (render_at(n) -> (image, seconds)), the two that bracket the
    target interpolated in log-log (error and time both power laws of n). The converged image has
    noise of its own, n / n_converged of the test image's variance where both fall as 1 / n, so
    the RMSE against it is divided by sqrt(1 + n / n_converged). taken(n): the samples a render
    asked for n takes (Mitsuba's multijitter rounds 32 up to 35, a grid of 5 x 7)."""
    prev, n = None, start
    while n <= n_converged:                     # beyond, the converged image is no longer the truth
        img, sec = render_at(n)
        k = taken(n)
        e = rel_rmse(img, converged, mask) / math.sqrt(1 + k / taken(n_converged))
        if e <= target:
            if prev is None:
                return k, sec
            k0, s0, e0 = prev
            t = (math.log(e0) - math.log(target)) / (math.log(e0) - math.log(e))
            return k0 * (k / k0) ** t, s0 * (sec / s0) ** t
        prev, n = (k, sec, e), n * 2
    return None


def mitsuba_samples(mi, sampler: str, n: int) -> int:
    """The samples per pixel Mitsuba's `sampler` takes when asked for n (its own rounding)."""
    s = mi.load_dict({"type": sampler, "sample_count": n})
    s.set_sample_count(n)
    return int(s.sample_count())


def speed(args, mi, tmp: Path, pano: Path, runtimes, bakes):
    """Time to 1% relative RMSE against each renderer's own converged image (another seed), warm,
    the render call only (median of 3 at each sample count), iblbake's reference on each of
    `runtimes` (its own converged image on each) against Mitsuba's `path` with each of its
    stratified samplers; the ratio column is the first runtime's time over each row's."""
    global RES
    RES = (RES[0] * args.speed_scale, RES[1] * args.speed_scale)
    from iblbake.render import render
    from iblbake.scene import load

    print(f"\n| scene | renderer | spp to {100 * args.target:g}% | seconds | Msamples/s | iblbake s / this s |")
    print("|---|---|---|---|---|---|")
    for name, (objects, mats) in scenes(tmp).items():
        if args.only and args.only not in name:
            continue
        p = tmp / "speed.yaml"

        def ib_at(n, seed=1, repeats=3, rt=runtimes[0]):
            p.write_text(yaml.safe_dump(iblbake_doc(pano, objects, mats, n, seed, "unbounded", tmp / "depth.exr")))
            sc = load.load(p)
            times, f = [], None
            for _ in range(repeats):
                t0 = time.perf_counter()
                f = render(sc, runtime=rt, cache=bakes)
                times.append(time.perf_counter() - t0)
            return f.hdr[..., :3].astype(np.float64), statistics.median(times)

        p.write_text(yaml.safe_dump(iblbake_doc(pano, objects, mats, 2, 1, "unbounded", tmp / "depth.exr")))
        mask = np.asarray(render(load.load(p), runtime=runtimes[0], cache=bakes).aovs["depth"]) > 0
        rows = []
        for rt in runtimes:
            at = functools.partial(ib_at, rt=rt)
            conv, _ = at(args.converged, seed=999, repeats=1)
            who = f"iblbake reference, {rt.device_label}" if len(runtimes) > 1 else "iblbake reference"
            rows.append((who, time_to_error(at, conv, args.converged, mask, args.target)))
        for sampler in ("multijitter", "ldsampler"):
            def mi_at(n, seed=1, sampler=sampler, repeats=3):
                scene = mi.load_dict(mitsuba_dict(mi, pano, objects, mats, 1024, n, seed, sampler))
                if repeats > 1:
                    mi.render(scene, spp=n)                                     # warm: the kernels
                times, img = [], None
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    img = np.array(mi.render(scene, spp=n))
                    times.append(time.perf_counter() - t0)
                return img[..., :3].astype(np.float64), statistics.median(times)
            mconv, _ = mi_at(args.converged, seed=999, repeats=1)
            taken = functools.partial(mitsuba_samples, mi, sampler)
            rows.append((f"Mitsuba path, {sampler}",
                         time_to_error(mi_at, mconv, args.converged, mask, args.target, taken=taken)))
        base = rows[0][1]
        for who, r in rows:
            if r is None:
                print(f"| {name} | {who} | > {args.converged} | | | |")
                continue
            ratio = f"{base[1] / r[1]:.2f}" if base else "-"
            print(f"| {name} | {who} | {r[0]:.0f} | {r[1]:.3f} | {RES[0] * RES[1] * r[0] / r[1] / 1e6:.2f} | "
                  f"{ratio} |", flush=True)
    print(f"\n{RES[0]}x{RES[1]}; iblbake devices: {', '.join(rt.device_label for rt in runtimes)}; "
          f"Mitsuba {args.variant}; converged images: "
          f"{args.converged} samples per pixel, seed 999; Msamples/s: pixels x spp / seconds")


def per_bounce(args, mi, tmp: Path, pano: Path, rt, bakes):
    """Samples per second per bounce count (--spp samples per pixel, warm, median of 3, the render
    call), and iblbake's reference pass split by what each step adds: shading alone (visibility
    off: no ray leaves the G-buffer's surfaces), the direct light's two shadow rays per sample
    (bounces 1), then each further bounce (a closest-hit ray, its shading and its environment
    shadow ray). Mitsuba's max_depth counts segments: bounces N is max_depth N + 1."""
    from iblbake.render import render
    from iblbake.scene import load

    steps = [("shading only (visibility off)", 1, False), ("bounces 1 (direct: + shadow rays)", 1, True),
             ("bounces 2", 2, True), ("bounces 3", 3, True), ("unbounded", "unbounded", True)]
    print("\n| scene | bounces | iblbake reference pass ms | Msamples/s | Mitsuba max_depth | Mitsuba ms | Msamples/s |")
    print("|---|---|---|---|---|---|---|")
    n = RES[0] * RES[1] * args.spp
    for name, (objects, mats) in scenes(tmp).items():
        if args.only and args.only not in name:
            continue
        for label, bounces, vis in steps:
            doc = iblbake_doc(pano, objects, mats, args.spp, 1, bounces, tmp / "depth.exr")
            doc["effects"]["reference"]["visibility"] = vis
            p = tmp / "bounce.yaml"
            p.write_text(yaml.safe_dump(doc))
            sc = load.load(p)
            times = []
            for k in range(4):
                f = render(sc, runtime=rt, cache=bakes)
                if k:
                    times.append(sum(q["seconds"] for q in f.report["passes"] if q["name"] == "reference"))
            ib = statistics.median(times)
            row = f"| {name} | {label} | {1e3 * ib:.1f} | {n / ib / 1e6:.2f} |"
            if vis:
                depth = 1024 if bounces == "unbounded" else bounces + 1
                scene = mi.load_dict(mitsuba_dict(mi, pano, objects, mats, depth, args.spp, 1))
                mi.render(scene, spp=args.spp)
                mt = []
                for _ in range(3):
                    t0 = time.perf_counter()
                    np.array(mi.render(scene, spp=args.spp))
                    mt.append(time.perf_counter() - t0)
                m = statistics.median(mt)
                taken = RES[0] * RES[1] * mitsuba_samples(mi, "multijitter", args.spp)
                row += f" {depth} | {1e3 * m:.1f} | {taken / m / 1e6:.2f} |"
            else:
                row += " | | |"
            print(row, flush=True)
    print(f"\n{RES[0]}x{RES[1]}, {args.spp} samples per pixel; iblbake device: {rt.device_label}; "
          f"Mitsuba {args.variant} `path` with multijitter")


def variance(args, mi, tmp: Path, pano: Path, rt, bakes, seeds: int = 8):
    """Samples needed, timing aside: per scene the relative variance of the frame at --spp samples
    per pixel times spp (the mean over surface pixels of each pixel's luminance variance across
    `seeds` seeds, over the squared mean luminance; the spp to 1% relative RMSE is it / 1e-4),
    iblbake's reference with one sequence per G-buffer sample (target_noise 0) and with the two
    replicates a noise target keeps, against Mitsuba's `path` with each of its samplers. Mitsuba
    box-filters random points over the pixel; iblbake traces its centre (camera.spp 1): Mitsuba's
    figure holds the pixel's own variance too, which is small away from edges."""
    from iblbake.core.metrics import luminance
    from iblbake.render import render
    from iblbake.scene import load

    print("\n| scene | iblbake, one sequence | iblbake, two replicates | Mitsuba multijitter | ldsampler | "
          "independent |")
    print("|---|---|---|---|---|---|")
    for name, (objects, mats) in scenes(tmp).items():
        if args.only and args.only not in name:
            continue
        p, mask = tmp / "variance.yaml", None

        def rel(frames, spp=args.spp):
            a = np.array(frames)
            return a.var(0, ddof=1).mean() / a.mean() ** 2 * spp

        row = []
        for target in (0.0, 1e-9):                       # 1e-9: replicates kept, never reached
            frames = []
            for seed in range(1, seeds + 1):
                doc = iblbake_doc(pano, objects, mats, args.spp, seed, "unbounded", tmp / "depth.exr")
                doc["effects"]["reference"]["target_noise"] = target
                p.write_text(yaml.safe_dump(doc))
                f = render(load.load(p), runtime=rt, cache=bakes)
                mask = np.asarray(f.aovs["depth"]) > 0
                frames.append(luminance(f.hdr[..., :3].astype(np.float64))[mask])
            row.append(rel(frames))
        for sampler in ("multijitter", "ldsampler", "independent"):
            frames = []
            for seed in range(1, seeds + 1):
                scene = mi.load_dict(mitsuba_dict(mi, pano, objects, mats, 1024, args.spp, seed, sampler))
                frames.append(luminance(np.array(mi.render(scene, spp=args.spp))[..., :3].astype(np.float64))[mask])
            row.append(rel(frames, mitsuba_samples(mi, sampler, args.spp)))   # what it took (ldsampler: 128 -> 256)
        print(f"| {name} | " + " | ".join(f"{v:.3f}" for v in row) + " |", flush=True)
    print(f"\n{RES[0]}x{RES[1]}, {args.spp} samples per pixel, {seeds} seeds; relative variance x spp "
          f"(lower needs fewer samples); iblbake device: {rt.device_label}; Mitsuba {args.variant} `path`")


def neighbour_range(img: np.ndarray) -> np.ndarray:
    """Per texel the largest difference to its 8 neighbours (wrapping in u): how far a bilinear
    lookup anywhere in the texel can be from the texel's value."""
    out = np.zeros_like(img)
    pad = np.concatenate([img[:, -1:], img, img[:, :1]], 1)
    pad = np.concatenate([pad[:1], pad, pad[-1:]], 0)
    h, w = img.shape[:2]
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            out = np.maximum(out, np.abs(pad[dy:dy + h, dx:dx + w] - img))
    return out


def upsample(img: np.ndarray, k: int) -> np.ndarray:
    """Bilinear between texel centres, k times finer (wrapping in u, clamped in v): a panorama smooth
    at the scale of its texels, where iblbake's nearest lookup and Mitsuba's bilinear one agree."""
    h, w = img.shape[:2]
    def axis(n, wrap):
        x = (np.arange(n * k) + 0.5) / k - 0.5
        i0 = np.floor(x).astype(int)
        f = x - i0
        i1 = i0 + 1
        if wrap:
            return i0 % n, i1 % n, f
        return np.clip(i0, 0, n - 1), np.clip(i1, 0, n - 1), f
    j0, j1, fy = axis(h, False)
    i0, i1, fx = axis(w, True)
    rows = img[j0] * (1 - fy)[:, None, None] + img[j1] * fy[:, None, None]
    return rows[:, i0] * (1 - fx)[None, :, None] + rows[:, i1] * fx[None, :, None]


if __name__ == "__main__":
    main()
