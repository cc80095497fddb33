"""`iblbake compare`: identical images pass at tolerance 0, the project's stored reference sheet
matches a fresh render cell by cell, a shifted highlight fails with the error of every cell
printed, and bad pairs are one-line errors."""

import pytest
import json

import numpy as np

from iblbake.io import images

from . import make_reference
from tests.helpers import run_cli

REF_PNG = make_reference.REFERENCE / "sheet_small.png"
REF_LAYOUT = make_reference.REFERENCE / "sheet_small.json"
# a fresh render on this kind of machine is bit-identical (measured 0); another CPU's float
# rounding may move a few 8-bit values, far below a real change (a 15 degree turn: 0.1-0.3)
TOLERANCE = 0.005


def test_identical_images_pass_at_zero():
    p = run_cli("compare", REF_PNG, REF_PNG, "--layout", REF_LAYOUT, "--json")
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert len(doc["errors"]) == 4 and all(e["error"] == 0 for e in doc["errors"])


@pytest.mark.slow
def test_stored_reference_sheet_matches_a_fresh_render(tmp_path):
    r = make_reference.render_sheet(tmp_path)
    assert r.returncode == 0, r.stderr
    p = run_cli("compare", REF_PNG, tmp_path / "sheet.png", "--layout", REF_LAYOUT, "--tolerance", TOLERANCE,
                "--json")
    assert p.returncode == 0, p.stdout + p.stderr
    print([e["error"] for e in json.loads(p.stdout)["errors"]])


@pytest.mark.slow
def test_shifted_highlight_fails_per_cell(tmp_path):
    r = make_reference.render_sheet(tmp_path, ["--set", "environment.rotation_y=15"])
    assert r.returncode == 0, r.stderr
    p = run_cli("compare", REF_PNG, tmp_path / "sheet.png", "--layout", REF_LAYOUT, "--tolerance", TOLERANCE)
    assert p.returncode == 1
    assert len([ln for ln in p.stdout.splitlines() if "flip" in ln]) == 4, p.stdout
    assert "over --tolerance" in p.stderr and len(p.stderr.strip().splitlines()) == 1


def test_rmse_of_exr_and_bad_pairs(tmp_path):
    a = np.full((8, 16, 3), 2.0, np.float32)
    images.write_exr(tmp_path / "a.exr", a)
    images.write_exr(tmp_path / "b.exr", a * 1.01)
    p = run_cli("compare", tmp_path / "a.exr", tmp_path / "b.exr", "--metric", "rmse", "--tolerance", "0.02",
                "--json")
    assert p.returncode == 0, p.stderr
    assert abs(json.loads(p.stdout)["errors"][0]["error"] - 0.01) < 1e-6
    images.write_exr(tmp_path / "c.exr", np.ones((4, 16, 3), np.float32))
    for other, words in ((tmp_path / "c.exr", "one size"), (REF_PNG, "PNG with a PNG")):
        p = run_cli("compare", tmp_path / "a.exr", other)
        assert p.returncode == 1 and words in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    p = run_cli("compare", REF_PNG, REF_PNG, "--layout", tmp_path / "missing.json")
    assert p.returncode == 1 and "missing.json" in p.stderr


def test_frames_named_in_no_encoding_are_compared(tmp_path):
    """PNGs whose names are not UTF-8 (b'\\xfe.png'): read through a link, not `TypeError: open()`."""
    a = np.full((8, 8, 3), 100, np.uint8)
    b = a.copy()
    b[:4] = 200
    images.write_png(tmp_path / "\udcfe.png", a)
    images.write_png(tmp_path / "\udcfd.png", b)
    p = run_cli("compare", tmp_path / "\udcfe.png", tmp_path / "\udcfd.png", "--metric", "rmse",
                "--tolerance", "1", "--json")
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["errors"][0]["error"] == pytest.approx(0.5 ** 0.5, rel=1e-6)    # half the pixels off by 100%
