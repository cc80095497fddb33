"""The API's promise (issue 44) against a new user's trial: scene mappings take numpy values."""

import numpy as np
import pytest

import iblbake
from tests.conftest import write_exr


@pytest.fixture(scope="module")
def sky(tmp_path_factory):
    v = (np.arange(16)[:, None, None] + 0.5) / 16
    return write_exr(tmp_path_factory.mktemp("sky") / "sky.exr",
                     np.where(v < 0.5, [0.6, 0.8, 1.0], [0.1, 0.08, 0.05]) * np.ones((16, 32, 1)))


def scene_of(sky, **sections):
    doc = {"camera": {"perspective": {"position": [0, 0, 3], "fov_y": 40}, "resolution": [8, 8]},
           "environment": {"path": sky},
           "materials": {"m": {"base_color": [0.75, 0.5, 0.25], "roughness": 0.5}},
           "objects": [{"sphere": {"radius": 1}, "material": "m"}],
           "effects": {"diffuse": "sh", "specular": "off"}}
    return {**doc, **sections}


def test_a_scene_mapping_takes_numpy_values(sky, tmp_path):
    """numpy scalars and arrays, tuples and paths read as a file's numbers, lists and strings
    ("holds np.int64(32), not a finite number"); a bool, numpy's too, is still not a number."""
    from pathlib import Path
    plain = scene_of(sky, probes={"rays": 16})
    plain["camera"] = {"perspective": {"position": [0.0, 0.0, 3.0], "fov_y": 40}, "resolution": [32, 24]}
    numpy = scene_of(Path(sky), probes={"rays": np.int64(16)})
    numpy["environment"] = {"path": Path(sky)}
    numpy["camera"] = {"perspective": {"position": np.array([0.0, 0, 3]), "fov_y": np.float32(40)},
                       "resolution": [np.int64(32), np.int64(24)]}
    numpy["materials"] = {"m": {"base_color": np.array([0.75, 0.5, 0.25], np.float32), "roughness": np.float64(0.5)}}
    numpy["objects"] = ({"sphere": {"radius": np.int32(1)}, "material": "m"},)
    assert iblbake.load_scene(numpy).data == iblbake.load_scene(plain).data
    for bad in ({"resolution": [np.bool_(True), 24]}, {"resolution": [True, 24]},
                {"perspective": {"fov_y": np.bool_(True)}}):
        with pytest.raises(iblbake.InputError, match="camera"):
            iblbake.load_scene(scene_of(sky, camera=bad))


def test_scene_value_errors_of_the_bakes_are_input_errors(sky, tmp_path):
    """`probes: {counts: 1}` and a cache folder that is a file raised the bare iblbake.Error, not
    the documented InputError."""
    scene = scene_of(sky, objects=[{"sphere": {"radius": 1}, "material": "m"},
                                   {"plane": {"point": [0, -1, 0], "size": 4}, "material": "m"}])
    with pytest.raises(iblbake.InputError, match="probes.counts 1"):
        iblbake.bake_probes({**scene, "probes": {"counts": 1}}, cache=tmp_path / "cache")
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(iblbake.InputError, match="cannot create the cache folder"):
        iblbake.render(scene_of(sky), cache=afile)
