"""The study's lightmap rungs (study/ladder.py lightmap_rungs): `--ladder lightmaps` bakes the
scene's lightmap section in each basis at its density x 0.5, 1 and 2, each rung with its atlas
bytes, bake time, frame time and error against the reference; the default and realtime ladders
study the lightmap only where the scene has a `lightmap:` section."""

import json
import math
from pathlib import Path

import pytest
import yaml

import iblbake
from iblbake.errors import InputError
from iblbake.render import lightmaps
from iblbake.render.plan import effect_modes
from iblbake.study import ladder
from tests.helpers import run_cli

ROOT = Path(__file__).resolve().parents[1]
CUBE = str(ROOT / "examples/corpus/meshes/cube.obj")
DENSITIES = (1, 2, 4)                 # the scene's 2 texels a unit x 0.5, 1, 2
FLOATS = {"irradiance": 1, "sh_l1": 4, "sh": 9, "sg": 9}   # RGB coefficients a texel (sg: 9 lobes)


def doc(env, lightmap=True):
    d = {"camera": {"perspective": {"position": [0.3, 1.4, 3.2], "look_at": [0, 0.4, 0], "fov_y": 55},
                    "resolution": [40, 30]},
         "environment": {"path": str(env)},
         "materials": {"m": {"base_color": [0.7, 0.6, 0.5], "roughness": 1, "specular": 0}},
         "objects": [{"mesh": {"path": CUBE}, "material": "m", "name": "cube"},
                     {"plane": {"point": [0, 0, 0], "size": 3.5}, "material": "m", "name": "floor"}],
         "effects": {"diffuse": "sh", "specular": "off"}}
    if lightmap:
        d["lightmap"] = {"samples": 64, "texels_per_unit": 2}
    return d


def labels(rungs) -> list:
    return [r.label for r in rungs if r.label.startswith("lightmap")]


def test_the_ladders_study_a_lightmap_only_where_the_scene_asks_for_one(lobed_sky):
    """With a lightmap section: `lightmaps` is the grid (4 bases x 3 densities), the default ladder
    the scene's basis at each density and each other basis at its own, realtime the section as it
    is, and the scene's own lightmap names its basis and density. Without one, none; `--ladder
    lightmaps` says in one line what to add."""
    sc = iblbake.load_scene(doc(lobed_sky))
    fx = effect_modes(sc)
    grid = labels(ladder.LADDERS["lightmaps"](sc, fx))
    assert sorted(grid) == sorted(f"lightmap {b} @ {d}" for b in FLOATS for d in DENSITIES)
    assert set(FLOATS) <= set(lightmaps.NAMES)
    assert sorted(labels(ladder.default_ladder(sc, fx, "CPU"))) == sorted(
        [f"lightmap sh_l1 @ {d}" for d in DENSITIES] + [f"lightmap {b} @ 2" for b in ("irradiance", "sh", "sg")])
    assert labels(ladder.realtime_ladder(sc, fx)) == ["lightmap"]

    lit = iblbake.load_scene({**doc(lobed_sky), "effects": {"diffuse": "lightmap", "specular": "off"}})
    assert ladder.configured_rung(lit, "diffuse").label == "configured: lightmap sh_l1 @ 2"

    bare = iblbake.load_scene(doc(lobed_sky, lightmap=False))
    fx = effect_modes(bare)
    assert labels(ladder.default_ladder(bare, fx, "CPU", paths=True)) == []
    assert labels(ladder.realtime_ladder(bare, fx)) == []
    with pytest.raises(InputError, match=r"no lightmap: section; add one \(`lightmap: \{\}`") as e:
        ladder.LADDERS["lightmaps"](bare, fx)
    assert "\n" not in str(e.value)
    dark = iblbake.load_scene({**doc(lobed_sky), "effects": {"diffuse": "off", "specular": "prefiltered"}})
    fx = effect_modes(dark)
    assert labels(ladder.default_ladder(dark, fx, "CPU", paths=True)) == labels(ladder.realtime_ladder(dark, fx)) == []
    with pytest.raises(InputError, match=r"no diffuse term \(effects.diffuse: off\); give effects.diffuse a mode"):
        ladder.LADDERS["lightmaps"](dark, fx)


@pytest.mark.slow
def test_lightmap_rungs_report_bytes_bake_time_and_error(tmp_path, lobed_sky):
    """`iblbake accuracy --ladder lightmaps` on a cube on a floor (64 rays a texel): every rung of
    the grid in the JSON, the table and the report page, with its atlas bytes (the basis' RGB
    coefficients x fp16 RGBA a texel: exactly 4x, 9x the irradiance's at a density; growing with
    the density), the bake's own seconds and texels, its frame time, and its error against the
    reference (every object's mean within 6% under this smooth sky, a third of the panorama's SH's
    error or less; the frame's error lower at 4 texels a unit than at 1)."""
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(doc(lobed_sky)))
    r = run_cli("accuracy", tmp_path / "scene.yaml", "--ladder", "lightmaps", "--max-side", 32, "--repeats", 1,
                "--max-samples", 256, "--no-flip", "--cache", tmp_path / "c", "-o", tmp_path / "out", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)["rungs"]
    rows = {x["label"]: x for x in out if x["label"].startswith("lightmap")}
    sh = next(x for x in out if x["label"] == "configured: SH 3 bands")
    assert sorted(rows) == sorted(f"lightmap {b} @ {d}" for b in FLOATS for d in DENSITIES)
    for label, x in rows.items():
        lm = x["lightmap"]
        assert x["mode"] == "lightmap" and x["bytes"] == lm["bytes"] > 0
        assert lm["basis"] == label.split()[1] and lm["texels_per_unit"] == float(label.split()[-1])
        assert lm["bake_s"] > 0 and x["bake_s"] >= 0 and x["frame_s"] > 0 and x["time_s"] > 0
        # measured 1.6-2.6% (the panorama's SH, which sees no cube: 16.6%)
        assert math.isfinite(x["relative_rmse"]) and x["worst_region_absolute"] < 0.06, (label, x["region_absolute"])
        assert x["worst_region_absolute"] < sh["worst_region_absolute"] / 3
    for d in DENSITIES:
        one = rows[f"lightmap irradiance @ {d}"]["bytes"]
        assert {b: rows[f"lightmap {b} @ {d}"]["bytes"] / one for b in FLOATS} == FLOATS
    for b in FLOATS:
        got = [rows[f"lightmap {b} @ {d}"] for d in DENSITIES]
        assert got[0]["bytes"] < got[1]["bytes"] < got[2]["bytes"]
        assert got[0]["lightmap"]["texels"] < got[1]["lightmap"]["texels"] < got[2]["lightmap"]["texels"]
        assert got[0]["relative_rmse"] > 1.4 * got[2]["relative_rmse"]     # measured 3.5% and 1.9%
    table = (tmp_path / "out" / "table.md").read_text()
    page = (tmp_path / "out" / "index.html").read_text()
    for label, x in rows.items():
        assert f"| diffuse | {label} |" in table and f"| {x['bytes']} |" in table
        assert label in page


def test_a_rung_past_the_atlas_cap_is_refused_before_anything_renders(tmp_path, lobed_sky):
    """A density of the grid whose atlas passes lightmap.max_texels (the scene's 2 texels a unit fit
    300 texels, 4 do not: about 28 units of surface) is a one-line error naming the rung and the key,
    said before the reference renders (its bake would refuse it after)."""
    d = doc(lobed_sky)
    d["lightmap"]["max_texels"] = 300
    ran = []
    with pytest.raises(InputError, match=r"ladder rung 'lightmap irradiance @ 4': lightmap.texels_per_unit: 4 texels "
                                         r"per unit asks about \d+ texels .* over the cap of 300") as e:
        iblbake.accuracy(d, "lightmaps", max_side=16, repeats=1, max_samples=16, flip=False, cache=tmp_path / "c",
                         before_run=lambda *a: ran.append(a))
    assert "\n" not in str(e.value) and not ran
    assert not (tmp_path / "c").exists() or not any((tmp_path / "c").iterdir())
