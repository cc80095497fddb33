"""A volume's files (render/probes): probes.json (the manifest: grid, representation, every
convention the files are read with), the atlases written as EXR, and both read back with every
value checked (a damaged file is one line naming it)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from iblbake.bake import records as rec
from iblbake.core.bases.probes import PROBE_BASES
from iblbake.errors import IblbakeError
from iblbake.render.probes.grid import Grid
from iblbake.render.probes.relocation import ACTIVE, INACTIVE, MAX_OFFSET
from iblbake.render.probes.volume import basis_of, volume_dict

FORMAT = "iblbake-probes"
VERSION = 1
FILES = {n: b.file for n, b in PROBE_BASES.items()}      # each probe basis's file (core/bases/probes.py)


LIGHT_FIELDS = (
    "Each as the scene's lights.N: directional.direction "
    "the direction the light travels (world frame, environment.rotation_y applied), color linear RGB of luminance "
    "1, illuminance the E a surface facing it receives (environment.intensity applied; the probes' units), "
    "angular_diameter in degrees (the disk of solid_angle_sr it came from: the soft shadows' penumbra); "
    "irradiance = color x illuminance per channel; shadows hard, soft (over the disk) or none")
LIGHTS_CONVENTION = (
    "the lights whose direct light an engine draws per pixel, as the frame does: the probes' paths add each at "
    "every vertex they meet (its bounce is in the probes), never along their own first ray, so neither the scene's "
    "lights (source lights.N) nor those extracted from the panorama (environment.sun: extract; the panorama the "
    "probes saw lacks them) are in the probes' direct light. " + LIGHT_FIELDS)


def light_entries(scene, suns) -> list:
    """probes.json's `lights` (LIGHTS_CONVENTION): the frame's lights (device_scene.scene_lights:
    the scene's, then those extracted from the panorama, `suns`, Bakes.sun), each with its source,
    and a directional one with its irradiance per channel and its disk's solid angle."""
    from iblbake.render.device_scene import scene_lights

    own = len(scene.data["lights"])
    out = []
    for k, lt in enumerate(scene_lights(scene, suns)):
        source = f"lights.{k}" if k < own else f"environment.sun: extract ({k - own + 1} of {len(suns)}, brightest first)"
        entry = {"source": source, **lt}
        d = lt.get("directional")
        if d:
            entry["irradiance"] = [c * d["illuminance"] for c in d["color"]]
            entry["solid_angle_sr"] = 2 * math.pi * (1 - math.cos(math.radians(d["angular_diameter"]) / 2))
        out.append(entry)
    return out


SKY_CONVENTION = (
    "the light where no probe is near and outside the volume (the renderer's fallback, effects.sh_bands and "
    "sh_window): irradiance E_k of the panorama the probes saw, less the lights extracted from it (an engine draws "
    "those per pixel from `lights`: the whole panorama's SH would count them twice), world frame "
    "(environment.rotation_y applied), times environment.intensity; real orthonormal SH, z polar axis, no "
    "Condon-Shortley phase, k = l (l + 1) + m, as `iblbake sh`'s irradiance; E(n) = sum_k E_k Y_k(n), clamped at 0")


ENVIRONMENT_CONVENTION = (
    "the panorama the bake lit the scene with where lights were extracted from it (environment.sun: extract): the "
    "scene's panorama less the extracted `lights`, each disk filled from the ring about it, linear RGB as iblbake read "
    "it, equirect in iblbake's mapping (docs/conventions.md 'Equirectangular panoramas'), neither environment.rotation_y nor "
    "intensity applied (as the scene's own file). An engine prefilters it for the specular (iblbake mips) and "
    "projects it for a sky SH: the scene's panorama there counts the listed lights twice. The background shows "
    "the panorama whole")


ENVIRONMENT_FILE = "environment.exr"      # `iblbake probes`' residual panorama (lightmaps': export.ENVIRONMENT)


def environment_entry(env: dict, file: str) -> dict:
    """A manifest's `environment` (ENVIRONMENT_CONVENTION): the residual panorama's file and what
    turns and scales it as the frame does."""
    return {"file": file, "rotation_y": float(env["rotation_y"]), "intensity": float(env["intensity"])}


def write_environment(image, path, batch) -> None:
    """The residual panorama (Bakes.environment's image with `sun: extract`) as a half-float RGB
    EXR through `batch` (atomic.Batch)."""
    from iblbake.io import images
    images.write_exr(path, np.asarray(image, np.float32)[..., :3], half=True, batch=batch)


def sky_entry(image, env: dict, bands: int, window: str) -> dict:
    """probes.json's `sky` (SKY_CONVENTION): the SH irradiance of `image`, the panorama the probes
    were baked with (Bakes.environment: the residual where lights were extracted), in the world
    frame and the probes' units, as the renderer's SH fallback reads it (float64, numpy's exact
    texel integrals: bake/sh.py)."""
    from iblbake.core import sh
    radiance = sh.project(np.asarray(image, np.float64)[..., :3], bands, env["rotation_y"])
    e = radiance * (sh.window(bands, window) * sh.ahat(bands))[:, None] * env["intensity"]
    return {"bands": bands, "window": window, "lights_extracted": env.get("sun") == "extract",
            "irradiance": [[float(v) for v in row] for row in e]}


def manifest(volume: dict, lights: list = (), sky: dict | None = None, environment: dict | None = None) -> dict:
    """The manifest of a sampled volume's files: the grid, the representation, how to sample it
    and every convention the files are read with, each probe's state; `lights` (light_entries)
    the lights an engine adds, `sky` (sky_entry) the light where no probe is, `environment`
    (environment_entry) the residual panorama where lights were extracted."""
    g, s, basis = volume["grid"], volume["settings"], basis_of(volume)
    states = volume["data"][:, 3].astype(int)
    return {
        "format": FORMAT, "version": VERSION,
        "grid": {"origin": list(g.origin), "spacing": list(g.spacing), "counts": list(g.counts),
                 "probe_position": "origin + (gx, gy, gz) * spacing + offset"},
        "representation": basis.name,
        "files": {"irradiance": basis.file, "distance": "distance.exr", "probe_data": "probe_data.exr",
                  # the table probes.glsl's specular reads (kernels: basis_table)
                  **({"specular_table": basis.specular_table} if basis.specular_table else {})},
        "irradiance_texels": volume["irradiance_texels"], "distance_texels": volume["distance_texels"],
        "normal_bias": volume["normal_bias"], "view_bias": volume["view_bias"],
        "visibility": volume["visibility"], "classification": volume["classification"],
        "settings": {k: v for k, v in s.items()},
        "states": {"active": int((states == ACTIVE).sum()), "inactive": int((states == INACTIVE).sum())},
        "conventions": {
            "units": basis.units,
            "probe_index": "gy * nx * nz + gz * nx + gx (RTXGI, right-handed, y up)",
            "atlas": "probe tile (n + 2) texels square, 1-texel octahedral border; tile column gx + gy * nx, "
                     "row gz; the file's first row at the top (v = 0)",
            "octahedral": "RTXGI DDGIGetOctahedralCoordinates on world directions: +z at the tile centre",
            "sh": "irradiance_sh.exr: row = probe index, column k = l (l + 1) + m, real orthonormal SH, z polar "
                  "axis, no Condon-Shortley phase, world frame",
            "distance": "R: mean of min(|t|, 1.5 |spacing|), G: mean of its square, weights cos^distance_exponent",
            "probe_data": "RGBA, texel (index % (nx * ny), index / (nx * ny)): offset in units of spacing, "
                          "A = state (0 active, 1 inactive), as RTXGI's probe data texture",
            "lights": LIGHTS_CONVENTION,
            **({"sky": SKY_CONVENTION} if sky else {}),
            **({"environment": ENVIRONMENT_CONVENTION} if environment else {}),
        },
        "report": volume["report"],
        "lights": list(lights),
        **({"sky": sky} if sky else {}),
        **({"environment": environment} if environment else {}),
        **basis.manifest(volume),
    }


def data_texture(data: np.ndarray, grid: Grid) -> np.ndarray:
    nx, ny, nz = grid.counts
    out = np.zeros((nz, nx * ny, 4), np.float32)
    i = np.arange(grid.count)
    out[i // (nx * ny), i % (nx * ny), :3] = data[:, :3] / np.asarray(grid.spacing)
    out[i // (nx * ny), i % (nx * ny), 3] = data[:, 3]
    return out


def save(volume: dict, folder: Path) -> list:
    """The volume's images into folder (atomically, each); the names written."""
    from iblbake.io import images

    folder = Path(folder)
    names = []
    irr = volume["irradiance"]
    name = basis_of(volume).file
    images.write_exr(folder / name, np.asarray(irr, np.float32))
    names.append(name)
    images.write_exr(folder / "distance.exr", np.asarray(volume["distance"], np.float32), channels=("R", "G"))
    images.write_exr(folder / "probe_data.exr", data_texture(volume["data"], volume["grid"]),
                     channels=("R", "G", "B", "A"))
    return names + ["distance.exr", "probe_data.exr"]


# the bake report's keys that a frame, `probes` and the warnings read (render/units.py, cli/probes.py,
# placement_warnings, warnings), each with its check (bake/records.py)
REPORT = {"probes": rec.count, "rays_traced": rec.count, "inactive": rec.count, "relocated": rec.count,
          "bytes": rec.count, "seconds": lambda v: rec.number(v) and v >= 0,
          "inside_geometry": rec.count, "outside_camera_room": rec.count, "on_surface": rec.count,
          "noisy_short_of_memory": rec.count, "rays_per_probe": rec.count,
          "interior_step": lambda v: v is None or rec.number(v) and v > 0, "off_by": rec.counts_by(),
          "inside_objects": rec.counts_by(str.isdigit), "more_rays": rec.counts_by(str.isdigit),
          "capped": rec.fields({"step": rec.number, "probes": rec.count}, ("step", "probes")),
          "camera_cramped": rec.fields({"free": rec.number, "cell": rec.number, "object": rec.count,
                                        "automatic": lambda v: isinstance(v, bool), "extent": rec.number,
                                        "others": rec.number}, ("free", "cell")),
          "box_outside_bounds": rec.fields({"box": rec.box, "bounds": rec.box}, ("box", "bounds"))}
REPORT_REQUIRED = ("probes", "rays_traced", "inactive", "relocated", "bytes", "seconds")


def _bad(path, what: str):
    return IblbakeError(f"{path}: {what}; bake the probes again (iblbake probes SCENE -o DIR/)")


def load(folder: Path, man: dict, manifest_name: str = "probes.json") -> dict:
    """A volume from its folder and manifest (manifest_name: how the folder calls it), every
    value checked: the manifest's types and ranges, the images' shapes against it, finite and
    non-negative values, states 0 or 1, offsets within 45% of a cell, the bake report's keys read
    back (REPORT)."""
    from iblbake.io import images

    folder = Path(folder)
    where = folder / manifest_name
    if not isinstance(man, dict) or man.get("format") != FORMAT or man.get("version") != VERSION:
        raise _bad(where, f"not an {FORMAT} v{VERSION} manifest")
    try:
        g = man["grid"]
        vecs = [g["origin"], g["spacing"], g["counts"]]
        if not all(isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                                for x in v) for v in vecs):
            raise ValueError("grid: origin, spacing and counts must be 3 numbers each")
        grid = Grid(tuple(float(x) for x in vecs[0]), tuple(float(x) for x in vecs[1]), tuple(int(x) for x in vecs[2]))
        rep, n, nd = man["representation"], man["irradiance_texels"], man["distance_texels"]
        settings = man["settings"]
        if not (isinstance(rep, str) and rep in FILES and all(isinstance(x, int) and not isinstance(x, bool)
                                                               for x in (n, nd))
                and isinstance(settings, dict) and isinstance(settings.get("classification"), bool)):
            raise ValueError("representation, texels or settings")
        for k, (choices, _default, _doc) in PROBE_BASES[rep].option_specs.items():
            if settings.get(k) not in choices:
                raise ValueError(f"settings.{k}")
    except (KeyError, TypeError, ValueError) as e:
        raise _bad(where, f"manifest lacks or mangles {e}") from None
    wrong = rec.wrong(man.get("report"), REPORT, REPORT_REQUIRED)
    if wrong:
        raise _bad(where, wrong)
    if min(grid.counts) < 1 or grid.count > 1 << 20 or min(grid.spacing) <= 0 \
            or not all(math.isfinite(x) for x in grid.origin + grid.spacing) or not (2 <= n <= 64 and 2 <= nd <= 64):
        raise _bad(where, "its grid or texel counts are out of range")
    nx, ny, nz = grid.counts

    def read(name, shape):
        path = folder / name
        try:
            a = images.read_exr(path).astype(np.float64)
        except (OSError, IblbakeError, RuntimeError, ValueError) as e:
            raise _bad(path, f"cannot be read ({e})") from None
        if a.shape[:2] != shape[:2] or a.shape[2] < shape[2]:
            raise _bad(path, f"holds {a.shape[1]}x{a.shape[0]}x{a.shape[2]}, the manifest says "
                             f"{shape[1]}x{shape[0]}x{shape[2]}")
        a = a[..., :shape[2]]
        if not np.isfinite(a).all():
            raise _bad(path, "holds a value that is not finite")
        return a

    basis = PROBE_BASES[rep]
    irr = read(basis.file, basis.shape(grid, {**settings, "irradiance_texels": n}))
    wrong = basis.check(irr, basis.options(settings))
    if wrong:
        raise _bad(folder / basis.file, wrong)
    dist = read("distance.exr", ((nd + 2) * nz, (nd + 2) * nx * ny, 2))
    if (dist < 0).any():
        raise _bad(folder / "distance.exr", "holds a negative distance moment")
    tex = read("probe_data.exr", (nz, nx * ny, 4))
    i = np.arange(grid.count)
    rows = tex[i // (nx * ny), i % (nx * ny)]
    if not np.isin(rows[:, 3], (ACTIVE, INACTIVE)).all() or (np.abs(rows[:, :3]) >= MAX_OFFSET + 1e-6).any():
        raise _bad(folder / "probe_data.exr", "holds a probe state other than 0 or 1, or an offset beyond 45% of a cell")
    data = np.concatenate([rows[:, :3] * np.asarray(grid.spacing), rows[:, 3:]], 1)
    settings.update(irradiance=rep, irradiance_texels=n, distance_texels=nd)
    return volume_dict(grid, settings, irr, dist, data, man["report"])


def read_manifest(path: Path) -> dict:
    try:
        man = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise _bad(path, f"cannot be read as JSON ({e})") from None
    if not isinstance(man, dict):
        raise _bad(path, "is not a JSON object")
    return man

