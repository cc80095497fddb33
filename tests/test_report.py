"""The interactive report (iblbake/study/html.py, iblbake/study/page/): its data files, the
overwrite rule for its outputs, and the page itself driven in headless Chromium through
puppeteer-core (tests/node/report_page.cjs): no console error, the tone mapping of
iblbake/core/tonemap.py to the last bit, the A/B flip, the exposure, the pixel readout against
the EXR, the plot linked to the table, and a large study's size and open time."""

import json
import shutil
import subprocess
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from iblbake.core import tonemap
from iblbake.io import atomic, images
from iblbake.study import html

from tests.helpers import decode, manifest_of, run_cli, scene_file

NODE = Path(__file__).parent / "node"
CHROMIUM = "/usr/bin/chromium"
FX = {"tonemap": "aces", "exposure": 0.0, "output_transfer": "srgb", "gamma": 2.2}


def synthetic_page(folder, n=6, w=40, h=24, seed=1, title="synthetic", radius=0.2):
    """A study's page without a study: a reference and n - 1 noisy rungs of a lit disk (its
    radius a fraction of the longer side), the rungs' error falling with their time (every third
    on the frontier)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w] / max(w, h)
    base = np.stack([0.2 + 4 * xx, 0.05 + 2 * yy, 0.3 + xx * yy], -1)
    mask = (xx - 0.5 * w / max(w, h)) ** 2 + (yy - 0.5 * h / max(w, h)) ** 2 < radius ** 2
    entries = [html.Entry("reference diffuse", base * mask[..., None], mask, "diffuse", None, True,
                          {"term": "diffuse", "label": "reference"})]
    for i in range(n - 1):
        img = base * (1 + rng.normal(0, 0.3 / (i + 1), base.shape)) * mask[..., None]
        entries.append(html.Entry(f"rung {i}", img, mask, "diffuse", 0, False,
                                  {"term": "diffuse", "label": f"rung {i}", "time_ms": 0.1 * (i + 1),
                                   "relative_rmse": 0.3 / (i + 1), "pareto": i % 3 == 0},
                                  {"objects.0 (sphere)": 0.1 / (i + 1)}))
    page = html.Page(title, entries, FX, objects=np.where(mask, 0, -1), object_names=["objects.0 (sphere)"])
    with atomic.Batch() as b:
        html.write(folder, page, b)
    return page


def test_data_files_hold_the_float16_frames_and_masks(tmp_path):
    page = synthetic_page(tmp_path, n=3, title="a </script><b>title")
    for i, e in enumerate(page.entries):
        path = tmp_path / "report" / f"{i:04d}.js"
        assert path.read_text().startswith("// iblbake ")          # the overwrite rule's mark
        rgb, mask = decode(path, e.hdr.shape[:2])
        np.testing.assert_array_equal(rgb, e.hdr.astype(np.float16))
        np.testing.assert_array_equal(mask, e.mask)
    # a sun's pixel above float16's range is its largest value, not infinity; NaN is black
    hdr = np.array([[[1e6, np.nan, 0.5]]], np.float32)
    raw = zlib.decompress(html.pack(hdr, None))
    np.testing.assert_array_equal(np.frombuffer(raw[:6], np.uint8).reshape(2, -1).T.copy().view("<f2").ravel(),
                                  np.array([65504, 0, 0.5], np.float16))
    from iblbake.io.guard import written_by_iblbake          # the overwrite rule knows them
    assert written_by_iblbake(tmp_path / "index.html") and written_by_iblbake(tmp_path / "report" / "0002.js")
    index = (tmp_path / "index.html").read_text()
    assert index.split("\n", 1)[0].startswith("<!DOCTYPE html><!-- iblbake ")
    assert "</script><b>" not in index and "<\\/script><b>title" in index      # the title cannot end the script
    assert len(index) < 60_000                      # no pixels inline: the script, style and labels


@pytest.fixture(scope="module")
def sky(tmp_path_factory):
    v, u = np.meshgrid((np.arange(32) + 0.5) / 32, (np.arange(64) + 0.5) / 64, indexing="ij")
    img = np.stack([1 + 0.8 * np.cos(2 * np.pi * u), 1 + 0.6 * np.cos(np.pi * v), 1 + 0.5 * np.sin(2 * np.pi * u)], -1)
    p = tmp_path_factory.mktemp("sky") / "sky.exr"
    images.write_exr(p, img.astype(np.float32))
    return p


@pytest.mark.parametrize("name", ["index.html", "report/0001.js"])
def test_accuracy_refuses_a_foreign_report_file(tmp_path, sky, name):
    """-o DIR replaces index.html and its data only where iblbake wrote them (before any render)."""
    scene = scene_file(tmp_path, sky, effects={"specular": "off"})
    (tmp_path / "out" / "report").mkdir(parents=True)
    (tmp_path / "out" / name).write_text("someone's page\n")
    r = run_cli("accuracy", scene, "--max-side", 16, "--repeats", 1, "-o", tmp_path / "out", "--cache", tmp_path / "c")
    assert r.returncode == 1, r.stderr
    assert f"{tmp_path / 'out' / name}: exists and is not a file iblbake wrote" in r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "c").exists()       # refused before rendering


def test_sheet_html_refuses_a_foreign_index(tmp_path, sky):
    scene = scene_file(tmp_path, sky)
    (tmp_path / "page").mkdir()
    (tmp_path / "page" / "index.html").write_text("<html>mine</html>\n")
    r = run_cli("sheet", scene, "--columns", "effects.sh_bands=1,3", "-o", tmp_path / "s.png", "--html",
                tmp_path / "page", "--cache", tmp_path / "c")
    assert r.returncode == 1, r.stderr
    assert "--html" in r.stderr and "index.html: exists and is not a file iblbake wrote" in r.stderr
    assert (tmp_path / "page" / "index.html").read_text() == "<html>mine</html>\n"


# ---- in the browser ----

@pytest.fixture(scope="module")
def browser():
    if (shutil.which("node") is None or not (NODE / "node_modules" / "puppeteer-core").is_dir()
            or not Path(CHROMIUM).exists()):
        pytest.skip("puppeteer-core and Chromium are not set up: run `make readers` (make test does)")

    def drive(index, steps, tmp, errors=False):
        spec = Path(tmp) / f"steps-{time.monotonic_ns()}.json"
        spec.write_text(json.dumps(steps))
        p = subprocess.run(["node", str(NODE / "report_page.cjs"), str(index), str(spec)],
                           capture_output=True, text=True, timeout=120)
        assert p.returncode == 0, p.stderr
        out = json.loads(p.stdout)
        assert errors or out["errors"] == []        # no console error, no failed load
        return out
    return drive


def shown(page, i, ev=0.0, operator="aces"):
    """What `render` writes for entry i's HDR (as the page holds it: float16), 8-bit."""
    return tonemap.to_u8(tonemap.tonemap(page.entries[i].hdr.astype(np.float16).astype(np.float64),
                                         operator, ev, "srgb", 2.2)).astype(int)


@pytest.mark.external
def test_the_page_tone_maps_as_render_does(tmp_path, browser):
    """The page's port of tonemap.py against numpy's, every operator and transfer, on values from
    black to past the input cap: the same float64 arithmetic, to rounding."""
    synthetic_page(tmp_path, n=2)
    values = [0.0, 1e-6, 0.003, 0.04, 0.18, 0.5, 1.0, 2.0, 7.5, 11.2, 100.0, 1e5, 1e20, -1.0]
    rgbs = [[v, 0.5 * v + 0.01, 2 * v] for v in values]
    cases = [(op, ev, tr, g) for op in tonemap.OPERATORS for ev, tr, g in ((0, "srgb", 2.2), (1.5, "gamma", 2.4))]
    out = browser(tmp_path / "index.html", [{"eval": f"{json.dumps(cases)}.map(([op, ev, tr, g]) => "
                                                     f"{json.dumps(rgbs)}.map((c) => IBL.tonemap(c, op, ev, tr, g)))"}],
                  tmp_path)
    got = np.array(out["results"][0])
    want = np.array([tonemap.tonemap(np.array(rgbs), op, ev, tr, g) for op, ev, tr, g in cases])
    assert np.abs(got - want).max() < 1e-12


@pytest.mark.external
def test_flip_and_exposure_show_what_render_writes(tmp_path, browser):
    """Pane A shows the rung as `render` tone-maps it (within 1/255); the A/B flip (space) puts
    the reference's pixels there; +1 EV under the linear operator doubles the displayed linear
    value, read back from the canvas."""
    page = synthetic_page(tmp_path, n=3)
    ys, xs = np.nonzero(page.entries[0].mask)
    px = [(int(x), int(y)) for x, y in zip(xs[::17], ys[::17])]
    read = {"eval": f"{json.dumps(px)}.map(([x, y]) => IBL.displayed('paneA', x, y))"}
    out = browser(tmp_path / "index.html",
                  [{"eval": "[IBL.state.a, IBL.state.b]"}, read, {"key": " "}, read, {"key": " "},
                   {"eval": "document.getElementById('operator').value = 'linear', "
                            "document.getElementById('operator').dispatchEvent(new Event('change')), IBL.exposure(-2), "
                            "IBL.render().then(() => true)"}, read,
                   {"eval": "IBL.exposure(-1), IBL.render().then(() => true)"}, read], tmp_path)
    res = out["results"]
    assert res[0] == [1, 0]                          # A the first rung, B its reference
    at = tuple(np.array(px).T[::-1])
    assert np.abs(np.array(res[1]) - shown(page, 1)[at]).max() <= 1
    assert np.abs(np.array(res[3]) - shown(page, 0)[at]).max() <= 1      # flipped: the reference
    assert np.abs(np.array(res[6]) - shown(page, 1, -2, "linear")[at]).max() <= 1
    lo, hi = (np.array(res[k], float) / 255 for k in (6, 8))

    def linear(v):
        return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)
    ok = (lo > 0.2) & (hi < 0.95)                    # 8-bit steps small against the value, no clip
    assert ok.sum() > 20
    ratio = linear(hi[ok]) / linear(lo[ok])
    # 8 bits round each value by at most half a step: sRGB's 2.4 power turns that into a relative
    # error of 2.4 * (0.5 / 255) / (v + 0.055) in the linear value, either way in each of the two
    steps = 2.4 * (0.5 / 255) * (1 / (lo[ok] + 0.055) + 1 / (hi[ok] + 0.055))
    assert np.all(np.abs(ratio / 2 - 1) <= 1.05 * steps)


@pytest.mark.external
def test_plot_points_and_table_select_rungs(tmp_path, browser):
    """Clicking a plot point shows that rung (pane A's caption, the table's row); shift-click
    makes it B; the table sorts by a column on a click of its header; hovering a point shows its
    rung until the cursor leaves it."""
    page = synthetic_page(tmp_path, n=6)
    out = browser(tmp_path / "index.html",
                  [{"eval": "document.querySelectorAll('#plot circle').length"},
                   {"click": "#plot circle[data-entry='4']"},
                   {"eval": "[IBL.state.a, document.getElementById('capA').textContent, "
                            "document.querySelector('#table tr.sel').dataset.entry]"},
                   {"click": "#plot circle[data-entry='2']", "shift": True},
                   {"eval": "[IBL.state.a, IBL.state.b]"},
                   {"click": "#table th[data-key='relative_rmse']"},
                   {"eval": "[...document.querySelectorAll('#table tbody tr')].map((r) => +r.dataset.entry)"},
                   {"key": "ArrowDown"}, {"eval": "IBL.state.a"},
                   {"move": True, "selector": "#plot circle[data-entry='1']", "fx": 0.5, "fy": 0.5},
                   {"eval": "[IBL.state.a, document.getElementById('capA').textContent]"},
                   {"move": True, "selector": "#table", "fx": 0.5, "fy": 0.5},
                   {"eval": "document.getElementById('capA').textContent"}], tmp_path)
    res = out["results"]
    assert res[0] == 5                               # every rung, not the reference
    assert res[2] == [4, f"A: diffuse: {page.entries[4].label}", "4"]
    assert res[4] == [4, 2]
    assert res[6] == [5, 4, 3, 2, 1]                 # by increasing error
    assert res[8] == 3                               # the next row in the table's order
    assert res[10] == [3, "A: diffuse: rung 0"]      # hovering a point shows it, selecting nothing
    assert res[12] == "A: diffuse: rung 2"           # and leaving it shows the selected rung again


@pytest.mark.external
@pytest.mark.slow
def test_sheet_page_reads_out_the_exr_values(tmp_path, sky, browser):
    """`sheet --html`: the page's pixel readout of A and B is each cell's EXR (--frames-exr) to
    float16's precision."""
    scene = scene_file(tmp_path, sky, materials={"base_color": [0.8, 0.5, 0.3], "roughness": 0.4, "metallic": 0.3})
    r = run_cli("sheet", scene, "--columns", "effects.sh_bands=1,3", "--cell-size", "24x24", "-o", tmp_path / "s.png",
                "--frames", tmp_path / "fr", "--frames-exr", "--html", tmp_path / "page", "--cache", tmp_path / "c")
    assert r.returncode == 0, r.stderr
    px = [(12, 12), (5, 13), (17, 8)]
    out = browser(tmp_path / "page" / "index.html",
                  [{"eval": f"{json.dumps(px)}.map(([x, y]) => (IBL.readout(x, y), "
                            "[document.getElementById('roA').textContent, document.getElementById('roB').textContent]))"}],
                  tmp_path)
    heads = manifest_of(tmp_path / "page" / "index.html")["columns"]
    assert ["column", "column: effects.sh_bands"] in heads     # the table names the swept key
    keys = browser(tmp_path / "page" / "index.html", [{"eval": "document.getElementById('keys').textContent"}],
                   tmp_path)["results"][0]
    assert "next cell" in keys and "plot" not in keys and "reference" not in keys
    cells = [images.read_exr(tmp_path / "fr" / f"r00_c{c:02d}.exr") for c in (0, 1)]
    for (x, y), lines in zip(px, out["results"][0]):
        for line, exr in zip(lines, cells):
            vals = [float(v) for v in line.split(": ", 1)[1].split()[:3]]
            want = exr[y, x, :3]
            assert want.min() > 0.01
            np.testing.assert_allclose(vals, want, rtol=1e-3)    # float16: 2^-11 relative


@pytest.mark.external
@pytest.mark.slow
def test_a_study_of_80_rungs_is_small_and_opens_in_a_second(tmp_path, browser):
    """80 rungs at 320 x 180: the folder's size, and the time from navigation to the first
    images drawn (the best of two loads, the CPU being shared)."""
    synthetic_page(tmp_path, n=80, w=320, h=180)
    size = sum(p.stat().st_size for p in tmp_path.rglob("*") if p.is_file())
    assert size < 5.0e6                              # measured 4.86 MB (docs/manual.md)
    assert (tmp_path / "index.html").stat().st_size < 60_000
    best = min(browser(tmp_path / "index.html", [], tmp_path)["open_ms"] for _ in range(2))
    assert best < 1000                               # measured 250-350 ms


@pytest.mark.external
def test_error_map_and_split(tmp_path, browser):
    """The error pane is errors.png's error image (metrics.error_image: magma over |dL| / L to
    50%) of the page's float16 data, and the absolute map (`e`) |dL| over half the reference's
    mean luminance; the split shows A left of its line and B right of it."""
    from matplotlib import colormaps

    from iblbake.core.metrics import error_image, luminance
    page = synthetic_page(tmp_path, n=3)
    a, b = (page.entries[i].hdr.astype(np.float16).astype(np.float64) for i in (1, 0))
    mask = page.entries[1].mask
    ys, xs = np.nonzero(mask)
    px = [(int(x), int(y)) for x, y in zip(xs[::13], ys[::13])]
    read = {"eval": f"{json.dumps(px)}.map(([x, y]) => IBL.displayed('paneE', x, y))"}
    row = np.nonzero(mask[12])[0]                    # the disk's middle row: either side of the line
    split = [(int(row[1]), 12), (int(row[-2]), 12)]
    out = browser(tmp_path / "index.html",
                  [read, {"key": "e"}, read, {"key": "s"},
                   {"eval": f"{json.dumps(split)}.map(([x, y]) => IBL.displayed('paneA', x, y))"}], tmp_path)
    at = tuple(np.array(px).T[::-1])
    np.testing.assert_array_equal(np.array(out["results"][0]), error_image(a, b, mask)[at])
    la, lb = luminance(a), luminance(b)
    top = 0.5 * lb[mask].mean()
    j = np.minimum(np.floor(np.clip(np.abs(la - lb) / top, 0, 1) * 256), 255).astype(int)
    lut = (colormaps["magma"](np.linspace(0, 1, 256))[:, :3] * 255 + 0.5).astype(int)
    np.testing.assert_array_equal(np.array(out["results"][2]), lut[j][at])
    (lx, ly), (rx, ry) = split
    left, right = out["results"][4]
    assert np.abs(np.array(left) - shown(page, 1)[ly, lx]).max() <= 1
    assert np.abs(np.array(right) - shown(page, 0)[ry, rx]).max() <= 1
    assert np.abs(shown(page, 1)[ly, lx] - shown(page, 0)[ly, lx]).max() > 1 or \
        np.abs(shown(page, 1)[ry, rx] - shown(page, 0)[ry, rx]).max() > 1      # A and B differ there


@pytest.mark.external
def test_zoom_is_shared_and_nearest_neighbour(tmp_path, browser):
    """Wheel turns over pane A zoom every pane about the cursor: the image pixel under it stays,
    pane B and the error pane show the same pixel at the same place, each image pixel a block of
    one colour (nearest neighbour)."""
    page = synthetic_page(tmp_path, n=3)
    at = {"selector": "#paneA", "fx": 0.43, "fy": 0.52}
    where = "document.getElementById('roA').textContent.split(')')[0]"
    block = ("['paneA', 'paneB'].map((id) => { const c = document.getElementById(id); "
             "const d = c.getContext('2d').getImageData(Math.round(0.43 * c.width) - 5, Math.round(0.52 * c.height) - 5, "
             "11, 11).data; return [...new Set(Array.from({length: 121}, (_, k) => d.slice(4 * k, 4 * k + 3).join()))]; })")
    out = browser(tmp_path / "index.html",
                  [{"move": True, **at}, {"eval": where}, {"wheel": 8, "deltaY": -100, **at},
                   {"move": True, **{**at, "fx": 0.4301}}, {"eval": where}, {"eval": "IBL.state.zoom"},
                   {"eval": block}], tmp_path)
    res = out["results"]
    assert res[1] == res[4]                          # the pixel under the cursor stays under it
    assert res[5] == pytest.approx(1.25 ** 8)
    x, y = (int(v) for v in res[1].strip("(").split(","))
    (a_colours, b_colours) = res[6]
    assert len(a_colours) == 1 and len(b_colours) == 1           # one colour a pixel, no filtering
    assert np.abs(np.array(a_colours[0].split(","), int) - shown(page, 1)[y, x]).max() <= 1
    assert np.abs(np.array(b_colours[0].split(","), int) - shown(page, 0)[y, x]).max() <= 1


@pytest.mark.external
def test_a_missing_data_file_is_said_on_the_page(tmp_path, browser):
    """The folder copied without report/: the page says which file it misses instead of failing
    silently, and shows the images it has."""
    synthetic_page(tmp_path, n=3)
    (tmp_path / "report" / "0002.js").unlink()
    out = browser(tmp_path / "index.html",
                  [{"eval": "IBL.select(2).then(() => document.getElementById('status').textContent)"},
                   {"eval": "IBL.select(1).then(() => document.getElementById('status').textContent)"}],
                  tmp_path, errors=True)
    assert out["results"][0] == "report/0002.js: missing (the report's data files sit beside index.html)"
    assert out["results"][1] == "3 images, 40 x 24"
    assert any("0002.js" in e for e in out["errors"])
