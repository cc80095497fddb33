"""`iblbake accuracy`: the Pareto frontier against brute force, the study on a small scene (its
reference's noise, errors falling with N and with SH bands, every report file), the CI guard."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from iblbake.io import images
from iblbake.study import accuracy, report

from tests.helpers import run_cli


def brute_force_front(points):
    return sorted((i for i, (t, e) in enumerate(points)
                   if not any((t2 <= t and e2 <= e) and (t2 < t or e2 < e) for t2, e2 in points)),
                  key=lambda i: points[i])


@pytest.mark.parametrize("seed", range(20))
def test_pareto_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    # a coarse grid makes ties in time and in error likely
    pts = [(float(t), float(e)) for t, e in zip(rng.integers(0, 8, n), rng.integers(0, 8, n))]
    pts = list(dict.fromkeys(pts))            # equal points: both or neither; keep one
    assert accuracy.pareto(pts) == brute_force_front(pts)


def test_pareto_frontier_of_a_table():
    rows = [{"term": "specular", "label": x, "time_s": t, "relative_rmse": e}
            for x, t, e in (("a", 1, 0.5), ("b", 2, 0.2), ("c", 3, 0.3), ("d", 4, 0.1), ("e", 0.5, 0.9))]
    assert accuracy.frontiers(rows) == {"specular": ["e", "a", "b", "d"]}


@pytest.fixture(scope="module")
def smooth_env(tmp_path_factory):
    """A smooth sky (a broad warm lobe over a cool gradient): SH converges on it, no sun."""
    h, w = 64, 128
    from iblbake.core import conventions
    d = conventions.equirect_texel_dirs(w, h)
    sun = np.array([0.4, 0.6, 0.7]) / np.linalg.norm([0.4, 0.6, 0.7])
    lobe = np.exp(4.0 * ((d @ sun) - 1))[..., None] * np.array([3.0, 2.2, 1.2])
    sky = (0.3 + 0.2 * d[..., 1:2]) * np.array([0.5, 0.7, 1.0])
    p = tmp_path_factory.mktemp("smooth") / "sky.exr"
    images.write_exr(p, (lobe + sky).astype(np.float32))
    return p


@pytest.fixture(scope="module")
def study(tmp_path_factory, smooth_env):
    d = tmp_path_factory.mktemp("study")
    scene = {"camera": {"perspective": {"position": [0, 0, 3], "fov_y": 45}, "resolution": [96, 96]},
             "environment": {"path": str(smooth_env), "rotation_y": 30},
             "materials": {"m": {"base_color": [0.8, 0.7, 0.6], "metallic": 0.5, "roughness": 0.5}},
             "objects": [{"sphere": {"radius": 1}, "material": "m"}],
             "effects": {"diffuse": "sh", "specular": "prefiltered"}}
    (d / "scene.yaml").write_text(yaml.safe_dump(scene))
    ladder = {"rungs": [{"key": "effects.samples", "values": [2, 8, 32, 128], "with": {"effects.specular": "importance"}},
                        {"key": "effects.sh_bands", "values": [1, 2, 3, 5]},
                        {"steps": [{"effects.specular": "lobe", "effects.lobe.samples": 4, "label": "lobe K=4"}]}]}
    (d / "ladder.yaml").write_text(yaml.safe_dump(ladder))
    cache = d / "cache"
    args = ("accuracy", d / "scene.yaml", "--ladder", d / "ladder.yaml", "--max-side", 40, "--repeats", 1,
            "--cache", cache, "--max-samples", 8192)
    r = run_cli(*args, "-o", d / "out", "--json")
    assert r.returncode == 0, r.stderr
    return {"dir": d, "args": args, "summary": json.loads(r.stdout)}


def rungs(summary, term):
    return [r for r in summary["rungs"] if r["term"] == term and not r["configured"]]


@pytest.mark.slow
def test_reference_noise_below_half_a_percent(study):
    for term in ("diffuse", "specular"):
        ref = study["summary"]["reference"][term]
        assert ref["noise"] < 0.005, ref
        assert 0 < ref["noise_bulk"] <= ref["noise"], ref
        assert ref["object_pixels"] > 500


def test_bulk_noise_leaves_out_the_worst_percent():
    """The study's noise_bulk (core/metrics.bulk_relative_rmse): the relative RMSE over the 99% of
    pixels that differ least, over the RMS of all. One pixel of 100 off by 10 is the whole
    relative RMSE (1) and none of the bulk's; a difference spread evenly is the same in both."""
    from iblbake.core.metrics import bulk_relative_rmse, relative_rmse
    b = np.ones((100, 3))
    a = b.copy()
    a[7] += 10
    assert relative_rmse(a, b) == pytest.approx(1.0) and bulk_relative_rmse(a, b) == 0.0
    assert bulk_relative_rmse(b + 0.1, b) == pytest.approx(0.1) == pytest.approx(relative_rmse(b + 0.1, b))
    assert bulk_relative_rmse(a[:0], b[:0]) == 0.0


def test_absolute_region_errors_read_brightness_and_colour():
    """core/metrics region_absolute (issue 59): a region 15x too bright reads ratio 15 (14 off),
    a region of the right brightness but turned blue reads ratio about 1 and its worst channel
    off, a region black in both (a metal's diffuse term) is left out, one of too few pixels too;
    halves splits a region by the side its normal faces."""
    from iblbake.core.metrics import halves, region_absolute
    ref = np.ones((4, 4, 4))
    got = ref.copy()
    regions = np.zeros((4, 4), int)
    regions[:, 2] = 1
    regions[:, 3] = 2
    got[:, :2, :3] *= 15                                   # region 0: 15x too bright
    got[:, 2, :3] = [0.8, 1.0, 3.3]                        # region 1: about as bright, bluer
    ref[:, 3, :3] = got[:, 3, :3] = 0                      # region 2: black in both
    mask = np.ones((4, 4), bool)
    e = region_absolute(got, ref, mask, regions)
    assert set(e) == {0, 1} and e[0]["pixels"] == 8 and e[1]["pixels"] == 4
    assert e[0]["ratio"] == pytest.approx(15) and e[0]["absolute"] == pytest.approx(14)
    assert e[1]["ratio"] == pytest.approx(0.2126 * 0.8 + 0.7152 + 0.0722 * 3.3)
    assert e[1]["channel"] == pytest.approx(2.3) == e[1]["absolute"]
    assert e[0]["tint"] == pytest.approx(0, abs=1e-12)      # as coloured as the truth: brighter only
    assert e[1]["tint"] == pytest.approx(np.abs(np.array([0.8, 1.0, 3.3]) / e[1]["ratio"] - 1).max())
    assert region_absolute(got, ref, mask, regions, min_pixels=5).keys() == {0}
    normals = np.zeros((4, 4, 3))
    normals[:2, :, 1], normals[2:, :, 1] = 1, -1           # upper rows face up, lower rows down
    parts = halves(normals, regions == 0, min_pixels=2)
    assert set(parts) == {"+y", "-y"} and parts["+y"].sum() == 4 and not (parts["+y"] & parts["-y"]).any()


def test_halves_too_small_to_judge_are_named():
    """Study.region_metrics, specular: a metal sphere's halves of 4 pixels or more are judged, one
    the camera sees in 2 pixels is named with its pixels in parts_left_out (corpus_absolute.py
    prints it beside the count) instead of vanishing."""
    from types import SimpleNamespace

    from iblbake.study.accuracy import Study
    regions = np.zeros((4, 4), int)
    normals = np.zeros((4, 4, 3))
    normals[..., 1] = 1
    normals[3, :2, 1], normals[3, :2, 0] = 0, 1           # two pixels face +x (and up, none)
    ref = np.ones((4, 4, 4))
    fake = SimpleNamespace(object_regions=lambda: regions, _normals=normals, metal_objects=lambda: [0],
                           scene=SimpleNamespace(data={"objects": [{"sphere": {}, "name": "gold"}]}))
    out = Study.region_metrics(fake, ref, ref, np.ones((4, 4), bool), "specular")
    assert set(out["part_absolute"]) == {"'gold' (objects.0) +y"}
    assert out["parts_left_out"] == {"'gold' (objects.0) +x": 2}


def test_edge_over_interior_reads_a_seam_of_one_pixel():
    """core/metrics edge_over_interior (issue 59, "no seams"): a floor (rows below 8) and a wall
    of one mesh (one region; the junction found by the normals' turn) or two, the frame right
    inside and 1.3x bright in the one-pixel rows either side of the junction: 1.3 where the region
    means move 8%; no seam: 1; a frame uniformly 2x bright: 1 (a seam is relative to the
    interior). A sphere's smooth normals (4 degrees a pixel) make no junction: None."""
    from iblbake.core.metrics import edge_over_interior, junctions, luminance
    h, w = 16, 20
    ref = np.ones((h, w, 4))
    ref[8:, :, :3] = 0.5                                   # the floor darker than the wall
    normals = np.zeros((h, w, 3))
    normals[:8, :, 2], normals[8:, :, 1] = 1, 1            # wall faces +z, floor +y
    mask = np.ones((h, w), bool)
    for regions in (np.zeros((h, w), int), np.repeat((np.arange(h) >= 8)[:, None], w, 1).astype(int)):
        j = junctions(mask, regions, normals)
        assert j.sum() == 2 * w and j[7].all() and j[8].all()
        assert edge_over_interior(ref, ref, mask, regions, normals) == pytest.approx(1)
        assert edge_over_interior(2 * ref, ref, mask, regions, normals) == pytest.approx(1)
        got = ref.copy()
        got[7:9, :, :3] *= 1.3
        assert edge_over_interior(got, ref, mask, regions, normals) == pytest.approx(1.3)
        assert luminance(got[:8, :, :3]).mean() / luminance(ref[:8, :, :3]).mean() == pytest.approx(1 + 0.3 / 8)
        got[:2, :, :3] *= 3          # interior: rows 0-3 (wall, 1) and 12-15 (floor, 0.5); rows 0-1 3x
        assert edge_over_interior(got, ref, mask, regions, normals) == pytest.approx(1.3 / (10 / 6))
    a = np.deg2rad(4) * np.arange(w)[None, :] + 0 * np.arange(h)[:, None]
    sphere = np.stack([np.sin(a), np.zeros_like(a), np.cos(a)], -1)
    assert not junctions(mask, np.zeros((h, w), int), sphere).any()
    assert edge_over_interior(ref, ref, mask, np.zeros((h, w), int), sphere) is None


@pytest.mark.slow           # over 3 s on the 2-core CPU (with its module's study): make test, not make check
def test_error_falls_with_samples_and_bands(study):
    """Monotonic within twice the reference's noise."""
    s = study["summary"]
    for term, key in (("specular", "effects.samples"), ("diffuse", "effects.sh_bands")):
        sel = sorted((r for r in rungs(s, term) if key in r["values"]), key=lambda r: r["values"][key])
        errs = [r["relative_rmse"] for r in sel]
        slack = 2 * s["reference"][term]["noise"]
        assert len(errs) == 4 and all(b <= a + slack for a, b in zip(errs, errs[1:])), (term, errs)
        assert errs[-1] < errs[0] / 2, (term, errs)


@pytest.mark.slow           # over 3 s on the 2-core CPU (with its module's study): make test, not make check
def test_report_files(study):
    s, out = study["summary"], study["dir"] / "out"
    assert len(s["rungs"]) == 2 + 4 + 4 + 1                  # the configured setting of each term first
    with open(out / "table.csv") as f:
        table = list(csv.DictReader(f))
    assert [r["label"] for r in table] == [r["label"] for r in s["rungs"]]
    for r, row in zip(s["rungs"], table):
        for k in ("time_s", "bake_s", "relative_rmse", "mean_relative_error", "max_relative_error", "flip"):
            assert r[k] is not None and np.isfinite(r[k]), (r["label"], k)
        assert float(row["relative_rmse"]) == pytest.approx(r["relative_rmse"])
        assert float(row["time_ms"]) == pytest.approx(1000 * r["time_s"])
    assert json.loads((out / "accuracy.json").read_text())["rungs"] == s["rungs"]
    md = (out / "table.md").read_text().splitlines()
    assert len(md) == 2 + len(s["rungs"])
    import OpenImageIO as oiio
    spec = oiio.ImageInput.open(str(out / "plot.png")).spec()
    assert (spec.width, spec.height) == report.PLOT_SIZE
    # the 40-pixel study frames are enlarged until every caption fits under its cell (they were cut)
    from iblbake.study import sheet
    caption = f"{s['reference']['diffuse']['samples_per_pixel'][0]} spp, noise 0.00%"
    assert oiio.ImageInput.open(str(out / "errors.png")).spec().width > 5 * sheet.text_width(caption, sheet.CAPTION_PT)
    front = s["frontier"]
    assert set(front) == {"diffuse", "specular"} and all(front.values())


@pytest.mark.slow           # over 3 s on the 2-core CPU (with its module's study): make test, not make check
def test_reference_is_cached_and_max_error_guards(study):
    """A second study reuses the reference; --max-error above the configured frame's error
    passes, below it fails in one line."""
    s = study["summary"]
    err = s["configured"]["relative_rmse"]
    assert 0 < err < 1
    r = run_cli(*study["args"], "--json", "--max-error", err * 1.01)
    assert r.returncode == 0, r.stderr
    again = json.loads(r.stdout)
    assert all(all(again["reference"][t]["cached"]) for t in ("diffuse", "specular"))
    assert again["reference"]["specular"]["noise"] == s["reference"]["specular"]["noise"]
    r = run_cli(*study["args"], "-q", "--max-error", err * 0.99)
    assert r.returncode == 1
    assert "--max-error" in r.stderr and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


@pytest.mark.slow           # over 3 s on the 2-core CPU (with its module's study): make test, not make check
def test_bad_ladder_is_one_line(tmp_path, study):
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"rungs": [{"key": "effects.sampels", "values": [1]}]}))
    args = list(study["args"])
    args[args.index("--ladder") + 1] = bad
    r = run_cli(*args, "-q")
    assert r.returncode != 0 and "effects.sampels" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_references_in_two_workers_equal_the_serial_ones(tmp_path, study):
    """--jobs 2 on a fresh cache: the four reference seeds render in two worker processes, the
    study reads them back, and its noise and every rung's error are the serial study's (the
    references are seeded: the same on any process)."""
    args = list(study["args"])
    args[args.index("--cache") + 1] = tmp_path / "cache"
    r = run_cli(*args, "--json", "--jobs", "2")
    assert r.returncode == 0, r.stderr
    got, s = json.loads(r.stdout), study["summary"]
    spread = got["reference_workers"]
    assert sum(w["references"] for w in spread["workers"]) == 4 and spread["jobs"] == 2
    assert all(all(got["reference"][t]["cached"]) for t in ("diffuse", "specular"))
    assert got["reference"]["specular"]["noise"] == s["reference"]["specular"]["noise"]
    assert [x["relative_rmse"] for x in got["rungs"]] == [x["relative_rmse"] for x in s["rungs"]]


@pytest.mark.slow           # over 3 s on the 2-core CPU (with its module's study): make test, not make check
def test_plot_legend_hides_no_point_and_tick_labels_do_not_overlap(study):
    """plot.png kept its legend inside the upper right of each panel (over a point) and labelled
    the minor ticks of a log axis spanning less than a decade, one over another."""
    import matplotlib.pyplot as plt

    s = study["summary"]
    fig = report.plot_figure(s["rungs"], s["frontier"], "t")
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    assert len(fig.legends) == 1
    legend = fig.legends[0].get_window_extent(r)
    for ax in fig.axes:
        assert ax.get_legend() is None and not legend.overlaps(ax.get_window_extent(r))
        for axis in (ax.xaxis, ax.yaxis):
            boxes = [t.get_window_extent(r) for t in axis.get_ticklabels(which="both")
                     if t.get_visible() and t.get_text()]
            assert boxes, axis
            assert not any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])
    plt.close(fig)


def test_ladder_has_direct_only_where_paths_run(tmp_path, smooth_env):
    """The study's reference traces every bounce (Study.paths) where light passes between
    surfaces, and then the ladder measures "direct only" (bounces 1), GTAO's multi-bounce fit and
    the irradiance probes: a sphere on a floor has them; a lone sphere, --no-visibility and
    --bounces 1 none."""
    from iblbake.device.runtime import Runtime
    from iblbake.render import Bakes
    from iblbake.study import ladder

    def study_of(objects, **settings):
        p = tmp_path / "s.yaml"
        p.write_text(yaml.safe_dump({
            "camera": {"perspective": {"position": [0, 1, 4], "fov_y": 45}, "resolution": [64, 48]},
            "environment": {"path": str(smooth_env)}, "materials": {"m": {"roughness": 0.5}},
            "objects": [{**o, "material": "m"} for o in objects], "effects": {"diffuse": "sh", "specular": "prefiltered"}}))
        st = accuracy.Study(p, (), accuracy.Settings(**settings), runtime=Runtime(), bakes=Bakes(tmp_path / "c"))
        labels = [r.label for r in ladder.default_ladder(st.scene, st.fx, "CPU", paths=st.paths)]
        return (st.paths, labels.count("direct only 256 spp"), labels.count("ao gtao multibounce"),
                sum(x.startswith("probes") for x in labels))

    sphere, floor = {"sphere": {"center": [0, 0.5, 0], "radius": 0.5}}, {"plane": {"point": [0, 0, 0], "size": 4}}
    assert study_of([sphere, floor]) == (True, 2, 1, 7)
    assert study_of([sphere]) == (False, 0, 0, 0)
    assert study_of([sphere, floor], visibility=False) == (False, 0, 0, 0)
    assert study_of([sphere, floor], bounces=1) == (False, 0, 0, 0)


@pytest.mark.slow
def test_study_reference_converges_where_direct_light_falls_short(tmp_path, smooth_env):
    """A white Lambert sphere on a white floor: the study's reference traces every bounce, so
    the direct-light reference at 256 spp is further from it than its own noise allows (the
    light the two exchange: measured 17.3% relative RMSE, the reference's noise 0.25%), while the
    path-traced reference at 256 spp (another seed) is off by its noise alone (measured 1.6%)."""
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump({
        "camera": {"perspective": {"position": [0, 1.2, 3.5], "look_at": [0, 0.4, 0], "fov_y": 40},
                   "resolution": [48, 36]},
        "environment": {"path": str(smooth_env)},
        "materials": {"w": {"base_color": [0.9, 0.9, 0.9], "roughness": 1, "specular": 0}},
        "objects": [{"sphere": {"center": [0, 0.5, 0], "radius": 0.5}, "material": "w"},
                    {"plane": {"point": [0, 0, 0], "size": 4}, "material": "w"}],
        "effects": {"diffuse": "sh", "specular": "off"}}))
    lad = tmp_path / "l.yaml"
    lad.write_text(yaml.safe_dump({"rungs": [{"steps": [
        {"effects.diffuse": "reference", "effects.reference.bounces": b, "effects.reference.max_samples": 256,
         "effects.reference.target_noise": 0, "effects.reference.seed": 7, "label": str(b)}
        for b in (1, "unbounded")]}]}))
    r = run_cli("accuracy", p, "--ladder", lad, "--repeats", 1, "--no-flip", "--cache", tmp_path / "c", "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    ref = s["reference"]["diffuse"]
    err = {x["label"]: x["relative_rmse"] for x in s["rungs"] if not x["configured"]}
    print(f"reference noise {ref['noise']:.4f}; direct {err['1']:.4f}, converged 256 spp {err['unbounded']:.4f}")
    assert ref["bounces"] == "unbounded"
    assert ref["noise"] < 0.005
    assert 0.14 < err["1"] < 0.21
    assert err["unbounded"] < 0.03


@pytest.mark.slow
def test_probes_beat_sh_with_gtao_in_the_open_box(tmp_path, panoramas):
    """The gallery's open box (examples/sheets/bounces.yaml: coloured walls, courtyard), diffuse
    alone against the converged reference: irradiance probes carry the walls' light, SH with GTAO
    only darkens (measured at 96 px, 1024 spp: probes 8 at 8.7%, SH with GTAO 41.8%; the issue
    asks for a factor of 2), and the study reports the probes' bake apart from their time."""
    box = Path(__file__).resolve().parents[1] / "examples" / "sheets" / "bounces.yaml"
    lad = tmp_path / "l.yaml"
    lad.write_text(yaml.safe_dump({"rungs": [{"term": "diffuse", "steps": [
        {"effects.diffuse": "sh", "effects.ao": "gtao", "label": "SH + gtao"},
        {"effects.diffuse": "probes", "probes.counts": 8, "label": "probes 8"}]}]}))
    r = run_cli("accuracy", box, "--ladder", lad, "--set", "effects.specular=off", "--max-side", 96,
                "--max-samples", 1024, "--repeats", 1, "--no-flip", "--cache", tmp_path / "c", "--json")
    assert r.returncode == 0, r.stderr
    rungs = {x["label"]: x for x in json.loads(r.stdout)["rungs"] if not x["configured"]}
    sh_gtao, probe = rungs["SH + gtao"]["relative_rmse"], rungs["probes 8"]["relative_rmse"]
    print(f"SH + gtao {sh_gtao:.4f}, probes 8 {probe:.4f}")
    assert probe < 0.13 and sh_gtao > 2 * probe
    assert [b["name"] for b in rungs["probes 8"]["bakes"]][-1] == "probes" and rungs["probes 8"]["bake_s"] > 0


def test_a_black_reference_is_said_not_divided_by(tmp_path):
    """A scene no light reaches (a black panorama): every relative error would divide by zero (a new
    user's closed room printed 1.5e301% on every row); the study says so in one line, naming the
    term and what to do, and exits 1."""
    from tests.helpers import scene_file, write_exr
    env = write_exr(tmp_path / "black.exr", np.zeros((8, 16, 3), np.float32))
    p = scene_file(tmp_path, env, camera={"perspective": {"position": [0, 0, 3], "fov_y": 45}, "resolution": [16, 16]},
                   effects={"diffuse": "sh", "specular": "off"})
    r = run_cli("accuracy", p, "--repeats", 1, "--no-flip", "--max-samples", 16, "--cache", tmp_path / "c")
    assert r.returncode == 1 and "Traceback" not in r.stderr
    line = [x for x in r.stderr.splitlines() if x.startswith("Error")]
    assert len(line) == 1 and "diffuse term's reference is black" in line[0] and "effects.diffuse=off" in line[0], r.stderr


@pytest.mark.slow           # over 3 s on the 2-core CPU (with its module's study): make test, not make check
def test_report_page_holds_every_rung(study):
    """index.html (iblbake/study/html.py): each term's reference and every rung, each image the
    frame and mask its metrics read: the relative RMSE recomputed from the page's float16 data is
    the table's (float16 rounding moves it by about 1e-4 of itself)."""
    from iblbake.core.metrics import relative_rmse
    from tests.helpers import decode, manifest_of

    s, out = study["summary"], study["dir"] / "out"
    m = manifest_of(out / "index.html")
    refs = [e for e in m["entries"] if e["is_reference"]]
    assert [e["label"] for e in refs] == ["reference diffuse", "reference specular"]
    rungs_shown = [e for e in m["entries"] if not e["is_reference"]]
    assert [(e["term"], e["label"]) for e in rungs_shown] == [(r["term"], r["label"]) for r in s["rungs"]]
    images_ = [decode(out / e["file"], (m["height"], m["width"])) for e in m["entries"]]
    for e, r, (rgb, mask) in zip(rungs_shown, s["rungs"], images_[len(refs):]):
        ref = images_[e["reference"]][0]
        assert m["entries"][e["reference"]]["term"] == r["term"]
        got = relative_rmse(rgb[mask].astype(float), ref[mask].astype(float))
        assert got == pytest.approx(r["relative_rmse"], rel=5e-4, abs=5e-5), r["label"]
        assert e["row"]["relative_rmse"] == pytest.approx(r["relative_rmse"])
        assert e["regions"] == r["region_errors"]


def test_a_study_says_each_warning_once_per_rung(tmp_path, panoramas, rt):
    """A new user's trial: each rung printed the panorama's chromaticity warning and the probes'
    share outside their volume twice (the rung's warm-up render and its timed one each said them).
    A sphere under city (it declares non-Rec.709 chromaticities) with its probe box over its left
    half: the first rung says each of the two once; a second rung says the probes' share again, not
    the panorama's chromaticities, which no rung changes (trial72: five times a study)."""
    from iblbake.render.bakes import Bakes
    from iblbake.study.ladder import Rung

    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump({
        "camera": {"perspective": {"position": [0, 0, 3], "fov_y": 40}, "resolution": [16, 16]},
        "environment": {"path": str(panoramas["city"])},
        "materials": {"m": {"base_color": [0.8, 0.6, 0.4], "roughness": 1, "specular": 0}},
        "objects": [{"sphere": {"radius": 0.8}, "material": "m"}],
        "probes": {"min": [-1.9, -2, -2], "max": [-0.1, 2, 2], "counts": [2, 2, 2], "rays": 256},
        "effects": {"diffuse": "probes", "specular": "off"}}))
    said = []
    st = accuracy.Study(p, (), accuracy.Settings(max_side=16, repeats=1, max_samples=16, flip=False),
                        runtime=rt, bakes=Bakes(tmp_path / "c"), warn=said.append)
    st.render_reference("diffuse")
    assert sum("chromaticities" in m for m in said) == 1, said
    for label in ("probes", "probes again"):
        del said[:]
        st.run_rung(Rung("diffuse", label, [("effects.diffuse", "probes")]))
        assert len(said) == 1 and "outside the probe volume" in said[0], said


def test_a_saturated_spheres_worst_channel_is_its_brightness():
    """A new user's trial: coloured Lambert spheres' worst channel 24-33% off while their luminance
    was within 20%. Measured (64 px, CPU, studio): a blue sphere [0.3, 0.3, 0.8] in a corridor,
    each channel x1.203, x1.202, x1.175 of the converged reference's [0.566, 0.659, 1.775] (its
    mean 1): the worst channel 31% is its luminance's 20% times blue's 1.775 over the mean; the
    colour itself is near (tint 3%: blue 1.8% under the luminance, times 1.775)."""
    from iblbake.core.metrics import mean_errors
    truth = np.array([0.566, 0.659, 1.775])
    e = mean_errors(truth * [1.203, 1.202, 1.175], truth)
    assert e["ratio"] == pytest.approx(1.197, abs=2e-3) and e["channel"] == pytest.approx(0.310, abs=2e-3)
    assert e["tint"] == pytest.approx(0.033, abs=2e-3) and e["absolute"] == e["channel"]
