"""`iblbake mips` end to end: the cache reuses, detects corruption, survives concurrency and kills."""

import pytest
import json
import signal
import subprocess
import sys
import time

import numpy as np

from iblbake.bake import cache

from tests.helpers import run_cli, write_exr

ARGS = ["--size", "16", "--samples", "32", "--dfg-size", "16", "--dfg-samples", "64", "--json"]


def panorama(tmp_path, name="env.exr", seed=0):
    img = np.random.default_rng(seed).random((32, 64, 3)).astype(np.float32)
    img[5, 9] = 200.0
    return write_exr(tmp_path / name, img)


def bake(env, root, *extra):
    p = run_cli("mips", env, "--cache", root, *ARGS, *extra)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


def entries(root):
    return sorted(p for p in root.iterdir() if not p.name.startswith("."))


def test_second_run_is_cached_and_complete(tmp_path):
    env, root = panorama(tmp_path), tmp_path / "c"
    first = bake(env, root)
    assert not any(e["cached"] for e in first["entries"].values())
    second = bake(env, root)
    assert all(e["cached"] for e in second["entries"].values())
    assert len(entries(root)) == 3
    for e in entries(root):
        m = cache.verify(e)
        assert m is not None and m["files"]
    pre = json.loads((root / first["entries"]["prefiltered"]["path"].split("/")[-1] / "manifest.json").read_text())
    assert pre["roughness_mapping"].startswith("level k of K")
    assert [f["roughness"] for f in pre["files"]] == [0.0, 1.0]   # sizes 16, 8 (--min-size 8)


def test_options_change_the_key_and_dfg_is_shared(tmp_path):
    env, root = panorama(tmp_path), tmp_path / "c"
    a = bake(env, root)
    b = bake(env, root, "--layout", "cubemap")
    assert a["entries"]["radiance"]["path"] == b["entries"]["radiance"]["path"] and b["entries"]["radiance"]["cached"]
    assert a["entries"]["prefiltered"]["path"] != b["entries"]["prefiltered"]["path"]
    assert b["entries"]["dfg"]["cached"]
    other = panorama(tmp_path, "other.exr", seed=1)
    c = bake(other, root, "--only", "dfg")
    assert set(c["entries"]) == {"dfg"} and c["entries"]["dfg"]["cached"]


def test_corrupted_file_is_detected_and_rebuilt(tmp_path):
    env, root = panorama(tmp_path), tmp_path / "c"
    first = bake(env, root)
    entry = root / first["entries"]["prefiltered"]["path"].split("/")[-1]
    victim = entry / "prefiltered_01.exr"
    data = bytearray(victim.read_bytes())
    data[len(data) // 2] ^= 0xFF
    victim.write_bytes(bytes(data))
    p = run_cli("mips", env, "--cache", root, *ARGS)
    assert p.returncode == 0, p.stderr
    assert "does not match its manifest hash" in p.stderr
    out = json.loads(p.stdout)
    assert out["entries"]["prefiltered"]["cached"] is False and out["entries"]["radiance"]["cached"] is True
    assert cache.verify(entry) is not None


def test_concurrent_runs_share_one_entry(tmp_path):
    env, root = panorama(tmp_path), tmp_path / "c"
    cmd = [sys.executable, "-m", "iblbake.cli", "mips", env, "--cache", str(root), *ARGS]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(3)]
    outs = [p.communicate(timeout=300) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1] for o in outs]
    paths = {json.loads(o[0])["entries"]["prefiltered"]["path"] for o in outs}
    assert len(paths) == 1
    assert len(entries(root)) == 3
    assert not [p for p in root.iterdir() if p.name.startswith(".tmp-")]
    assert all(cache.verify(e) is not None for e in entries(root))


@pytest.mark.kill
def test_killed_run_leaves_nothing_a_later_run_accepts(tmp_path):
    env, root = panorama(tmp_path), tmp_path / "c"
    cmd = [sys.executable, "-m", "iblbake.cli", "mips", env, "--cache", str(root), "--size", "32",
           "--samples", "512", "--method", "fis", "--dfg-size", "64", "--dfg-samples", "8192", "-q"]
    for delay in (0.3, 0.8, 1.5, 2.5):
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        time.sleep(delay)
        p.send_signal(signal.SIGKILL if delay != 0.8 else signal.SIGINT)
        p.wait(timeout=60)
        if root.exists():
            for e in entries(root):
                assert cache.verify(e) is not None, e   # anything under a final name is complete
    p = subprocess.run(cmd + ["--json"], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert all(cache.verify(e) is not None for e in entries(root))


def test_bad_input_fails_cleanly(tmp_path):
    root = tmp_path / "c"
    p = run_cli("mips", tmp_path / "missing.exr", "--cache", root)
    assert p.returncode != 0 and "missing.exr" in p.stderr and "Traceback" not in p.stderr
    assert not root.exists() or not entries(root)


def test_spectral_on_a_too_sharp_level_fails_before_any_bake(tmp_path):
    """--method spectral with 32 levels (r_1 = 1/31, bands beyond 2048): one line naming the level
    and the fix, exit 1, and not even the radiance chain baked."""
    root = tmp_path / "c"
    p = run_cli("mips", panorama(tmp_path), "--cache", root, "--levels", "32", "--min-size", "1",
                "--method", "spectral")
    assert p.returncode == 1 and "Traceback" not in p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "level 1" in lines[0] and "--method auto" in lines[0], p.stderr
    assert not root.exists() or not entries(root)


@pytest.mark.slow
def test_verify_measures_stores_and_reports(tmp_path):
    """--verify N: each level's relative RMSE against the float64 brute force at N texels, stored
    in the manifest (the files keep their hashes), equal to the benchmark's figures (the same
    texels, measured apart here), under 1% for the default method; render --report shows them."""
    from iblbake.bake import mips as mipsbake
    from iblbake.io import images

    env = panorama(tmp_path)
    root = tmp_path / "cache"
    out = bake(env, root, "--only", "prefiltered", "--verify", "24")
    v = out["entries"]["prefiltered"]["verify"]
    entry = root / out["entries"]["prefiltered"]["path"].rsplit("/", 1)[-1]
    man = json.loads((entry / "manifest.json").read_text())
    assert man["verify"]["relative_rmse"] == v["relative_rmse"] and cache.verify(entry) is not None
    src = images.read_exr(env)[..., :3]
    picks = mipsbake.verification_texels(src, "equirect", [f["size"] for f in man["files"]],
                                         [f["roughness"] for f in man["files"]], 24)
    levels = [images.read_exr(entry / f["name"]) for f in man["files"]]
    want = mipsbake.level_errors(levels, picks)
    assert np.allclose(v["relative_rmse"], want, rtol=1e-5, atol=1e-9)
    assert max(v["relative_rmse"]) < 0.01 and len(v["relative_rmse"]) == len(man["files"])
    scene = tmp_path / "s.yaml"
    scene.write_text(f"camera: {{perspective: {{position: [0, 0, 3]}}, resolution: [8, 8]}}\n"
                     f"environment: {{path: {env}}}\nmaterials: {{m: {{metallic: 1, roughness: 0.5}}}}\n"
                     f"objects: [{{sphere: {{radius: 1}}, material: m}}]\n"
                     f"effects: {{diffuse: off, specular: prefiltered, prefilter: {{size: 16, samples: 32, "
                     f"level_sizes: halving, min_size: 8, levels: {len(man['files'])}}}}}\n")
    p = run_cli("render", scene, "--cache", root, "--json")
    assert p.returncode == 0, p.stderr
    pre = next(b for b in json.loads(p.stdout)["bakes"] if b["name"] == "prefiltered")
    assert pre["cached"] and pre["verified_relative_rmse"] == v["relative_rmse"]
