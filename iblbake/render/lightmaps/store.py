"""A lightmap cached by content in the bake store (bake/cache.py), as the probes are (render/units.py
Probes): keyed by everything its rays see (units.light_transport: the geometry and materials by their
files' content, the lights, the panorama by content and its frame), the lightmap settings, the
camera's position (it picks each two-sided surface's lit side) and the code (this package and its
kernel). The entry holds the atlases (the irradiance, the basis's coefficients, the valid texels,
the basis's second set fitted for the specular lobe where the frame reads one: its key says so)
and the layout as .npy files (float32; the reading's float64 comes back from them), the basis with
its options and the bake's report in its manifest; load() checks each (a corrupt entry is baked
again: bake/cache.py get_checked)."""

from __future__ import annotations

from pathlib import Path
from tokenize import TokenError

import numpy as np

from iblbake.bake import records as rec
from iblbake.errors import IblbakeError

VERSION = 2
LAYOUT = {"corners": (3, 3), "normals": (3, 3), "objects": (), "uv": (3, 2), "spheres": (4,)}  # per triangle
INT = {"objects": np.int32, "valid": bool}                          # the rest float32


def code_hash() -> str:
    """This package's source, the bases' registry's (core/bases: every fit a texel may take) and
    the kernel's."""
    import importlib
    import pkgutil

    from iblbake.core import bases as core_bases
    from iblbake.device.programs import source_hash
    from iblbake.render import lightmaps
    from iblbake.render.bakes import _code_hash
    mods = [importlib.import_module(f"{pkg.__name__}.{m.name}") for pkg in (lightmaps, core_bases)
            for m in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name)]
    return _code_hash(tuple(mods), source_hash("paths/lightmap_trace.cl"))


def key(job, settings: dict) -> str:
    """The entry's key: the settings less the options of bases other than its own (an SG option
    does not bake an L1 SH lightmap again)."""
    from iblbake.bake import cache
    from iblbake.core.bases.probes import PROBE_BASES
    from iblbake.render.lightmaps import bases
    from iblbake.render.units import light_transport
    from iblbake.scene import pack
    camera = pack.camera_vectors(job.scene.data["camera"])[0]
    others = {k for b in PROBE_BASES.values() for k in b.option_specs} - set(
        bases.options(settings.get("basis", "sh_l1"), settings) if settings.get("basis") in bases.NAMES else ())
    kept = {k: v for k, v in settings.items() if k not in others}
    return "lightmap-" + cache.content_key({"kind": "lightmap", "v": VERSION, **light_transport(job), "settings": kept,
                                            "camera": [float(x) for x in camera], "code": code_hash()})


def save(lm: dict, folder: Path) -> list:
    """The lightmap's arrays into the store's build folder (bake/cache.py renames it into place whole,
    its manifest last): the irradiance, the basis's coefficients (basis.npy), the valid texels and
    the layout; the names written."""
    names = []
    lay = lm["layout"]
    coeffs = np.reshape(lm[lm["basis"]], (lay.height, lay.width, -1, 3))    # `irradiance`: one row a texel
    arrays = {"irradiance": lm["irradiance"], "basis": coeffs, "valid": lm["valid"],
              **{n: getattr(lay, n) for n in LAYOUT}, **({"specular": lm["specular"]} if "specular" in lm else {})}
    for name, arr in arrays.items():
        np.save(Path(folder) / f"{name}.npy", np.asarray(arr, INT.get(name, np.float32)))
        names.append(f"{name}.npy")
    return names


def _read(folder: Path, name: str, shape: tuple) -> np.ndarray:
    """One array of the entry, of the dtype and shape its name asks (None in shape: any length)."""
    try:
        a = np.load(folder / f"{name}.npy", mmap_mode="r", allow_pickle=False)     # no header's size allocated
    except (OSError, EOFError, ValueError, SyntaxError, TokenError, TypeError, KeyError, MemoryError) as e:
        raise ValueError(f"{name}.npy: {e}") from None       # numpy's header parser: a flipped byte gives any
    if a.dtype != np.dtype(INT.get(name, np.float32)) or len(a.shape) != len(shape) or \
            any(want is not None and got != want for got, want in zip(a.shape, shape)):
        raise ValueError(f"{name}.npy holds {a.dtype} {a.shape}, not {np.dtype(INT.get(name, np.float32))} {shape}")
    a = np.array(a)
    if a.dtype.kind == "f" and not np.isfinite(a).all():
        raise ValueError(f"{name}.npy holds values that are not finite")
    return a


def _basis(man: dict, key: str = "options") -> tuple:
    """(basis, options) of a manifest, each a choice of bases.py's (`key`: the options of the basis's
    set, or of its second set for the specular lobe)."""
    from iblbake.core.bases.probes import PROBE_BASES
    from iblbake.render.lightmaps import bases
    name, opts = man["basis"], man[key]
    specs = PROBE_BASES[name].option_specs if name in PROBE_BASES else {}
    if name not in bases.NAMES or not isinstance(opts, dict) or set(opts) != set(specs) or \
            any(opts[k] not in specs[k][0] or isinstance(opts[k], bool) for k in specs):
        raise ValueError(f"basis {name!r} with options {opts!r} is not a lightmap basis")
    return name, opts


# the bake report's keys that a frame, `lightmap` and the export read (render/units.py, cli/lightmap.py,
# export.py), each with its check (bake/records.py)
REPORT = {"width": rec.count, "height": rec.count, "texels": rec.count, "samples": rec.count,
          "rays_traced": rec.count, "texels_per_unit": lambda v: rec.number(v) and v > 0,
          "seconds": lambda v: rec.number(v) and v >= 0, "bytes": rec.counts_by(),
          "uv_sources": lambda v: isinstance(v, dict) and all(k.isdigit() and isinstance(s, str) for k, s in v.items())}


def load(folder: Path, man: dict) -> dict:
    """The lightmap of an entry, every array's dtype, shape (against the manifest's atlas size and
    basis), finiteness and range checked: an IblbakeError naming the folder where one fails."""
    from iblbake.core.bases.probes import PROBE_BASES
    from iblbake.render.lightmaps import bases
    from iblbake.render.lightmaps.uv import Layout
    folder = Path(folder)
    try:
        w, h = man["width"], man["height"]
        if not all(type(v) is int and 0 < v <= 1 << 16 for v in (w, h)):
            raise ValueError(f"an atlas of {w!r} x {h!r} texels")
        name, opts = _basis(man)
        sources = {int(k): str(v) for k, v in man["uv_sources"].items()}
        report = man["report"]
        wrong = rec.wrong(report, REPORT, tuple(REPORT))
        if wrong or (report["width"], report["height"]) != (w, h):
            raise ValueError(wrong or "its report's atlas size is not the manifest's")
        a = {"irradiance": _read(folder, "irradiance", (h, w, 3)), "valid": _read(folder, "valid", (h, w)),
             "basis": _read(folder, "basis", (h, w, bases.floats(name, opts), 3))}
        a["objects"] = _read(folder, "objects", (None,))
        a.update({n: _read(folder, n, (len(a["objects"]), *tail)) for n, tail in LAYOUT.items() if n != "objects"})
        bad = {"irradiance": "negative irradiance" if (a["irradiance"] < 0).any() else None,
               "objects": "negative object indices" if (a["objects"] < 0).any() else None,
               "uv": "UVs outside the atlas" if (a["uv"] < 0).any() or (a["uv"][..., 0] > w).any()
               or (a["uv"][..., 1] > h).any() else None,
               "basis": PROBE_BASES[name].check(a["basis"].reshape(h * w, -1, 3), opts)
               if name in PROBE_BASES else None}
        for n, why in bad.items():
            if why:
                raise ValueError(f"{n}.npy: {why}")
        spec = _specular(folder, man, name, h, w)
    except (OSError, EOFError, KeyError, TypeError, ValueError, AttributeError) as e:
        raise IblbakeError(f"{folder}: not a lightmap entry ({' '.join(str(e).split())})") from None
    lay = Layout(w, h, *(a[n].astype(np.float64) for n in ("corners", "normals")), a["objects"],
                 a["uv"].astype(np.float64), a["spheres"].astype(np.float64), sources)
    coeffs = a["basis"].astype(np.float64)
    return {"layout": lay, "irradiance": a["irradiance"].astype(np.float64),
            name: coeffs if name != "irradiance" else a["irradiance"].astype(np.float64), "basis": name,
            "options": opts, "valid": a["valid"], "report": report, **spec}


def _specular(folder: Path, man: dict, name: str, h: int, w: int) -> dict:
    """The entry's second set for the specular lobe (specular.npy, its options in the manifest's
    specular_options; bake.bake), checked as the basis's, where it has one: {} otherwise."""
    from iblbake.core.bases.probes import PROBE_BASES
    from iblbake.render.lightmaps import bases
    if man.get("specular_options") is None:
        return {}
    if name not in bases.LOBED:
        raise ValueError(f"a specular set for basis {name!r}, which carries no lobe")
    _name, opts = _basis(man, "specular_options")
    sp = _read(folder, "specular", (h, w, bases.floats(name, opts), 3))
    why = PROBE_BASES[name].check(sp.reshape(h * w, -1, 3), opts)
    if why:
        raise ValueError(f"specular.npy: {why}")
    return {"specular": sp.astype(np.float64), "specular_options": opts}


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
                "height": rep["height"], "basis": lm["basis"], "options": lm["options"],
                **({"specular_options": lm["specular_options"]} if "specular" in lm else {}),
                "uv_sources": rep["uv_sources"], "report": rep}

    lm, manifest, was = cache.get_checked(root, k, build, lambda m: load(root / m["key"], m), warn=job.warn)
    return lm, was
