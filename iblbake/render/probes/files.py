"""A volume's files (render/probes): probes.json (the manifest: grid, representation, every
convention the files are read with), the atlases written as EXR, and both read back with every
value checked (a damaged file is one line naming it)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from iblbake.core import bases
from iblbake.errors import IblbakeError
from iblbake.render.probes.grid import Grid
from iblbake.render.probes.relocation import ACTIVE, INACTIVE, MAX_OFFSET
from iblbake.render.probes.volume import basis_options, volume_dict

FORMAT = "iblbake-probes"
VERSION = 1
# a directional basis (core/bases PROBES) stores each probe's radiance coefficients in its layout
FILES = {"octahedral": "irradiance.exr", "sh": "irradiance_sh.exr", **{n: f"basis_{n}.exr" for n in bases.PROBES}}


def manifest(volume: dict) -> dict:
    """The manifest of a sampled volume's files: the grid, the representation, how to sample it
    and every convention the files are read with, each probe's state."""
    g, s = volume["grid"], volume["settings"]
    states = volume["data"][:, 3].astype(int)
    return {
        "format": FORMAT, "version": VERSION,
        "grid": {"origin": list(g.origin), "spacing": list(g.spacing), "counts": list(g.counts),
                 "probe_position": "origin + (gx, gy, gz) * spacing + offset"},
        "representation": volume["representation"],
        "files": {"irradiance": FILES[volume["representation"]], "distance": "distance.exr",
                  "probe_data": "probe_data.exr",
                  # the table probes.glsl's ambient-dice specular reads (kernels: basis_table)
                  **({"specular_table": "ambient_dice_specular.exr"} if volume["representation"] == "ambient_dice"
                     else {})},
        "irradiance_texels": volume["irradiance_texels"], "distance_texels": volume["distance_texels"],
        "normal_bias": volume["normal_bias"], "view_bias": volume["view_bias"],
        "visibility": volume["visibility"], "classification": volume["classification"],
        "settings": {k: v for k, v in s.items()},
        "states": {"active": int((states == ACTIVE).sum()), "inactive": int((states == INACTIVE).sum())},
        "conventions": {
            "units": ("irradiance E (W m^-2 for radiance in W m^-2 sr^-1), linear, float32; diffuse = albedo / pi * E"
                      if volume["representation"] in ("octahedral", "sh") else
                      "radiance coefficients of the basis (W m^-2 sr^-1 in radiance units), linear, float32; its "
                      "irradiance function gives E, diffuse = albedo / pi * E"),
            "probe_index": "gy * nx * nz + gz * nx + gx (RTXGI, right-handed, y up)",
            "atlas": "probe tile (n + 2) texels square, 1-texel octahedral border; tile column gx + gy * nx, "
                     "row gz; the file's first row at the top (v = 0)",
            "octahedral": "RTXGI DDGIGetOctahedralCoordinates on world directions: +z at the tile centre",
            "sh": "irradiance_sh.exr: row = probe index, column k = l (l + 1) + m, real orthonormal SH, z polar "
                  "axis, no Condon-Shortley phase, world frame",
            "distance": "R: mean of min(|t|, 1.5 |spacing|), G: mean of its square, weights cos^distance_exponent",
            "probe_data": "RGBA, texel (index % (nx * ny), index / (nx * ny)): offset in units of spacing, "
                          "A = state (0 active, 1 inactive), as RTXGI's probe data texture",
        },
        "report": volume["report"],
        **({"basis": basis_manifest(volume)} if volume["representation"] in bases.PROBES else {}),
    }


def basis_manifest(volume: dict) -> dict:
    """What a basis's file holds: the basis, its options and its layout (the basis module's)."""
    rep = volume["representation"]
    m = bases.BASES[rep]
    return {"name": rep, "title": m.TITLE, "options": basis_options(volume["settings"]), "floats": m.floats(
            basis_options(volume["settings"])),
            "layout": f"{FILES[rep]}: row = probe index, column k = the basis's coefficient k (RGB radiance "
                      f"coefficients, world frame; back-face rays black); the basis's own layout, its rows being "
                      f"the columns here: " + " ".join(m.__doc__.split("Layout:")[1].split()),
            "irradiance": "docs/conventions.md 'Directional bases'; probes.glsl's probeOwnIrradiance evaluates it"}


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
    name = FILES[volume["representation"]]
    images.write_exr(folder / name, np.asarray(irr, np.float32))
    names.append(name)
    images.write_exr(folder / "distance.exr", np.asarray(volume["distance"], np.float32), channels=("R", "G"))
    images.write_exr(folder / "probe_data.exr", data_texture(volume["data"], volume["grid"]),
                     channels=("R", "G", "B", "A"))
    return names + ["distance.exr", "probe_data.exr"]


def _bad(path, what: str):
    return IblbakeError(f"{path}: {what}; bake the probes again (iblbake probes SCENE -o DIR/)")


def load(folder: Path, man: dict, manifest_name: str = "probes.json") -> dict:
    """A volume from its folder and manifest (manifest_name: how the folder calls it), every
    value checked: the manifest's types and ranges, the images' shapes against it, finite and
    non-negative values, states 0 or 1, offsets within 45% of a cell."""
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
        if rep in bases.PROBES:
            for k, (choices, _default, _doc) in bases.BASES[rep].OPTIONS.items():
                if settings.get(k) not in choices:
                    raise ValueError(f"settings.{k}")
    except (KeyError, TypeError, ValueError) as e:
        raise _bad(where, f"manifest lacks or mangles {e}") from None
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

    if rep == "sh":
        irr = read(FILES[rep], (grid.count, 9, 3))
    elif rep in bases.PROBES:
        m = bases.BASES[rep]
        opts = {k: settings[k] for k in m.OPTIONS}
        irr = read(FILES[rep], (grid.count, m.floats(opts), 3))
        try:                          # every probe's coefficients as one basis's columns
            m.validate(irr.transpose(1, 0, 2).reshape(irr.shape[1], -1), opts)
        except ValueError as e:
            raise _bad(folder / FILES[rep], str(e)) from None
    else:
        irr = read(FILES[rep], ((n + 2) * nz, (n + 2) * nx * ny, 3))
        if (irr < 0).any():
            raise _bad(folder / FILES[rep], "holds negative irradiance")
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
    return volume_dict(grid, settings, irr, dist, data, man.get("report", {}))


def read_manifest(path: Path) -> dict:
    try:
        man = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise _bad(path, f"cannot be read as JSON ({e})") from None
    if not isinstance(man, dict):
        raise _bad(path, "is not a JSON object")
    return man

