"""A baked volume as a value (render/probes): the frozen record bake() and load() return (Volume,
made by volume_dict), which of a scene's `probes` keys the bake depends on (bake_settings) and
which are read when shading (sampled), and the options of a probes' directional basis."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from iblbake.core import bases
from iblbake.core.bases.probes import PROBE_BASES
from iblbake.render.probes.grid import Grid


def basis_of(volume):
    """A volume's probe basis (core/bases/probes.py PROBE_BASES): what its representation names."""
    return PROBE_BASES[volume["representation"]]


def basis_options(settings: dict) -> dict:
    """The options of the probes' basis: the probes section's keys of the same names as the
    basis's effects keys (probes.sg_lobes, probes.sg_fit), so a probe basis is set apart from the
    distant one."""
    return PROBE_BASES[settings["irradiance"]].options(settings)


SAMPLING_KEYS = ("visibility", "normal_bias", "view_bias")   # read when shading, not baked


def bake_settings(settings: dict) -> dict:
    """What of a scene's `probes` section the bake depends on: not the sampling keys, nor the
    options of the bases it does not store (probes.sg_lobes beside irradiance: ambient_dice would
    bake the same volume again under another key, and write a setting it did not read)."""
    others = {k for n, m in bases.BASES.items() if n != settings["irradiance"] for k in m.OPTIONS}
    own = set(PROBE_BASES[settings["irradiance"]].option_specs)
    return {k: v for k, v in settings.items() if k not in SAMPLING_KEYS and (k not in others or k in own)}


@dataclasses.dataclass(frozen=True, eq=False)
class Volume(Mapping):
    """A baked volume: its grid, bake settings, arrays (irradiance: the basis's file, the octahedral
    atlas or (probes, floats, 3) coefficients; distance: the moments' atlas; data: (probes, 4)
    offset in world units and state) and report; sampled, a scene's sampling settings too (biases
    in world units). Its basis is the registry's entry (core/bases/probes.py); the grid, texel
    counts and representation are read from grid and settings. Read as a mapping too, by the names
    the volume record's fields have (scene/layout.py PROBE_VOLUME), as the twin and the packer do."""
    grid: Grid
    settings: dict
    irradiance: object
    distance: object
    data: object
    report: dict
    visibility: bool | None = None       # sampled(): the scene's sampling settings
    normal_bias: float | None = None
    view_bias: float | None = None

    @property
    def basis(self):
        return PROBE_BASES[self.representation]

    @property
    def representation(self) -> str:
        return self.settings["irradiance"]

    counts = property(lambda self: self.grid.counts)
    origin = property(lambda self: self.grid.origin)
    spacing = property(lambda self: self.grid.spacing)
    irradiance_texels = property(lambda self: self.settings["irradiance_texels"])
    distance_texels = property(lambda self: self.settings["distance_texels"])
    classification = property(lambda self: self.settings["classification"])

    KEYS = ("grid", "counts", "origin", "spacing", "representation", "irradiance_texels", "distance_texels",
            "classification", "settings", "irradiance", "distance", "data", "report")
    SAMPLED = ("visibility", "normal_bias", "view_bias")

    def __iter__(self):
        return iter(self.KEYS + (self.SAMPLED if self.visibility is not None else ()))

    def __len__(self):
        return len(tuple(iter(self)))

    def __getitem__(self, key):
        if key not in tuple(iter(self)):
            raise KeyError(key)
        return getattr(self, key)


def volume_dict(grid: Grid, settings: dict, irr, dist, data, report: dict) -> Volume:
    """The Volume of a bake or a load: its grid, a probes section (its bake settings kept), arrays
    and report."""
    return Volume(grid, bake_settings(settings), irr, dist, data, report)


def sampled(volume, settings: dict):
    """The volume with a scene's sampling settings (visibility, biases in world units): what
    twin.irradiance and the shade pass read (a volume made by hand as a dict stays one)."""
    u = volume["grid"].unit
    given = {"visibility": settings["visibility"], "normal_bias": settings["normal_bias"] * u,
             "view_bias": settings["view_bias"] * u}
    return dataclasses.replace(volume, **given) if isinstance(volume, Volume) else {**volume, **given}

