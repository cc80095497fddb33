"""A lightmap cached by content in the bake store (bake/cache.py), as the probes are (render/units.py
Probes): keyed by everything its rays see (units.light_transport: the geometry and materials by their
files' content, the lights, the panorama by content and its frame), the lightmap settings, the
camera's position (it picks each two-sided surface's lit side) and the code (this package and its
kernel). The entry holds the atlases and the layout as .npy files (float32; the reading's float64
comes back from them) and the bake's report in its manifest."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from iblbake.errors import IblbakeError

VERSION = 1
ARRAYS = {"irradiance": 3, "sh_l1": 4, "valid": 2}                    # atlas arrays: their ndim
LAYOUT = ("corners", "normals", "objects", "uv", "spheres")


def code_hash() -> str:
    import importlib
    import pkgutil

    from iblbake.device.programs import source_hash
    from iblbake.render import lightmaps
    from iblbake.render.bakes import _code_hash
    mods = [importlib.import_module(f"{lightmaps.__name__}.{m.name}") for m in sorted(
        pkgutil.iter_modules(lightmaps.__path__), key=lambda m: m.name)]
    return _code_hash(tuple(mods), source_hash("paths/lightmap_trace.cl"))


def key(job, settings: dict) -> str:
    from iblbake.bake import cache
    from iblbake.render.units import light_transport
    from iblbake.scene import pack
    camera = pack.camera_vectors(job.scene.data["camera"])[0]
    return "lightmap-" + cache.content_key({"kind": "lightmap", "v": VERSION, **light_transport(job), "settings": settings,
                                            "camera": [float(x) for x in camera], "code": code_hash()})


def save(lm: dict, folder: Path) -> list:
    """The lightmap's arrays into the store's build folder (bake/cache.py renames it into place whole,
    its manifest last); the names written."""
    names = []
    lay = lm["layout"]
    for name, arr in [*((n, lm[n]) for n in ARRAYS), *((n, getattr(lay, n)) for n in LAYOUT)]:
        np.save(Path(folder) / f"{name}.npy",
                np.asarray(arr, bool if name == "valid" else np.int32 if name == "objects" else np.float32))
        names.append(f"{name}.npy")
    return names


def load(folder: Path, man: dict) -> dict:
    """The lightmap of an entry, its shapes checked against the manifest's atlas size."""
    from iblbake.render.lightmaps.uv import Layout
    folder = Path(folder)
    try:
        w, h = man["width"], man["height"]
        a = {n: np.load(folder / f"{n}.npy", allow_pickle=False) for n in (*ARRAYS, *LAYOUT)}
        ok = all(a[n].shape[:2] == (h, w) and a[n].ndim == d for n, d in ARRAYS.items())
        t = len(a["objects"])
        ok = ok and a["corners"].shape == a["normals"].shape == (t, 3, 3) and a["uv"].shape == (t, 3, 2)
        if not ok or not all(np.isfinite(a[n]).all() for n in ("irradiance", "sh_l1", "uv")):
            raise ValueError("arrays of the wrong shape, or not finite")
    except (OSError, KeyError, TypeError, ValueError) as e:
        raise IblbakeError(f"{folder}: not a lightmap entry ({e})") from None
    lay = Layout(w, h, *(a[n].astype(np.float64) if n != "objects" else a[n] for n in LAYOUT[:2]),
                 a["objects"], a["uv"].astype(np.float64), a["spheres"].astype(np.float64),
                 {int(k): v for k, v in man["uv_sources"].items()})
    return {"layout": lay, "irradiance": a["irradiance"].astype(np.float64), "sh_l1": a["sh_l1"].astype(np.float64),
            "valid": a["valid"], "report": man["report"]}


def baked(job, settings: dict | None = None, progress=None) -> tuple:
    """(the lightmap as load() gives it, cached): the job's scene's lightmap from the store, baked
    there where it is not (bake.bake)."""
    from iblbake.bake import cache
    from iblbake.render.lightmaps.bake import bake
    settings = settings or job.scene.data["lightmap"]
    root, k = job.bakes.root, key(job, settings)

    def build(tmp: Path):
        lm = bake(job, settings, progress)
        rep = lm["report"]
        return {"kind": "lightmap", "files": [{"name": n} for n in save(lm, tmp)], "width": rep["width"],
                "height": rep["height"], "uv_sources": rep["uv_sources"], "report": rep}

    lm, manifest, was = cache.get_checked(root, k, build, lambda m: load(root / m["key"], m), warn=job.warn)
    return lm, was
