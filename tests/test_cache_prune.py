"""The bake cache's default home, `iblbake cache` and `cache prune`: least recently used first,
and safe while other processes render from the same cache."""

import pytest
import json
import os
import subprocess
import sys
import time

import numpy as np

from iblbake.bake import cache

from tests.helpers import read_png, run_cli, sheet_scene


def test_default_cache_is_the_per_user_folder(monkeypatch):
    import platformdirs
    monkeypatch.delenv("IBLBAKE_CACHE", raising=False)
    assert cache.default_root() == __import__("pathlib").Path(platformdirs.user_cache_dir("iblbake")) / "bakes"
    monkeypatch.setenv("IBLBAKE_CACHE", "/somewhere")
    assert str(cache.default_root()) == "/somewhere"


@pytest.mark.external
def test_cache_lists_and_prunes_least_recently_used_first(tmp_path, small_panoramas):
    root = tmp_path / "c"
    for name in ("city", "studio"):
        p = run_cli("mips", small_panoramas[name], "--cache", root, "--size", "32", "--levels", "3", "--only",
                    "radiance", "-q")
        assert p.returncode == 0, p.stderr
    listed = json.loads(run_cli("cache", "--cache", root, "--json").stdout)
    assert len(listed["entries"]) == 2 and listed["bytes"] == sum(e["bytes"] for e in listed["entries"])
    old, new = sorted(listed["entries"], key=lambda e: e["used"])
    past = time.time() - 3600
    os.utime(os.path.join(old["path"], "manifest.json"), (past, past))
    os.utime(os.path.join(new["path"], "manifest.json"), (past + 60, past + 60))
    p = run_cli("cache", "prune", "--max-size", str(new["bytes"]), "--cache", root, "--json")
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert [e["key"] for e in doc["removed"]] == [old["key"]] and doc["bytes"] == new["bytes"]
    # recently used entries stay, whatever the size asked for
    os.utime(os.path.join(new["path"], "manifest.json"))
    doc = json.loads(run_cli("cache", "prune", "--max-size", "0", "--cache", root, "--json").stdout)
    assert doc["removed"] == [] and len(doc["kept_in_use"]) == 1
    p = run_cli("cache", "prune", "--max-size", "lots", "--cache", root)
    assert p.returncode == 2 and "500M" in p.stderr


@pytest.mark.external
@pytest.mark.kill
def test_prune_while_two_renders_run_leaves_both_correct(tmp_path, small_panoramas):
    """A loop pruning the cache to nothing while two renders read it: every entry is old (an hour
    unused) when they start, so the pruner takes what they do not touch first; both renders finish
    with the pixels they have alone, and the pruner did remove entries."""
    root = tmp_path / "c"
    scenes = {}
    for n in ("city", "studio"):
        (tmp_path / n).mkdir()
        scenes[n] = sheet_scene(tmp_path / n, small_panoramas[n])
    want = {}
    for n, sc in scenes.items():
        p = run_cli("render", sc, "-o", tmp_path / f"{n}_alone.png", "--cache", root, "-q")
        assert p.returncode == 0, p.stderr
        want[n] = read_png(tmp_path / f"{n}_alone.png")
    p = run_cli("mips", small_panoramas["city"], "--cache", root, "--size", "16", "--levels", "2", "-q")
    assert p.returncode == 0, p.stderr           # entries no render reads
    past = time.time() - 3600
    for e in cache.entries(root):
        os.utime(os.path.join(e["path"], "manifest.json"), (past, past))
    before = {e["key"] for e in cache.entries(root)}
    pruner = subprocess.Popen([sys.executable, "-c", (
        "import time; from iblbake.bake import cache\n"
        "end = time.time() + 120\n"
        "while time.time() < end:\n"
        f"    cache.prune({str(root)!r}, 0)\n"
        "    time.sleep(0.002)\n")])
    try:
        procs = {n: subprocess.Popen([sys.executable, "-m", "iblbake.cli", "render", str(sc), "-o",
                                      str(tmp_path / f"{n}.png"), "--cache", str(root), "-q"],
                                     stderr=subprocess.PIPE, text=True) for n, sc in scenes.items()}
        for n, pr in procs.items():
            _, err = pr.communicate(timeout=300)
            assert pr.returncode == 0, err
            assert np.array_equal(read_png(tmp_path / f"{n}.png"), want[n]), n
    finally:
        pruner.kill()
        pruner.wait()
    assert before - {e["key"] for e in cache.entries(root)}, "the pruner removed nothing"
