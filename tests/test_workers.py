"""Cells rendered in other processes (iblbake.study.workers): local worker processes and a Dask
LocalCluster give the serial cells bit for bit, a worker SIGKILLed mid-sweep loses nothing (its
cells are rendered again and counted), bakes are built once across workers, a bad cell fails
once, and --scheduler without Dask is a one-line error saying what to install."""

import json
import multiprocessing
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from iblbake.render import Bakes
from iblbake.device.runtime import Runtime
from iblbake.scene import load as scene_load
from iblbake.study import sheet, sweep, workers

from tests.helpers import run_cli, sheet_scene

# 16 cells, each heavy enough (importance sampling) that a worker is mid-cell when it is killed
GRID = {"title": "grid", "rows": {"key": "materials.gold.roughness", "range": {"start": 0.1, "stop": 0.9, "count": 4}},
        "columns": {"key": "materials.gold.metallic", "range": {"start": 0, "stop": 1, "count": 4}}}
HEAVY = ["effects.specular=importance", "effects.samples=64"]


def plan(scene_path, overrides=HEAVY):
    base = scene_load.load(scene_path, overrides, ["cell.png"])
    _, _, cells = sweep.plan_sheet(base, None, None, None)
    return cells, sheet.cell_scenes(scene_path, overrides, cells)


@pytest.fixture(scope="module")
def grid(tmp_path_factory, small_panoramas):
    """The 16-cell sweep, its scenes, and the serial cells (hdr, png) to compare against."""
    folder = tmp_path_factory.mktemp("grid")
    scene = sheet_scene(folder, small_panoramas["city"], GRID, res=(64, 48))
    cells, scenes = plan(scene)
    serial = sheet.render_cells(scenes, cells, runtime=Runtime(None), bakes=Bakes(folder / "serial"))
    return scene, cells, scenes, [(r.frame.hdr, r.frame.png) for r in serial]


def same_cells(results, serial):
    return len(results) == len(serial) and all(
        r.error is None and np.array_equal(r.frame.hdr, h) and np.array_equal(r.frame.png, p)
        for r, (h, p) in zip(results, serial))


def once_each_bake(results):
    """Every cache entry some cell used (SH, chains: the bakes with an entry) was built by exactly
    one cell; the others found it cached."""
    built = {}
    for r in results:
        for b in r.frame.report.get("bakes", []):
            if "entry" not in b:
                continue
            built.setdefault(b["name"], 0)
            built[b["name"]] += not b.get("cached")
    return built


@pytest.mark.external
@pytest.mark.kill
def test_pool_worker_killed_mid_sweep_loses_nothing(tmp_path, grid):
    """--jobs 2 on a fresh cache, one worker SIGKILLed after the first finished cell: the pool
    starts again for the unfinished cells (counted), every cell equals the serial one, and no
    bake was built twice."""
    _, cells, scenes, serial = grid
    killed = []

    def kill_one():
        if not killed:
            victim = multiprocessing.active_children()[0]
            os.kill(victim.pid, signal.SIGKILL)
            killed.append(victim.pid)

    results, summary = workers.render_cells_parallel(scenes, cells, 2, devices=[None], bakes=Bakes(tmp_path),
                                                     progress=kill_one)
    assert killed and same_cells(results, serial)
    assert 1 <= summary["retried_cells"] < 16 and "failed" not in summary["cells"]
    assert sum(w["cells"] for w in summary["workers"]) == 16
    # built at most once; none of the cells kept may report it when the dead worker built it
    assert len(once_each_bake(results)) >= 2 and set(once_each_bake(results).values()) <= {0, 1}


@pytest.mark.external
@pytest.mark.kill
def test_dask_local_cluster_equals_serial_and_survives_a_killed_worker(tmp_path, grid):
    """A LocalCluster of 2 worker processes: the cells equal the serial ones; one worker SIGKILLed
    after the first finished cell: Dask reschedules what it held, the nanny restarts it, the
    sweep completes the same, and the summary counts the cells whose worker died."""
    distributed = pytest.importorskip("distributed")
    _, cells, scenes, serial = grid
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=50) as cluster, distributed.Client(cluster) as client:
        results, summary = workers.render_cells_dask(scenes, cells, client, devices=[None],
                                                     bakes=Bakes(tmp_path / "a"))
        assert same_cells(results, serial) and summary["retried_cells"] == 0
        assert len(once_each_bake(results)) >= 2 and set(once_each_bake(results).values()) == {1}
        pids = client.run(os.getpid)
        killed = []

        def kill_one():
            if not killed:
                os.kill(next(iter(pids.values())), signal.SIGKILL)
                killed.append(1)

        results, summary = workers.render_cells_dask(scenes, cells, client, devices=[None],
                                                     bakes=Bakes(tmp_path / "b"), progress=kill_one)
    assert killed and same_cells(results, serial)
    assert summary["retried_cells"] >= 1 and sum(w["cells"] for w in summary["workers"]) == 16


@pytest.mark.external
def test_cli_scheduler_local_and_jobs_equal_serial(tmp_path, small_panoramas):
    """The command line: --scheduler local --jobs 2 and --jobs 2 --devices cpu,cpu:0 write the
    serial sheet byte for byte, with each worker in the summary."""
    pytest.importorskip("distributed")
    scene = sheet_scene(tmp_path, small_panoramas["city"], GRID, res=(32, 24))
    outs = {}
    for name, extra in [("serial", []), ("dask", ["--scheduler", "local", "--jobs", "2"]),
                        ("jobs", ["--jobs", "2", "--devices", "cpu,cpu:0"])]:
        p = run_cli("sheet", scene, "--cache", tmp_path / name, "--json", "-o", tmp_path / f"{name}.png", *extra)
        assert p.returncode == 0, p.stderr
        outs[name] = json.loads(p.stdout)
    assert (tmp_path / "dask.png").read_bytes() == (tmp_path / "serial.png").read_bytes()
    assert (tmp_path / "jobs.png").read_bytes() == (tmp_path / "serial.png").read_bytes()
    assert "workers" not in outs["serial"]
    for name in ("dask", "jobs"):
        spread = outs[name]["workers"]
        assert sum(w["cells"] for w in spread["workers"]) == 16 and spread["cells"] == {"rendered": 16}
        names = {b for c in outs[name]["cells"] for b in c["bakes_cached"]}
        assert names >= {"sh", "prefiltered"}
        for bake in names:                      # built once across the workers: one cell found it missing
            assert sum(bake not in c["bakes_cached"] for c in outs[name]["cells"]) == 1, (name, bake)
    assert outs["jobs"]["workers"]["devices"] == ["cpu", "cpu:0"]


@pytest.mark.external
def test_a_bad_cell_fails_once_with_its_error(tmp_path, small_panoramas):
    """A cell whose render fails (its panorama is not an EXR, which only decoding finds) comes
    back as its one-line error, not retried: --keep-going marks it and the rest render. Port 8787
    held meanwhile (as a second sheet's scheduler would, beside it in CI) adds no line."""
    pytest.importorskip("distributed")
    import socket
    held = socket.socket()
    try:
        held.bind(("0.0.0.0", 8787))
        held.listen()
    except OSError:
        pass                                    # already held by someone else: the same condition
    (tmp_path / "gone.exr").write_bytes(b"not an image" * 100)
    scene = sheet_scene(tmp_path, small_panoramas["city"], {
        "rows": {"key": "environment.path", "values": [str(small_panoramas["city"]), str(tmp_path / "gone.exr")]}},
        res=(16, 12))
    p = run_cli("sheet", scene, "--cache", tmp_path / "c", "--json", "-o", tmp_path / "s.png", "--keep-going",
                "--scheduler", "local", "--jobs", "2")
    held.close()
    assert p.returncode == 1 and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert "gone.exr" in p.stderr and "Traceback" not in p.stderr


@pytest.mark.external
def test_scheduler_without_dask_says_what_to_install(tmp_path, small_panoramas):
    scene = sheet_scene(tmp_path, small_panoramas["city"], GRID, res=(16, 12))
    code = ("import sys; sys.modules['distributed'] = None; from iblbake.entry import main; "
            "sys.argv = ['iblbake'] + sys.argv[1:]; main()")
    p = subprocess.run([sys.executable, "-c", code, "sheet", str(scene), "-o", str(tmp_path / "s.png"),
                        "--scheduler", "local"], capture_output=True, text=True, timeout=120)
    assert p.returncode != 0 and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert "pip install 'iblbake[distributed]'" in p.stderr and not (tmp_path / "s.png").exists()


@pytest.mark.external
@pytest.mark.kill
def test_resume_after_sigkill_of_the_whole_sweep(tmp_path, small_panoramas):
    """SIGKILL of `iblbake sheet` part way: --resume reads back exactly the cells whose entries
    the killed run finished and renders the others."""
    scene = sheet_scene(tmp_path, small_panoramas["city"], GRID, res=(64, 48))
    cmd = [sys.executable, "-m", "iblbake.cli", "sheet", str(scene), "--cache", str(tmp_path / "c"), "-q",
           "-o", str(tmp_path / "s.png"), *[a for s in HEAVY for a in ("--set", s)]]
    proc = subprocess.Popen(cmd)
    deadline = time.time() + 300
    while time.time() < deadline and len(list((tmp_path / "c").glob("cell-*"))) < 3:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    finished = {p.name for p in (tmp_path / "c").glob("cell-*") if (p / "manifest.json").exists()}
    assert 3 <= len(finished) < 16 and not (tmp_path / "s.png").exists()
    p = run_cli(*cmd[3:], "--resume", "--json")
    assert p.returncode == 0, p.stderr
    cells = json.loads(p.stdout)["cells"]
    assert sum(c["cached"] for c in cells) == len(finished)


@pytest.mark.external
def test_unreachable_scheduler_is_one_line(tmp_path, small_panoramas):
    pytest.importorskip("distributed")
    scene = sheet_scene(tmp_path, small_panoramas["city"], GRID, res=(16, 12))
    p = run_cli("sheet", scene, "-o", tmp_path / "s.png", "--scheduler", "tcp://127.0.0.1:9")
    assert p.returncode == 1 and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert "cannot connect" in p.stderr and not (tmp_path / "s.png").exists()


def test_a_gltf_goes_to_a_worker_with_the_files_it_names(tmp_path):
    """A .gltf reads its buffers and images by relative URI: on a worker they are written beside
    its copy at the same relative places (and only those inside its folder)."""
    src = tmp_path / "client"
    (src / "tex").mkdir(parents=True)
    doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": "m.bin", "byteLength": 4}],
           "images": [{"uri": "tex/a%20b.png"}, {"uri": "data:image/png;base64,AAAA"}, {"uri": "../outside.png"}]}
    gltf_path = str(src / "m.gltf")
    files = {gltf_path: ("s0", json.dumps(doc).encode()), str((src / "m.bin").resolve()): ("s1", b"BIN!"),
             str((src / "tex" / "a b.png").resolve()): ("s2", b"PNG"),
             str((tmp_path / "outside.png").resolve()): ("s3", b"OUT")}
    folder = tmp_path / "worker" / "s0"
    moved = workers._place_gltf(gltf_path, "s0", files[gltf_path][1], files, folder)
    assert (folder / "m.gltf").read_bytes() == files[gltf_path][1]
    assert (folder / "m.bin").read_bytes() == b"BIN!" and (folder / "tex" / "a b.png").read_bytes() == b"PNG"
    assert not (tmp_path / "worker" / "outside.png").exists()
    assert moved == {gltf_path: str(folder / "m.gltf"), str((src / "m.bin").resolve()): str((folder / "m.bin").resolve()),
                     str((src / "tex" / "a b.png").resolve()): str((folder / "tex" / "a b.png").resolve())}


def test_a_glb_goes_to_a_worker_with_the_files_it_names(tmp_path):
    """A .glb may name buffers and images by URI too (its JSON chunk): they were left behind."""
    from iblbake.io.gltf import glb_bytes
    doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": "m%20x.bin", "byteLength": 4}]}
    glb = str(tmp_path / "c" / "m.glb")
    files = {glb: ("s0", glb_bytes(doc, b"")), str((tmp_path / "c" / "m x.bin").resolve()): ("s1", b"BIN!")}
    folder = tmp_path / "worker" / "s0"
    moved = workers._place_gltf(glb, "s0", files[glb][1], files, folder)
    assert (folder / "m x.bin").read_bytes() == b"BIN!" and (folder / "m.glb").read_bytes() == files[glb][1]
    assert moved[str((tmp_path / "c" / "m x.bin").resolve())] == str((folder / "m x.bin").resolve())


def test_worker_count_caps_at_the_tasks_the_cores_and_the_memory(monkeypatch):
    """--jobs 1000 started a worker a cell (~160-400 MiB each) with a thousandth of the cores each:
    the count is capped at the cells, the cores and the available memory, and says which."""
    from iblbake.io import memory
    monkeypatch.setattr(os, "sched_getaffinity", lambda _pid: set(range(8)), raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 8)
    monkeypatch.setattr(memory, "host_bytes_available", lambda: 100 * workers.WORKER_BYTES)
    assert workers.worker_count(4, 25) == (4, None)
    assert workers.worker_count(1000, 5) == (5, "one a cell: 5 to render")
    assert workers.worker_count(1000, 25) == (8, "one a core: 8 cores")
    monkeypatch.setattr(memory, "host_bytes_available", lambda: 3 * workers.WORKER_BYTES + 1)
    n, why = workers.worker_count(1000, 25, "reference")
    assert n == 3 and why.startswith("the memory: ") and "400 MiB a worker" in why
    monkeypatch.setattr(memory, "host_bytes_available", lambda: 1 << 20)
    assert workers.worker_count(6, 25)[0] == 1            # always one
    monkeypatch.setattr(memory, "host_bytes_available", lambda: None)
    assert workers.worker_count(1000, 25)[0] == 8


@pytest.mark.external
def test_jobs_beyond_the_cores_are_capped_and_said(tmp_path, small_panoramas):
    """`sheet --jobs 1000` on 4 cells: no more workers than the cores (and the cells, and the
    memory), a note on stderr, the count asked and why in --json; each worker's measured peak
    memory within the WORKER_BYTES the memory cap assumes."""
    from iblbake.io.memory import host_bytes_available
    scene = sheet_scene(tmp_path, small_panoramas["city"], {"columns": {
        "key": "materials.gold.roughness", "values": [0.2, 0.4, 0.6, 0.8]}}, res=(16, 12))
    p = run_cli("sheet", scene, "--cache", tmp_path / "c", "--json", "-o", tmp_path / "s.png", "--jobs", "1000")
    assert p.returncode == 0, p.stderr
    spread = json.loads(p.stdout)["workers"]
    expected = min(4, len(os.sched_getaffinity(0)), max(1, host_bytes_available() // workers.WORKER_BYTES))
    assert spread["jobs"] == expected and spread["jobs_asked"] == 1000 and spread["jobs_capped_by"]
    assert len(spread["workers"]) <= expected and sum(w["cells"] for w in spread["workers"]) == 4
    assert p.stderr.startswith(f"iblbake: warning: --jobs 1000: {expected} worker process"), p.stderr
    assert all(0 < w["peak_mib"] < workers.WORKER_BYTES >> 20 for w in spread["workers"]), spread
