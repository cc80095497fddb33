"""Nothing dropped or misread in silence (issue 43): numbers as a user writes them, list-valued
sweeps from the command line, limits that name real options, negative panoramas reported, clean
`compare --json`, the study's own notes (bounces, samples above the reference's, SSR thumbnails,
the reference's samples), the plot's labels apart."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from iblbake.errors import InputError
from iblbake.io import images
from iblbake.scene import load as scene_load
from iblbake.scene.yaml_lines import load_with_lines
from iblbake.study import sweep

from tests.helpers import run_cli, scene_file, write_exr


@pytest.fixture
def sky(tmp_path):
    return Path(write_exr(tmp_path / "sky.exr", np.full((8, 16, 3), 0.5, np.float32)))


# --- numbers ----------------------------------------------------------------------------------

def test_scientific_notation_reads_as_numbers_with_its_lines():
    """YAML 1.1's float needs a dot and a signed exponent: 1e-6, 1e3, 1E3, 0.5e1 and 1.0e30 were
    strings, then 'not a number'."""
    text = "a: 1e-6\nb: 1e3\nc: 1E3\nd: 0.5e1\ne: 1.0e30\nf: -2.5E-3\ng: +1e2\nh: [1e-1, 2E+0]\ni: 1.5\nj: 7\n" \
           "k: 1e\nl: e3\nm: 1e3x\nn: '1e3'\n"
    data, lines = load_with_lines(text, "t.yaml")
    assert data == {"a": 1e-6, "b": 1000.0, "c": 1000.0, "d": 5.0, "e": 1e30, "f": -2.5e-3, "g": 100.0,
                    "h": [0.1, 2.0], "i": 1.5, "j": 7, "k": "1e", "l": "e3", "m": "1e3x", "n": "1e3"}
    assert all(isinstance(data[k], float) for k in "abcdefg")
    assert lines["e"] == 5 and lines["h.1"] == 8 and lines["n"] == 14


def test_scientific_notation_in_a_scene_and_in_set(tmp_path, sky):
    scene = scene_file(tmp_path, sky, effects={"specular": "importance", "samples": "1e2"})
    scene.write_text(scene.read_text().replace("'1e2'", "1e2"))
    sc = scene_load.load(scene, ["effects.exposure=-5e-1", "materials.m.roughness=2.5E-1",
                                 "camera.perspective.fov_y=0.3e2"])
    fx = sc.data["effects"]
    assert fx["samples"] == 100 and isinstance(fx["samples"], int)
    assert fx["exposure"] == -0.5 and sc.data["materials"]["m"]["roughness"] == 0.25
    assert sc.data["camera"]["perspective"]["fov_y"] == 30.0
    assert sweep.parse_cli_axis("materials.m.roughness=1e-1,5E-1")["values"] == [0.1, 0.5]
    assert sweep.parse_cli_axis("effects.samples=1e0:1e2:3:geometric")["range"] == {
        "start": 1.0, "stop": 100.0, "count": 3, "geometric": True}


def test_yaml_merge_keys_share_settings(tmp_path, sky):
    """`<<: *base` (YAML's merge key) was "could not determine a constructor for the tag": merged
    keys come in, a key written beside it wins, the first of a list of bases wins, and errors keep
    their lines."""
    text = (f"environment: {{path: {sky.name}}}\n"
            "materials:\n"
            "  gold: &metal {metallic: 1, roughness: 0.2, base_color: [1, 0.8, 0.3]}\n"
            "  rough: {<<: *metal, roughness: 0.6}\n"
            "  both:\n"
            "    <<: [{roughness: 0.9}, *metal]\n"
            "    metallic: 0\n"
            "objects: [{sphere: {radius: 1}, material: rough}]\n")
    (tmp_path / "s.yaml").write_text(text)
    mats = scene_load.load(tmp_path / "s.yaml").data["materials"]
    assert mats["rough"]["metallic"] == 1 and mats["rough"]["roughness"] == 0.6
    assert mats["rough"]["base_color"] == [1, 0.8, 0.3]
    assert mats["both"]["roughness"] == 0.9 and mats["both"]["metallic"] == 0
    assert load_with_lines(text, "s.yaml")[1]["materials.both.roughness"] == 6
    bad = text.replace("rough: {<<: *metal, roughness: 0.6}", "rough: {<<: *metal, roughness: 7}")
    (tmp_path / "s.yaml").write_text(bad)
    with pytest.raises(InputError, match=r"s\.yaml:4: materials\.rough\.roughness"):
        scene_load.load(tmp_path / "s.yaml")
    for wrong, words in (("a: {<<: 3}", "t.yaml:1: a: the merge key << takes a mapping"),
                         ("a: &a {<<: *a}", "t.yaml:1: a: nested deeper than 32 levels"),
                         # the trial: a second merge key loaded silently (the first won)
                         ("a: &a {x: 1}\nb: &b {x: 2}\nd: {<<: *a, <<: *b}",
                          r"t.yaml:3: d.<<: key given twice; merge several mappings with one list \(<<: \[\*a, \*b\]\)"),
                         ("<<: {x: 1}\n<<: {y: 2}", "t.yaml:2: <<: key given twice")):
        with pytest.raises(InputError, match=words):
            load_with_lines(wrong, "t.yaml")
    assert load_with_lines("a: &a {x: 1}\nb: &b {x: 2}\nd: {<<: [*a, *b]}", "t.yaml")[0]["d"] == {"x": 1}


# --- list-valued sweeps ---------------------------------------------------------------------------

def test_a_list_valued_key_sweeps_from_the_command_line(tmp_path, sky):
    """--columns "materials.m.base_color=[1,0,0],[0,1,0]" was a raw YAML parser message."""
    sc = scene_load.load(scene_file(tmp_path, sky))
    cols = sweep.parse_cli_axis("materials.m.base_color=[1,0,0],[0, 1, 0.5]", "--columns")
    rows = sweep.parse_cli_axis("camera.resolution=[32,24],[16, 12]", "--rows")
    assert cols["values"] == [[1, 0, 0], [0, 1, 0.5]] and rows["values"] == [[32, 24], [16, 12]]
    r, c, cells = sweep.plan_sheet(sc, rows, cols)
    assert [cl.values for cl in cells] == [
        [("camera.resolution", [32, 24]), ("materials.m.base_color", [1, 0, 0])],
        [("camera.resolution", [32, 24]), ("materials.m.base_color", [0, 1, 0.5])],
        [("camera.resolution", [16, 12]), ("materials.m.base_color", [1, 0, 0])],
        [("camera.resolution", [16, 12]), ("materials.m.base_color", [0, 1, 0.5])]]
    assert [s.label for s in c.steps] == ["[1, 0, 0]", "[0, 1, 0.5]"]
    cell = scene_load.load(sc.source, values=cells[3].values, origin="--rows")
    assert cell.data["camera"]["resolution"] == [16, 12] and cell.data["materials"]["m"]["base_color"] == [0, 1, 0.5]
    # a flow mapping or quoted commas stay one value; a broken list is a usage error naming the flag
    assert sweep.parse_cli_axis("environment.path='a,b.exr',c.exr")["values"] == ["a,b.exr", "c.exr"]
    with pytest.raises(InputError) as e:
        sweep.parse_cli_axis("materials.m.base_color=[1,0,0],[0,1", "--columns")
    assert e.value.exit_code == 2 and "--columns" in str(e.value)


# --- limits that name what raises them -------------------------------------------------------------

def test_the_pixel_limit_names_an_option_that_exists(tmp_path, sky):
    """render said "raise it with max_pixels or IBLBAKE_MAX_PIXELS": there was no such key or option."""
    scene = scene_file(tmp_path, sky, camera={"resolution": [8, 8]}, effects={"specular": "off"})
    p = run_cli("render", scene, "-o", tmp_path / "f.png", env={"IBLBAKE_MAX_PIXELS": "64"})
    assert p.returncode == 1, p.stderr
    line = p.stderr.strip()
    assert "over the limit of 64" in line and "--max-pixels" in line and "max_pixels or" not in line, line
    p = run_cli("render", scene, "-o", tmp_path / "f.png", "--max-pixels", "128", env={"IBLBAKE_MAX_PIXELS": "64"})
    assert p.returncode == 0, p.stderr
    # the reference's samples, not camera.spp's 1
    p = run_cli("render", scene, "-o", tmp_path / "r.png", "--set", "effects.diffuse=reference",
                "--set", "effects.reference.max_samples=16", "--set", "effects.reference.target_noise=0")
    assert p.returncode == 0 and "16 samples per pixel (reference, stopped by max_samples)" in p.stderr + p.stdout, \
        p.stdout + p.stderr
    assert "1 spp" not in p.stdout


# --- negative panoramas -------------------------------------------------------------------------

@pytest.mark.parametrize("fill", ["all -1", "half -5"])
def test_negative_panoramas_are_reported(tmp_path, fill):
    """--negative keep is "counted and reported": sh called them tiny, mips and render said nothing."""
    img = np.full((8, 16, 3), -1.0, np.float32) if fill == "all -1" else \
        np.where(np.arange(16)[None, :, None] < 8, -5.0, 1.0).astype(np.float32) * np.ones((8, 16, 3), np.float32)
    env = Path(write_exr(tmp_path / "neg.exr", img))
    _, info = images.read_panorama(env)
    assert info.negative == (384 if fill == "all -1" else 192) and not info.negative_tiny
    assert any("negative values kept as stored" in w for w in info.warnings)
    p = run_cli("sh", env, "--backend", "numpy", "--no-error")
    assert p.returncode == 0 and "tiny" not in p.stderr + p.stdout
    assert "negative values kept as stored" in p.stderr and "--negative clamp" in p.stderr, p.stderr
    scene = scene_file(tmp_path, env, camera={"resolution": [8, 8]}, effects={"specular": "off"})
    p = run_cli("render", scene, "-o", tmp_path / "f.exr")
    assert p.returncode == 0 and "negative values kept as stored" in p.stderr, p.stderr
    assert "environment.negative: clamp" in p.stderr
    p = run_cli("mips", env, "--only", "radiance", "--cache", tmp_path / "c")
    assert p.returncode == 0 and "negative values kept as stored" in p.stderr, p.stderr


def test_tiny_negatives_are_counted_without_a_warning():
    """A filter's undershoot (Blender's panoramas: >= -0.004, at most 6e-7 of the energy) stays quiet."""
    img = np.ones((64, 128, 3), np.float32)
    img[3, 5] = -0.004
    info = images.ImageInfo("x.exr", 128, 64, ("R", "G", "B"), "float", "0")
    images.validate_texels(img, info)
    assert info.negative == 3 and info.negative_tiny and not info.warnings


# --- compare --json ------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["missing", "not a png", "truncated"])
def test_compare_json_stays_clean_on_a_bad_input(tmp_path, kind):
    """compare missing.png b.png --json printed OpenImageIO's pending-error dump on stdout (breaking the
    JSON), an assertion on stderr and a garbled repeated line."""
    good = tmp_path / "b.png"
    images.write_png(good, (np.random.default_rng(0).random((16, 16, 3)) * 255).astype(np.uint8))
    bad = tmp_path / "a.png"
    if kind == "not a png":
        bad.write_text("garbage\n")
    elif kind == "truncated":
        data = good.read_bytes()
        bad.write_bytes(data[:len(data) // 2])
    p = run_cli("compare", bad, good, "--json")
    assert p.returncode == 1
    assert p.stdout == "", p.stdout
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "a.png" in lines[0] and "Assertion" not in p.stderr, p.stderr
    assert len(lines[0]) < 300
    p = run_cli("compare", good, good, "--json")
    assert p.returncode == 0 and json.loads(p.stdout)["errors"][0]["error"] == 0.0


# --- the study says what it changed -------------------------------------------------------------

@pytest.fixture
def floor_scene(tmp_path, sky):
    """A sphere on a floor: light passes between them (paths), where visibility is on."""
    return scene_file(tmp_path, sky, camera={"perspective": {"position": [0, 0.5, 4]}, "resolution": [12, 12]},
                      materials={"base_color": [0.8, 0.8, 0.8], "roughness": 0.5},
                      objects=[{"sphere": {"radius": 1}, "material": "m"},
                               {"plane": {"point": [0, -1, 0], "normal": [0, 1, 0], "size": 8}, "material": "m"}],
                      effects={"diffuse": "sh", "specular": "off"})


def test_the_study_says_what_it_changed(tmp_path, floor_scene):
    """--bounces 2 --no-visibility became 1 without a note; --max-samples 16 kept rungs of 64
    samples and put them on the frontier, measured against a reference of 16."""
    lad = tmp_path / "ladder.yaml"
    lad.write_text(yaml.safe_dump({"rungs": [{"key": "effects.reference.max_samples", "values": [8, 64], "term": "diffuse",
                                              "with": {"effects.diffuse": "reference",
                                                       "effects.reference.target_noise": 0}}]}))
    p = run_cli("accuracy", floor_scene, "--ladder", lad, "--bounces", "2", "--no-visibility", "--max-samples", 16,
                "--max-side", 12, "--repeats", 1, "--no-flip", "--cache", tmp_path / "c", "--json")
    assert p.returncode == 0, p.stderr
    assert "--bounces 2: with --no-visibility" in p.stderr and "the reference is the direct light (bounces 1)" \
        in p.stderr, p.stderr
    assert "more samples than the reference reached (max_samples=64)" in p.stderr, p.stderr
    s = json.loads(p.stdout)
    assert s["reference"]["diffuse"]["bounces"] == 1
    rungs = {r["label"]: r for r in s["rungs"]}
    high, low = rungs["max_samples=64"], rungs["max_samples=8"]
    assert high["above_reference"] and not high["pareto"] and not low["above_reference"]
    assert "max_samples=64" not in s["frontier"]["diffuse"]


@pytest.mark.slow
def test_an_ssr_rungs_thumbnail_is_the_specular_term(tmp_path, floor_scene, rt):
    """errors.png showed an SSR rung's whole frame (the PNG of both terms) beside the error map of
    the specular term that was measured."""
    from iblbake.render import Bakes, render
    from iblbake.core import tonemap
    from iblbake.study import accuracy as acc
    from iblbake.study.ladder import Rung

    floor_scene.write_text(floor_scene.read_text().replace("specular: 'off'", "specular: prefiltered"))
    study = acc.Study(floor_scene, [], acc.Settings(max_side=12, repeats=1, max_samples=8, flip=False),
                      runtime=rt, bakes=Bakes(tmp_path / "cache"))
    study.render_reference("specular")
    rung = Rung("specular", "prefiltered + ssr", [("effects.specular", "prefiltered"), ("effects.ssr", "on")])
    study.run_rung(rung)
    fx = study.scene.data["effects"]
    term = tonemap.to_u8(tonemap.tonemap(rung.frame.hdr[..., :3], fx["tonemap"], fx["exposure"],
                                         fx["output_transfer"], fx["gamma"]))
    both = render(study.load(study.rung_values(rung)), runtime=rt, cache=study.bakes).png
    assert np.array_equal(rung.frame.png[..., :3], term)
    assert np.abs(both[..., :3].astype(int) - term.astype(int)).max() > 10     # the diffuse term is not in it


def test_the_plots_labels_do_not_pile_up(tmp_path, floor_scene):
    """Every label was drawn at (3, 2) points from its point: on the default ladder dozens sat one
    over another. The default ladder's labels, at times and errors bunched as a CPU study's are."""
    import matplotlib.pyplot as plt
    from matplotlib.text import Text

    from iblbake.render.plan import effect_modes
    from iblbake.study import ladder, report

    sc = scene_load.load(floor_scene, ["effects.specular=prefiltered"])
    rng = np.random.default_rng(3)
    rows = []
    for r in ladder.default_ladder(sc, effect_modes(sc), "CPU", paths=True):
        n = dict(r.values).get("effects.samples")
        t, e = (1e-4 * n, 0.5 / np.sqrt(n)) if n else (2e-3 * rng.lognormal(0, 0.6), 0.2 * rng.lognormal(0, 0.4))
        rows.append({"term": r.term, "label": r.label, "time_s": float(t), "relative_rmse": float(e), "configured": False})
    from iblbake.study.accuracy import frontiers
    fig = report.plot_figure(rows, frontiers(rows), "t")
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    piled = 0
    for ax in fig.axes:
        boxes = [Text.get_window_extent(t, r) for t in ax.texts]     # the words, not their leader lines
        assert len(boxes) == sum(1 for row in rows if row["term"] == ax.get_title())
        piled += sum(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])
        panel = ax.get_window_extent(r)
        assert all(panel.x0 - 1 <= b.x0 and b.x1 <= panel.x1 + 1 and panel.y0 - 1 <= b.y0 and b.y1 <= panel.y1 + 1
                   for b in boxes)
    plt.close(fig)
    assert len(rows) > 60 and piled == 0, piled


def test_what_a_new_user_tripped_on_is_said_plainly(tmp_path, lobed_sky):
    """A new user's trial: an error in a key set by --set named the file's first line (or the line
    it replaced), `exclude: []` was refused, a mistyped built-in ladder was 'no such file' alone,
    and a sweep of on/off labelled its columns False / True."""
    from iblbake.scene import load as scene_load
    from iblbake.study import ladder, sweep
    from iblbake.errors import InputError
    from tests.helpers import scene_file
    p = scene_file(tmp_path, lobed_sky)
    with pytest.raises(InputError) as e:
        scene_load.load(p, ["probes={counts: 4, spacing: 0.5}"])
    assert f"{p}: --set: probes.spacing:" in str(e.value), str(e.value)
    sc = scene_load.load(p, ["reflection_probes=[{position: [0, 0, 0], min: [-2, -2, -2], max: [2, 2, 2], exclude: []}]"])
    assert sc.data["reflection_probes"][0]["exclude_ids"] == []
    with pytest.raises(InputError, match="did you mean --ladder realtime"):
        ladder.ladder_from_file("realtim", sc, None)
    assert [sweep.format_value(v) for v in (False, True, 0.5)] == ["off", "on", "0.5"]


def test_a_camera_far_outside_the_scene_is_said(tmp_path, sky):
    """A camera left at scale 1 in a scene scaled by 0.01 (trial74) rendered a few pixels of the
    room in a frame of sky, nothing said. The unit sphere's bounds (a sphere of radius 3^0.5 about
    them) from 200 units span 1 degree of a 45 degree frame: said once, naming the key; from 3 units,
    from inside the bounds, an orthographic view 4 units wide, or over an infinite floor: nothing."""
    def said(name, **sections):
        r = run_cli("render", scene_file(tmp_path, sky, name=name, **sections), "-o", tmp_path / f"{name}.exr",
                    "--cache", tmp_path / "c", "--json")
        assert r.returncode == 0, r.stderr
        return [w for w in json.loads(r.stdout)["warnings"] if "stands" in w and "outside its bounds" in w]

    far = {"perspective": {"position": [0, 0, 200], "fov_y": 45}, "resolution": [8, 8]}
    w = said("far", camera=far)
    assert len(w) == 1 and w[0].startswith("camera.perspective.position [0.0, 0.0, 200.0] stands 200 ") \
        and "spans 2.2% of the frame's height" in w[0], w
    assert said("near", camera={**far, "perspective": {"position": [0, 0, 3], "fov_y": 45}}) == []
    assert said("inside", camera={**far, "perspective": {"position": [0, 0, 0.5], "fov_y": 45}}) == []
    ortho = {"orthographic": {"position": [0, 0, 200], "width": 4}, "resolution": [8, 8]}
    assert said("ortho", camera=ortho) == []
    assert len(said("ortho_wide", camera={**ortho, "orthographic": {"position": [0, 0, 200], "width": 40}})) == 1
    floor = [{"sphere": {"radius": 1}, "material": "m"}, {"plane": {"point": [0, -1, 0], "normal": [0, 1, 0]},
                                                          "material": "m"}]
    assert said("floor", camera=far, objects=floor) == []
