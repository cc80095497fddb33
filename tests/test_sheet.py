"""`iblbake sheet`: cells equal to individually rendered frames, captions drawn, the JSON cells,
reuse across cells (a tone-mapping sweep lights once, a roughness sweep traces primary rays
once), the CLI shorthand, and bad sweep specs as one-line errors with nothing written."""

import json
import shutil

import numpy as np
import pytest
import yaml

from iblbake.io import images
from iblbake.study import sheet, sweep

from tests.helpers import read_png, run_cli, sheet_scene


SWEEP = {"title": "gold", "rows": {"key": "materials.gold.metallic", "values": [0, 1]},
         "columns": {"key": "materials.gold.roughness", "range": {"start": 0, "stop": 1, "count": 3}}}


@pytest.mark.external
def test_two_by_three_sheet_cells_equal_rendered_frames(tmp_path, small_panoramas):
    scene = sheet_scene(tmp_path, small_panoramas["city"], SWEEP)
    out, mosaic = tmp_path / "sheet.png", tmp_path / "sheet.exr"
    p = run_cli("sheet", scene, "-o", out, "-o", mosaic, "--json", "--cache", tmp_path / "c",
                "--frames", tmp_path / "frames")
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    cells = doc["cells"]
    assert len(cells) == 6
    assert [(c["row"], c["column"]) for c in cells] == [(r, c) for r in range(2) for c in range(3)]
    assert [c["values"] for c in cells] == [{"materials.gold.metallic": m, "materials.gold.roughness": r}
                                            for m in (0, 1) for r in (0.0, 0.5, 1.0)]
    png = read_png(out)
    hdr = images.read_exr(mosaic)
    assert hdr.shape[:2] == (2 * 32 + sheet.GAP, 3 * 48 + 2 * sheet.GAP)
    # the layout the sheet used, recomputed from the same inputs, places every cell
    rows_axis, cols_axis, plan_cells = sweep.plan_sheet(_load(scene))
    fake = [sheet.CellResult(c, frame=_Stub(np.zeros((32, 48, 3), np.uint8))) for c in plan_cells]
    lay = sheet.layout(fake, rows_axis, cols_axis, "gold", "values")
    assert png.shape[:2] == (lay.height, lay.width)
    for c in cells:
        single = tmp_path / f"single_{c['row']}_{c['column']}.png"
        sets = [a for k, v in c["values"].items() for a in ("--set", f"{k}={v}")]
        r = run_cli("render", scene, "-o", single, "--cache", tmp_path / "c", "-q", *sets)
        assert r.returncode == 0, r.stderr
        want = read_png(single)
        x, y = lay.origin(c["row"], c["column"])
        assert np.array_equal(png[y:y + 32, x:x + 48], want), c
        assert np.array_equal(read_png(c["outputs"][0]), want)
        # the caption under the cell is drawn (text pixels, not the flat background)
        band = png[y + 32:y + lay.caption_h + 32, x:x + 48].astype(int)
        assert (np.abs(band - band[0, 0]).max(axis=-1) > 60).sum() > 20, c


def _load(path):
    from iblbake.scene import load
    return load.load(path)


class _Stub:
    def __init__(self, png):
        self.png = png
        self.report = {"reused": []}


@pytest.mark.external
def test_tonemap_sweep_lights_once_and_roughness_sweep_traces_once(tmp_path, small_panoramas):
    scene = sheet_scene(tmp_path, small_panoramas["studio"])
    p = run_cli("sheet", scene, "-o", tmp_path / "t.png", "--columns", "effects.tonemap=aces,reinhard,hable",
                "--json", "--cache", tmp_path / "c")
    assert p.returncode == 0, p.stderr
    cells = json.loads(p.stdout)["cells"]
    assert cells[0]["reused"] == []
    for c in cells[1:]:
        assert set(c["reused"]) == {"gbuffer", "shade", "background", "resolve"}, c
    p = run_cli("sheet", scene, "-o", tmp_path / "r.png", "--rows", "materials.gold.roughness=0:1:4",
                "--json", "--cache", tmp_path / "c")
    assert p.returncode == 0, p.stderr
    cells = json.loads(p.stdout)["cells"]
    assert [c["values"]["materials.gold.roughness"] for c in cells] == pytest.approx([0, 1 / 3, 2 / 3, 1])
    assert all(c["reused"] == ["gbuffer"] for c in cells[1:]), cells


@pytest.mark.external
def test_a_metallic_axis_samples_the_panorama_once_per_roughness(tmp_path, small_panoramas):
    """Importance sampling splits around Fresnel (kernels/shade.cl importance): cells differing only
    in metallic reuse the two sums, the sheet goes down each metallic column to do so (rendering
    the importance pass 3 times for 6 cells, not 6), and every cell still equals its own frame."""
    scene = sheet_scene(tmp_path, small_panoramas["city"], SWEEP)
    common = ["--cache", tmp_path / "c", "--set", "effects.specular=importance", "--set", "effects.samples=16"]
    p = run_cli("sheet", scene, "-o", tmp_path / "s.png", "--json", "--frames", tmp_path / "frames", *common)
    assert p.returncode == 0, p.stderr
    cells = json.loads(p.stdout)["cells"]
    sampled = [c for c in cells if "importance" not in c["reused"]]
    assert [(c["row"], c["column"]) for c in sampled] == [(0, 0), (0, 1), (0, 2)], cells
    for c in cells:
        single = tmp_path / f"single_{c['row']}_{c['column']}.png"
        sets = [a for k, v in c["values"].items() for a in ("--set", f"{k}={v}")]
        r = run_cli("render", scene, "-o", single, "-q", *common, *sets)
        assert r.returncode == 0, r.stderr
        assert np.array_equal(read_png(c["outputs"][0]), read_png(single)), c


def test_cli_axis_shorthand():
    assert sweep.parse_cli_axis("effects.samples=1:256:9:log") == {
        "key": "effects.samples", "range": {"start": 1, "stop": 256, "count": 9, "geometric": True}}
    assert sweep.parse_cli_axis("effects.specular=importance,prefiltered") == {
        "key": "effects.specular", "values": ["importance", "prefiltered"]}
    assert sweep._range({"start": 1, "stop": 256, "count": 9, "geometric": True}, "x") == \
        [1, 2, 4, 8, 16, 32, 64, 128, 256]


@pytest.mark.external
@pytest.mark.parametrize("spec, words", [
    ({"rows": {"key": "materials.gold.roughnes", "values": [0, 1]}}, ["sweep.rows", "roughnes", "roughness"]),
    ({"rows": {"key": "materials.silver.roughness", "values": [0]}}, ["sweep.rows", "silver"]),
    ({"rows": {"key": "materials.gold.roughness", "values": []}}, ["sweep.rows.values", "non-empty"]),
    ({"rows": {"key": "materials.gold.roughness", "range": {"start": 0, "stop": 1, "count": 0}}},
     ["sweep.rows.range.count"]),
    ({"columns": {"key": "materials.gold.roughness", "values": [0.2, "shiny"]}},
     ["materials.gold.roughness", "shiny", "not a number"]),
    ({"columns": {"key": "materials.gold.roughness", "values": [0.2, 7]}}, ["materials.gold.roughness", "range"]),
    ({"layers": {"key": "effects.exposure", "values": [0]}}, ["sweep.layers", "unknown key"]),
    ({"rows": {"key": "materials.gold", "values": [0]}}, ["materials.gold", "section"]),
])
def test_bad_sweep_specs_fail_in_one_line_and_write_nothing(tmp_path, small_panoramas, spec, words):
    scene = sheet_scene(tmp_path, small_panoramas["studio"], spec)
    out = tmp_path / "bad.png"
    p = run_cli("sheet", scene, "-o", out, "--cache", tmp_path / "c")
    assert p.returncode == 1, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert not out.exists()


@pytest.mark.external
def test_keep_going_marks_the_failed_cell(tmp_path, small_panoramas):
    scene = sheet_scene(tmp_path, small_panoramas["studio"])
    out = tmp_path / "k.png"
    p = run_cli("sheet", scene, "-o", out, "--columns", "materials.gold.roughness=0.2,3,0.6", "--keep-going",
                "--json", "--cache", tmp_path / "c")
    assert p.returncode == 1 and "1 of 3 cells failed" in p.stderr, p.stderr
    cells = json.loads(p.stdout)["cells"]
    assert [c["error"] is None for c in cells] == [True, False, True]
    assert out.exists()


@pytest.mark.external
def test_makefile_rebuilds_only_what_reads_a_touched_input(tmp_path, small_panoramas):
    """Two scenes on two panoramas, a Makefile with `-include *.d` from --depfile: a second make
    does nothing; touching one panorama rebuilds only the frame and the sheet that read it; the
    depfile lists every file the scene reads (scene, panorama, mesh)."""
    import os
    import shutil
    import subprocess
    import sys
    import time
    import trimesh
    for name in ("city", "studio"):
        shutil.copy(small_panoramas[name], tmp_path / f"{name}.exr")
    trimesh.creation.icosphere(subdivisions=1, radius=0.4).export(tmp_path / "ico.ply")
    for name in ("city", "studio"):
        doc = yaml.safe_load(sheet_scene(tmp_path, tmp_path / f"{name}.exr").read_text())
        doc["environment"]["path"] = f"{name}.exr"
        doc["objects"].append({"mesh": {"path": "ico.ply", "translate": [0, 0.9, 0]}, "material": "paint"})
        (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(doc))
    exe = f"{sys.executable} -m iblbake.cli"
    (tmp_path / "Makefile").write_text(
        "all: city.png studio.png city_sheet.png\n"
        "%.png: %.yaml\n\t" + exe + " render $< -o $@ --depfile $@.d -q --cache c\n"
        "city_sheet.png: city.yaml\n\t" + exe + " sheet $< -o $@ --depfile $@.d -q --cache c "
        "--columns materials.gold.roughness=0.1,0.9\n"
        "-include *.d\n")
    make = lambda *a: subprocess.run(["make", "-C", str(tmp_path), *a], capture_output=True, text=True, timeout=300)
    r = make()
    assert r.returncode == 0, r.stdout + r.stderr
    assert make("-q").returncode == 0                       # up to date: a second make is a no-op
    deps = (tmp_path / "city.png.d").read_text()
    for f in ("city.yaml", "city.exr", "ico.ply"):
        assert f in deps.split(":")[1], deps
    before = {f: os.stat(tmp_path / f).st_mtime_ns for f in ("city.png", "studio.png", "city_sheet.png")}
    time.sleep(0.01)
    os.utime(tmp_path / "city.exr")
    r = make()
    assert r.returncode == 0, r.stdout + r.stderr
    after = {f: os.stat(tmp_path / f).st_mtime_ns for f in before}
    assert after["city.png"] > before["city.png"] and after["city_sheet.png"] > before["city_sheet.png"]
    assert after["studio.png"] == before["studio.png"]


@pytest.mark.external
def test_sh_and_mips_take_several_panoramas(tmp_path, small_panoramas):
    out = tmp_path / "sh"
    p = run_cli("sh", small_panoramas["city"], small_panoramas["studio"], "-o", f"{out}/", "--json",
                "--depfile", tmp_path / "sh.d")
    assert p.returncode == 0, p.stderr
    assert sorted(x.name for x in out.iterdir()) == ["city.json", "studio.json"]
    assert len(json.loads(p.stdout)["panoramas"]) == 2
    assert "studio.exr" in (tmp_path / "sh.d").read_text()
    p = run_cli("sh", small_panoramas["city"], small_panoramas["studio"], "-o", tmp_path / "one.json")
    assert p.returncode == 1 and "is a folder" in p.stderr
    p = run_cli("mips", small_panoramas["city"], small_panoramas["studio"], "--cache", tmp_path / "c", "--json",
                "--size", "32", "--levels", "3")
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)["panoramas"]
    assert len(doc) == 2 and doc[0]["entries"]["dfg"] == doc[1]["entries"]["dfg"]
    assert doc[0]["entries"]["prefiltered"]["path"] != doc[1]["entries"]["prefiltered"]["path"]


def _sheet(scene, tmp_path, *args):
    p = run_cli("sheet", scene, "--cache", tmp_path / "c", "--json", *args)
    return p, (json.loads(p.stdout) if p.returncode == 0 and p.stdout.strip() else None)


@pytest.mark.external
def test_shards_then_assemble_equal_the_serial_sheet(tmp_path, small_panoramas):
    """Shards 1/3, 2/3, 3/3 (the cells sorted by key and dealt round-robin: each cell in exactly
    one, two each) leave their cells in the cache; --assemble builds the sheet from them, equal byte for byte to the serial one,
    and fails in one line naming the cells while a shard is missing."""
    scene = sheet_scene(tmp_path, small_panoramas["city"], SWEEP)
    p, serial = _sheet(scene, tmp_path / "serial", "-o", tmp_path / "serial.png", "-o", tmp_path / "serial.exr")
    assert p.returncode == 0, p.stderr
    done = set()
    for i in (1, 2):
        p, doc = _sheet(scene, tmp_path, "--shard", f"{i}/3")
        assert p.returncode == 0, p.stderr
        cells = {(c["row"], c["column"]) for c in doc["cells"]}
        assert len(cells) == 2 and not cells & done
        done |= cells
    p, _ = _sheet(scene, tmp_path, "--assemble", "-o", tmp_path / "a.png")
    assert p.returncode != 0 and not (tmp_path / "a.png").exists()
    assert len(p.stderr.strip().splitlines()) == 1 and "2 of 6 cells are not in the cache" in p.stderr
    for r, c in {(r, c) for r in range(2) for c in range(3)} - done:
        assert f"row {r}, column {c}" in p.stderr
    p, doc = _sheet(scene, tmp_path, "--shard", "3/3")
    assert p.returncode == 0 and len(doc["cells"]) == 2
    p, doc = _sheet(scene, tmp_path, "--assemble", "-o", tmp_path / "a.png", "-o", tmp_path / "a.exr")
    assert p.returncode == 0, p.stderr
    assert all(c["cached"] for c in doc["cells"])
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "serial.png").read_bytes()
    assert np.array_equal(images.read_exr(tmp_path / "a.exr"), images.read_exr(tmp_path / "serial.exr"))


@pytest.mark.external
def test_resume_renders_only_the_missing_cells(tmp_path, small_panoramas):
    """A run that stopped part way (here: one shard of two) left its cells in the cache; --resume
    reads those back and renders the rest; without --resume every cell renders again."""
    scene = sheet_scene(tmp_path, small_panoramas["city"], SWEEP)
    p, doc = _sheet(scene, tmp_path, "--shard", "1/2")
    done = {(c["row"], c["column"]) for c in doc["cells"]}
    assert len(done) == 3
    p, doc = _sheet(scene, tmp_path, "--resume", "-o", tmp_path / "s.png")
    assert p.returncode == 0, p.stderr
    assert {(c["row"], c["column"]) for c in doc["cells"] if c["cached"]} == done
    p, doc = _sheet(scene, tmp_path, "-o", tmp_path / "s.png")
    assert not any(c["cached"] for c in doc["cells"])


@pytest.mark.external
def test_cells_are_shared_by_checkouts_in_other_folders(tmp_path, small_panoramas):
    """A cell's key holds its files' content, not their paths: a CI job whose checkout lies
    elsewhere renders the cells the other jobs assemble from one shared cache."""
    other = tmp_path / "elsewhere"
    other.mkdir()
    shutil.copy(small_panoramas["city"], other / "city.exr")
    p, doc = _sheet(sheet_scene(other, other / "city.exr", SWEEP), tmp_path, "--shard", "1/1")
    assert p.returncode == 0 and len(doc["cells"]) == 6, p.stderr
    p, doc = _sheet(sheet_scene(tmp_path, small_panoramas["city"], SWEEP), tmp_path, "--assemble",
                    "-o", tmp_path / "a.png")
    assert p.returncode == 0, p.stderr
    assert all(c["cached"] for c in doc["cells"])


@pytest.mark.external
def test_two_jobs_equal_the_serial_sheet(tmp_path, small_panoramas):
    """--jobs 2: two worker processes, each its own runtime; bakes built once in the shared cache;
    the sheet equals the serial one byte for byte."""
    scene = sheet_scene(tmp_path, small_panoramas["city"], SWEEP)
    p, _ = _sheet(scene, tmp_path / "serial", "-o", tmp_path / "serial.png")
    assert p.returncode == 0, p.stderr
    p, doc = _sheet(scene, tmp_path, "--jobs", "2", "-o", tmp_path / "j.png")
    assert p.returncode == 0, p.stderr
    assert len(doc["cells"]) == 6 and not any(c["cached"] for c in doc["cells"])
    assert (tmp_path / "j.png").read_bytes() == (tmp_path / "serial.png").read_bytes()
    # the chain baked once (by one worker, under the entry's lock), read by every other cell
    built = [c for c in doc["cells"] if "prefiltered" not in c["bakes_cached"]]
    print("cells that baked the prefiltered chain:", [(c["row"], c["column"]) for c in built])
    assert len(built) == 1


@pytest.mark.external
def test_time_captions_are_medians_of_warm_full_frames(tmp_path, small_panoramas):
    """--caption time times every cell as --repeat full frames after a warm-up (3 by default),
    the caption the median, --json every repeat; the cells' pixels are the untimed sheet's."""
    scene = sheet_scene(tmp_path, small_panoramas["city"], SWEEP)
    p, plain = _sheet(scene, tmp_path, "-o", tmp_path / "plain.exr")
    assert p.returncode == 0, p.stderr
    assert all(c["timing"] is None for c in plain["cells"])
    for args, k in (([], 3), (["--repeat", "2"], 2)):
        p, doc = _sheet(scene, tmp_path / f"t{k}", "-o", tmp_path / f"t{k}.exr", "--caption", "time", *args)
        assert p.returncode == 0, p.stderr
        for c in doc["cells"]:
            reps = c["timing"]["repeats"]
            assert len(reps) == k and all(x > 0 for x in reps)
            assert c["pass_seconds"] == pytest.approx(float(np.median(reps)), abs=1e-4)
        assert np.array_equal(images.read_exr(tmp_path / f"t{k}.exr"), images.read_exr(tmp_path / "plain.exr"))


@pytest.mark.external
@pytest.mark.parametrize("settings", [[], ["effects.tonemap=hable", "effects.exposure=0.7"],
                                      ["output.dither=true", "effects.output_transfer=gamma"],
                                      ["effects.tonemap=pbr_neutral", "effects.specular=importance"]])
def test_cells_equal_lone_renders_at_128(tmp_path, small_panoramas, settings):
    """The 2x3 sheet of issue 32 (128x128, roughness 0.2, 0.6 x metallic 0, 0.5, 1) at several
    display settings: every cell equals its `iblbake render` frame pixel for pixel. The lone frame
    builds the tone map into its one program, after kernels/scene.h turned FP contraction off; the
    sheet's tone map, in a program of its own, fused a multiply-add and put one pixel one code
    value off until tonemap.cl turned contraction off itself."""
    scene = sheet_scene(tmp_path, small_panoramas["city"], res=(128, 128))
    sets = [a for s in settings for a in ("--set", s)]
    p = run_cli("sheet", scene, "-o", tmp_path / "s.png", "--cache", tmp_path / "c", "--frames", tmp_path / "f",
                "--rows", "materials.gold.roughness=0.2,0.6", "--columns", "materials.gold.metallic=0,0.5,1", *sets)
    assert p.returncode == 0, p.stderr
    for r, rough in enumerate((0.2, 0.6)):
        for c, metal in enumerate((0, 0.5, 1)):
            lone = tmp_path / f"lone_{r}{c}.png"
            q = run_cli("render", scene, "-o", lone, "--cache", tmp_path / "c", "-q", *sets,
                        "--set", f"materials.gold.roughness={rough}", "--set", f"materials.gold.metallic={metal}")
            assert q.returncode == 0, q.stderr
            assert np.array_equal(read_png(tmp_path / "f" / f"r{r:02d}_c{c:02d}.png"), read_png(lone)), (r, c)


@pytest.mark.parametrize("timing", [None, "x", {"repeats": "x"}, {"repeats": [0.1, "a"]}, {"repeats": [-1.0]},
                                    {"repeats": None}])
def test_a_damaged_timing_in_a_cached_cell_counts_as_untimed(timing):
    """A cell read back from the cache takes its timed repeats from the entry's manifest: what is
    not a list of non-negative seconds there is ignored (the cell's own pass times are shown)."""
    frame = _Stub(np.zeros((2, 2, 3), np.uint8))
    frame.report = {"timing": timing, "passes": [{"seconds": 0.5}]}
    r = sheet.CellResult(sweep.Cell(0, 0, [], ""), frame=frame)
    assert r.repeats == [] and r.pass_seconds == 0.5
    frame.report["timing"] = {"repeats": [0.1, 0.3, 0.2]}
    assert r.repeats == [0.1, 0.3, 0.2] and r.pass_seconds == 0.2
