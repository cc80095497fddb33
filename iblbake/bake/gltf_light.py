"""An EXT_lights_image_based light from a panorama: the GGX-prefiltered cube chain at the
roughness each mip is read at, its faces as Babylon.js reads them, RGBD-packed, and the SH
irradiance coefficients (iblbake/io/gltf.py writes the file).

What Babylon.js 9 (the extension's reference loader; checked by rendering in tests/test_gltf_light.py)
does with the light, and so what is baked here:
- Mip k of N, specularImageSize S, is read for GGX alpha = S^(k/(N-1) - 1) (its shader's
  getLodFromAlphaG, log2(S alpha) times lodGenerationScale = (N-1)/log2(S)): alpha doubles
  twice per mip, from 1/S (a lobe one texel wide: mip 0 is the mirror) to 1. The extension's
  text says the mips "evenly map to roughness values from 0 to 1"; `mapping="linear"` bakes
  r_k = k/(N-1) for loaders that do that.
- Its world is left-handed: glTF's (x, y, z) is (-x, y, z) there (the loader's root node), and it
  samples the cube map in that world with every face image's rows bottom to top. In iblbake's
  cube faces (Vulkan's orientation, docs/conventions.md) that is: +X and -X swapped, every face turned
  180 degrees.
"""

from __future__ import annotations

import math

import numpy as np

from iblbake.bake import layouts
from iblbake.core.metrics import luminance

MAPPINGS = ("babylon", "linear")
DEFAULT_SIZE = 256
DEFAULT_MIN_SIZE = 16     # the extension: "the lowest-resolution mip ... (say, 16x16) for roughness 1"


def level_sizes(size: int, min_size: int) -> list:
    """Face size of each mip: size >> k down to min_size (both powers of two)."""
    for name, v in (("size", size), ("min size", min_size)):
        if v < 1 or v & (v - 1):
            raise ValueError(f"{name} {v} is not a power of two")
    return [size >> k for k in range(int(math.log2(size)) - int(math.log2(min(min_size, size))) + 1)]


def level_roughness(size: int, levels: int, mapping: str = "babylon") -> list:
    """Perceptual roughness r_k of each mip (alpha = r^2): the mirror at mip 0, then as `mapping`."""
    if levels == 1:
        return [0.0]
    if mapping == "linear":
        return layouts.level_roughness(levels)
    return [0.0] + [math.sqrt(size ** (k / (levels - 1) - 1.0)) for k in range(1, levels)]


def babylon_faces(level: np.ndarray) -> np.ndarray:
    """A cube level in iblbake's layout (faces +X -X +Y -Y +Z -Z of s x s stacked, 6s x s) ->
    (6, s, s, C) as the file holds them for Babylon: +X and -X swapped, each face turned 180
    degrees (the x mirror of its left-handed world, then rows bottom to top)."""
    s = level.shape[1]
    faces = np.asarray(level).reshape(6, s, s, -1)
    return np.ascontiguousarray(faces[[1, 0, 2, 3, 4, 5], ::-1, ::-1])


def rgbd_scale(levels, requested) -> float:
    """What the images are divided by (the light's intensity gives it back): `requested`, or
    'auto' = the smallest scale >= 1 at which no texel exceeds RGBD's 255."""
    if requested != "auto":
        return float(requested)
    peak = max(float(np.max(lv)) for lv in levels)
    return max(1.0, peak / 255.0)


def packing_error(faces: np.ndarray, packed: np.ndarray, scale: float) -> dict:
    """What RGBD did to one mip's faces (6, s, s, 3), packed as `packed` (6, s, s, 4) at `scale`,
    in luminance weighted by solid angle (a cube texel's, the same table on every face, symmetric
    under their flips): the share of the energy clipped at 255 x scale, and the relative RMSE of
    the round trip over the texels that do not clip (8-bit steps)."""
    from iblbake.io import gltf

    w = layouts.layout_solid_angles("cubemap", faces.shape[1]).reshape(faces.shape[:3])
    c = np.maximum(faces, 0.0)
    top = gltf.RGBD_MAX * scale
    y = luminance(c)
    total = max(float((y * w).sum()), 1e-300)
    clipped = float(((y - luminance(np.minimum(c, top))) * w).sum())
    keep = c.max(axis=-1) <= top
    yb = luminance(gltf.rgbd_decode(packed) * scale)
    rmse = math.sqrt(float((((yb - y) ** 2) * w)[keep].sum()) / max(float((y * y * w)[keep].sum()), 1e-300))
    return {"clipped_energy": clipped / total, "relative_rmse": rmse}


def bake(baker, image, info, root, policies: dict, *, size: int = DEFAULT_SIZE, min_size: int = DEFAULT_MIN_SIZE,
         mapping: str = "babylon", method: str = "auto", warn=None, progress=None) -> dict:
    """The light's parts, each through the bake cache: {"levels": cube levels (6s x s x 3) in
    iblbake's orientation, "roughness", "sizes", "methods", "irradiance": the 3-band SH
    document (iblbake.sh's), "entries": what was baked or reused}."""
    import time

    from iblbake.bake import mips as mipsbake
    from iblbake.bake import sh as shbake

    sizes = level_sizes(size, min_size)
    opts = {"layout": "cubemap", "base_size": size, "sizes": sizes,
            "roughness": level_roughness(size, len(sizes), mapping), "method": method,
            "samples": mipsbake.DEFAULT_SAMPLES, "lod_bias": mipsbake.DEFAULT_LOD_BIAS, "fis": True,
            "convolve_budget": None}
    entries = {}
    t0 = time.perf_counter()
    rm, rcached, chain = mipsbake.bake_radiance(baker, image, info, root, policies, warn=warn)
    entries["radiance"] = {"key": rm["key"], "cached": rcached, "seconds": round(time.perf_counter() - t0, 4)}
    t0 = time.perf_counter()
    pm, pcached = mipsbake.bake_prefiltered(baker, mipsbake.chain_loader(root, rm, chain), info, root, policies,
                                            opts, warn=warn, progress=progress)
    entries["prefiltered"] = {"key": pm["key"], "cached": pcached, "seconds": round(time.perf_counter() - t0, 4)}
    t0 = time.perf_counter()
    backend = shbake.choose_backend("auto", info.width, info.height, 3)
    coeffs, _ = shbake.project(image, 3, backend, baker.rt if backend == "opencl" else None)
    doc = shbake.document(coeffs, bands=3, window="none", info=info, options={}, device=baker.device_label,
                          timings={})
    entries["sh"] = {"backend": backend, "seconds": round(time.perf_counter() - t0, 4)}
    return {"levels": mipsbake.load_chain(root, pm), "sizes": sizes, "roughness": opts["roughness"],
            "methods": [f["method"] for f in pm["files"]], "irradiance": doc, "entries": entries}


def write(path, parts: dict, scale="1", name: str = "environment", extras: dict | None = None) -> dict:
    """Pack the parts of bake() into the glTF light at `path` (.gltf or .glb); the report per mip."""
    from iblbake.bake import sh as shbake
    from iblbake.io import gltf

    levels = parts["levels"]
    k = rgbd_scale(levels, scale)
    faces = [babylon_faces(lv) for lv in levels]
    packed = [gltf.rgbd_encode(f / k) for f in faces]
    pngs = [[gltf.png_bytes(face) for face in p] for p in packed]
    coeffs = shbake.gltf_coefficients(parts["irradiance"]) / k
    files = gltf.write(path, coeffs, pngs, parts["sizes"][0], intensity=k, name=name, extras=extras)
    mips = [{"size": s, "roughness": r, "alpha": r * r, "method": m, **packing_error(f, p, k)}
            for s, r, m, f, p in zip(parts["sizes"], parts["roughness"], parts["methods"], faces, packed)]
    return {"files": [str(f) for f in files], "intensity": k, "mips": mips,
            "irradiance_coefficients": coeffs.tolist()}
