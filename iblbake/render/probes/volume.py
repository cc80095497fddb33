"""A baked volume as a value (render/probes): the dict bake() and load() return (volume_dict), which
of a scene's `probes` keys the bake depends on (bake_settings) and which are read when shading
(sampled), and the options of a probes' directional basis."""

from __future__ import annotations

from iblbake.core import bases
from iblbake.core.bases.probes import PROBE_BASES
from iblbake.render.probes.grid import Grid


def basis_of(volume: dict):
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


def volume_dict(grid: Grid, settings: dict, irr, dist, data, report: dict) -> dict:
    """A baked volume: its grid, bake settings, arrays (irradiance: the octahedral atlas or (probes,
    9, 3) SH coefficients; distance: the moments' atlas; data: (probes, 4) offset in world units and
    state) and report."""
    return {"grid": grid, "counts": grid.counts, "origin": grid.origin, "spacing": grid.spacing,
            "representation": settings["irradiance"], "irradiance_texels": settings["irradiance_texels"],
            "distance_texels": settings["distance_texels"], "classification": settings["classification"],
            "settings": bake_settings(settings), "irradiance": irr, "distance": dist, "data": data, "report": report}


def sampled(volume: dict, settings: dict) -> dict:
    """The volume with a scene's sampling settings (visibility, biases in world units): what
    twin.irradiance and the shade pass read."""
    u = volume["grid"].unit
    return {**volume, "visibility": settings["visibility"], "normal_bias": settings["normal_bias"] * u,
            "view_bias": settings["view_bias"] * u}

