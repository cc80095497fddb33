"""Dilation into the exported atlases (render/probes/dilate.py, issue 59): an off probe's irradiance
is its active neighbours' inverse-square-weighted mean, so an engine that samples the atlas without
the states reads no black probe inside geometry."""

import numpy as np
import pytest

import iblbake
from iblbake.render import probes
from iblbake.render.probes.dilate import tiles_of
from iblbake.render.twin import probes as twin
from tests.helpers import load_scene


def test_an_off_probe_takes_its_active_neighbours_weighted_mean():
    counts = (3, 3, 3)
    rng = np.random.default_rng(3)
    values = rng.random((27, 4, 3))
    off = np.zeros(27, bool)
    centre = twin.probe_index(np.array([1, 1, 1]), counts)
    corner = twin.probe_index(np.array([0, 0, 0]), counts)
    off[[centre, corner]] = True
    out = probes.dilate_values(values, off, counts)
    assert np.array_equal(out[~off], values[~off])            # the active probes keep their values
    c = twin.probe_coords(np.arange(27), counts)
    for p in (centre, corner):
        d = ((c - c[p]) ** 2).sum(1)
        near = (np.abs(c - c[p]).max(1) == 1) & ~off
        want = (values[near] / d[near][:, None, None]).sum(0) / (1 / d[near]).sum()
        assert np.allclose(out[p], want, rtol=1e-12), p


def test_dilation_reaches_probes_beyond_the_first_ring():
    """A probe with no active neighbour takes the dilated ones' values on a later pass; with no
    active probe at all nothing changes."""
    counts = (5, 1, 1)
    values = np.array([[1.0], [0.0], [0.0], [0.0], [3.0]])
    off = np.array([False, True, True, True, False])
    out = probes.dilate_values(values, off, counts)
    assert np.allclose(out[:, 0], [1, 1, 2, 3, 3])
    assert np.array_equal(probes.dilate_values(values, np.ones(5, bool), counts), values)


@pytest.mark.parametrize("rep", ["octahedral", "sh"])
def test_a_probe_inside_a_solid_is_not_black_in_the_atlas(tmp_path, panoramas, rep):
    """A probe at the centre of a sphere too large to relocate it out is off; before dilation its
    tile in the atlas `iblbake probes` writes was black (0), read as such by an engine that samples
    the atlas without probe_data's states. Now it is the mean of the probes around it."""
    doc = {"camera": {"perspective": {"position": [0, 0, 6], "look_at": [0, 0, 0]}, "resolution": [8, 8]},
           "environment": {"path": str(panoramas["studio"])}, "materials": {"m": {"specular": 0}},
           "objects": [{"sphere": {"center": [0, 0, 0], "radius": 1.2}, "material": "m"}],
           "probes": {"min": [-3, -3, -3], "max": [3, 3, 3], "counts": [3, 3, 3], "rays": 128, "irradiance": rep}}
    vol = iblbake.bake_probes(load_scene(tmp_path, f"inside_{rep}", doc), cache=tmp_path / "cache")
    centre = twin.probe_index(np.array([1, 1, 1]), (3, 3, 3))
    assert vol.data[centre, 3] == probes.INACTIVE
    if rep == "sh":
        values = np.asarray(vol.irradiance, np.float64)
    else:
        values = tiles_of(np.asarray(vol.irradiance, np.float64), (3, 3, 3), vol.manifest["irradiance_texels"])
    active = vol.data[:, 3] == probes.ACTIVE
    c = twin.probe_coords(np.arange(27), (3, 3, 3))
    d = ((c - c[centre]) ** 2).sum(1)
    want = (values[active] / d[active].reshape((-1,) + (1,) * (values.ndim - 1))).sum(0) / (1 / d[active]).sum()
    assert np.abs(values[centre]).max() > 0.05 * np.abs(want).max() > 0     # black before dilation
    assert np.allclose(values[centre], want, rtol=1e-5, atol=1e-6)
