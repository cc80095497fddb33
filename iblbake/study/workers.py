"""Renders in other processes: a sheet's cells on N local worker processes (--jobs, one device
each from --devices) or on the workers of a Dask cluster (--scheduler), and a study's reference
seeds on local workers. Each is a pure function of its scene, its files' contents and the
renderer, kept in the cache under its key: a worker that dies loses nothing, what it was
rendering is rendered again and comes out the same, and the sheet is the serial one bit for bit."""

from __future__ import annotations

import os
import sys
import time
from collections import Counter
from pathlib import Path

from iblbake.errors import IblbakeError
from iblbake.scene import load as scene_load
from iblbake.study import sheet

DASK_HINT = "pip install 'iblbake[distributed]' (Dask's distributed scheduler)"
RETRIES = 2            # how often a pool whose worker died is started again for its unfinished cells
# A worker process's peak resident memory, measured (each worker's peak_mib in --json; tests/test_workers.py
# checks it): 384 MiB for the --jobs 2 worker that built the bakes of the gallery's spheres sheet (city,
# 2048 x 1024; 128 x 128 cells), 208 MiB for the other, 157 MiB for the parent. Uncapped, --jobs 1000
# on 25 cells started 25 workers (4.0 GB) of one PoCL thread each.
WORKER_BYTES = 400 << 20

_STATE: dict = {}      # this worker process: one runtime, bake store and reuse state per (device, cache)


def _worker(device, cache_root) -> dict:
    key = (device, cache_root)
    if key not in _STATE:
        from iblbake.render import Bakes, Reuse
        from iblbake.device.runtime import Runtime
        rt = Runtime(device)
        _STATE[key] = {"rt": rt, "bakes": Bakes(cache_root), "reuse": Reuse(),
                       "label": f"pid {os.getpid()} on {rt.device_label}"}
    return _STATE[key]


def _render(w: dict, sc, c, resume, repeat: int = 0) -> dict:
    """One cell in a worker; its error comes back as a value, so a bad input fails once (no retry)."""
    try:
        r = sheet.render_cell(sc, c, w["rt"], w["bakes"], w["reuse"], None, True, resume, w["rt"].info.kind,
                              repeat)
    except Exception as e:               # anything else: one line back to the parent
        return {"error": _error_text(e), "seconds": 0.0, "key": None, "rendered": False}
    return {"error": r.error, "seconds": r.seconds, "key": r.key, "frame": r.frame,
            "rendered": r.frame is not None and not r.frame.report.get("cell_cached")}


def _error_text(e: Exception) -> str:
    """A worker's error as the parent prints it: the user's error as its one line, anything else
    with its kind."""
    return str(e) if isinstance(e, IblbakeError) else f"{type(e).__name__}: {e}"


def _summary(results, workers: dict, retried: int, **extra) -> dict:
    return {**extra, "retried_cells": retried,
            "workers": [{"worker": k, **v} for k, v in sorted(workers.items())],
            "cells": dict(Counter("failed" if r.error else "cached" if r.frame is not None and
                                  r.frame.report.get("cell_cached") else "rendered" for r in results))}


def _collect(r: sheet.CellResult, out: dict, workers: dict, bakes, keep_going: bool) -> None:
    """A worker's answer into the cell's result; the frame comes back as a value (Dask) or is read
    from the shared cache (local workers)."""
    w = workers.setdefault(out.get("worker", "?"), {"cells": 0, "rendered": 0, "seconds": 0.0})
    w["cells"] += 1
    w["rendered"] += bool(out["rendered"])
    w["seconds"] = round(w["seconds"] + out["seconds"], 4)
    if out.get("peak_mib"):
        w["peak_mib"] = max(w.get("peak_mib", 0), out["peak_mib"])
    r.seconds, r.key = out["seconds"], out["key"]
    if out["error"]:
        if not keep_going:
            raise IblbakeError(f"cell ({sheet.cell_name(r.cell)}): {out['error']}")
        r.error = out["error"]
        return
    frame = out.get("frame")
    if frame is not None:
        sheet.store_cell(bakes, out["key"], frame)      # a worker elsewhere: keep it here too
    else:
        frame = sheet.cached_cell(bakes, out["key"])
        if frame is None:
            raise IblbakeError(f"cell ({sheet.cell_name(r.cell)}): its worker wrote no cache entry {out['key']}")
    frame.report["cell_cached"] = not out["rendered"]
    r.frame = frame


# --- local worker processes (--jobs N) ------------------------------------------------------------

_DEVICE: list = []     # this pool worker's device spec, taken from the parent's queue at start


def split_cores(jobs: int) -> dict:
    """The environment that gives each of `jobs` workers its share of the cores on a PoCL CPU
    device (PoCL otherwise starts a thread per core in every worker, and N workers fight over
    them); a value the user set is kept."""
    key = "POCL_MAX_PTHREAD_COUNT"
    return {key: os.environ.get(key) or str(max(1, (os.cpu_count() or 1) // jobs))}


def worker_count(asked: int, tasks: int, what: str = "cell", warn=None) -> tuple[int, str | None]:
    """How many worker processes to start when `asked` for `tasks` pieces of work (`what`s): at
    most one a task, one a core, and as many as the available memory holds at WORKER_BYTES each.
    (count, why fewer than asked, for --json; None when it is what was asked); `warn` is told."""
    from iblbake.io.memory import host_bytes_available
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    caps = [(max(1, tasks), f"one a {what}: {tasks} to render"), (cores, f"one a core: {cores} cores")]
    free = host_bytes_available()
    if free is not None:
        caps.append((max(1, free // WORKER_BYTES), f"the memory: {free / (1 << 30):.1f} GiB available, "
                                                  f"{WORKER_BYTES >> 20} MiB a worker"))
    n, why = min(caps, key=lambda c: c[0])
    if asked <= n:
        return asked, None
    if warn:
        warn(f"--jobs {asked}: {n} worker process{'es' if n != 1 else ''} ({why})")
    return n, why


def _pool_init(devices, cache_root, env):
    os.environ.update(env)               # before this process loads its OpenCL platforms
    _DEVICE[:] = [devices.get()]
    _worker(_DEVICE[0], cache_root)


def _pool_cell(sc, c, resume, cache_root, repeat=0):
    w = _worker(_DEVICE[0], cache_root)
    out = _render(w, sc, c, resume, repeat)
    out.pop("frame", None)               # the parent reads it from the shared cache
    return {**out, "worker": w["label"], "peak_mib": _peak_mib()}


def _peak_mib() -> int | None:
    """This process's peak resident memory so far (what WORKER_BYTES stands for), MiB."""
    try:
        import resource
    except ImportError:
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak >> 20 if sys.platform == "darwin" else peak >> 10      # bytes on macOS, KiB on Linux


def _pool(jobs: int, devices, cache_root: str):
    """`jobs` spawned worker processes (each its own OpenCL runtime), worker k on devices[k % n]."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    for k in range(jobs):
        queue.put(devices[k % len(devices)])
    return ProcessPoolExecutor(jobs, mp_context=ctx, initializer=_pool_init,
                               initargs=(queue, cache_root, split_cores(jobs)))


def render_cells_parallel(scenes, cells, jobs: int, *, devices, bakes, progress=None, keep_going=False,
                          resume=False, warn=None, repeat: int = 0):
    """(every cell's CellResult, a summary) from `jobs` spawned worker processes, worker k on
    devices[k % len(devices)]. Workers build each bake once between them (the entry's lock) and
    keep their cells in the cache. A worker that dies (SIGKILL, out of memory) breaks the pool: a
    new one renders the unfinished cells, reading back what the dead one had finished."""
    from concurrent.futures import as_completed
    from concurrent.futures.process import BrokenProcessPool

    results = [sheet.CellResult(c) for c in cells]
    todo = []
    for i, sc in enumerate(scenes):
        if isinstance(sc, Exception):
            results[i].error = str(sc)
        else:
            todo.append(i)
    asked = jobs
    jobs, capped = worker_count(asked, len(todo), warn=warn)
    workers, retried = {}, 0
    for attempt in range(RETRIES + 1):
        broken = []
        with _pool(jobs, devices, str(bakes.root)) as pool:
            futures = {pool.submit(_pool_cell, scenes[i], cells[i], resume or attempt > 0, str(bakes.root), repeat): i
                       for i in todo}
            try:
                for f in as_completed(futures):
                    i = futures[f]
                    try:
                        out = f.result()
                    except BrokenProcessPool:
                        broken.append(i)
                        continue
                    _collect(results[i], out, workers, bakes, keep_going)
                    if progress:
                        progress()
            except BaseException:
                for f in futures:
                    f.cancel()
                raise
        if not broken:
            break
        todo, retried = sorted(broken), retried + len(broken)
        if attempt == RETRIES:
            raise IblbakeError(f"worker processes died {RETRIES + 1} times; {len(todo)} cells unfinished "
                               f"(first: {sheet.cell_name(cells[todo[0]])}); the finished ones are in the cache "
                               f"{bakes.root}: run again with --resume")
        if warn:
            warn(f"a worker process died; rendering its {len(todo)} unfinished cells again")
    return results, _summary(results, workers, retried, jobs=jobs, jobs_asked=asked, jobs_capped_by=capped,
                             devices=list(devices))


def _pool_reference(scene_path, overrides, settings, term, seed, cache_root):
    from iblbake.study import accuracy
    w = _worker(_DEVICE[0], cache_root)
    study = accuracy.Study(scene_path, overrides, settings, runtime=w["rt"], bakes=w["bakes"])
    study.reference_seed(term, seed)
    return w["label"]


def render_references_parallel(study, jobs: int, devices, progress=None, warn=None) -> dict:
    """Every reference seed of the study's terms rendered into its cache by `jobs` local workers
    (the study then reads them back). Only the references: the rungs are timed afterwards, alone,
    since rungs timed side by side on shared cores would measure each other. A reference's
    recorded seconds are its worker's, contended."""
    from concurrent.futures import as_completed
    from concurrent.futures.process import BrokenProcessPool

    root = str(study.bakes.root)
    done: Counter = Counter()
    tasks = [(t, s) for t in study.terms for s in study.settings.seeds]
    asked = jobs
    jobs, capped = worker_count(asked, len(tasks), "reference", warn)
    with _pool(jobs, devices, root) as pool:
        futures = [pool.submit(_pool_reference, study.path, study.overrides, study.settings, t, s, root)
                   for t, s in tasks]
        try:
            for f in as_completed(futures):
                done[f.result()] += 1
        except BrokenProcessPool:
            raise IblbakeError(f"a worker process died; the finished references are in the cache {root}: "
                               f"run again (they are read back)") from None
        except BaseException:
            for f in futures:
                f.cancel()
            raise
    return {"jobs": jobs, "jobs_asked": asked, "jobs_capped_by": capped, "devices": list(devices),
            "workers": [{"worker": k, "references": n} for k, n in sorted(done.items())]}


# --- Dask (--scheduler) ---------------------------------------------------------------------------

def _dask_cell(sc, c, devices, cache_root, resume, files, repeat=0):
    """One cell on a Dask worker: its device from --devices by the worker's name (a LocalCluster
    names them 0..N-1), the scene's files from their paths where this machine has the same
    content there, else from the bytes the client scattered (written once into the worker's own
    folder, named by content)."""
    from distributed import get_worker

    worker = get_worker()
    name = str(worker.name)
    device = devices[int(name) % len(devices)] if name.isdigit() else devices[0]
    w = _worker(device, cache_root)
    moved = {}
    inputs = Path(worker.local_directory) / "iblbake-inputs"
    for path, (sha, data) in files.items():
        if path in moved or (os.path.isfile(path) and w["bakes"].file_sha256(path) == sha):
            continue
        if path.lower().endswith((".gltf", ".glb")):
            # a .gltf or .glb reads its buffers and images by relative URI: they go beside it, as they were
            moved.update(_place_gltf(path, sha, data, files, inputs / sha))
            continue
        local = inputs / f"{sha}{Path(path).suffix}"
        _write_once(local, data)
        moved[path] = str(local)
    out = _render(w, scene_load.with_files(sc, moved) if moved else sc, c, resume, repeat)
    return {**out, "worker": f"{worker.address} ({w['label']})"}


def _write_once(local: Path, data) -> None:
    if not local.is_file():
        from iblbake.io import atomic
        local.parent.mkdir(parents=True, exist_ok=True)
        atomic.write_bytes(local, data)


def _place_gltf(path, sha, data, files, folder: Path) -> dict:
    """Write a .gltf or .glb and the files its URIs name (from `files`, the client's scattered bytes) into
    `folder` at the same relative places; the moves made."""
    from iblbake.scene.gltf import relative_uris

    out = {path: str(folder / Path(path).name)}
    _write_once(folder / Path(path).name, data)
    for uri in relative_uris(data):                    # none for a broken file: the loader reports it
        original = str((Path(path).parent / uri).resolve())
        local = (folder / uri).resolve()
        if original in files and folder.resolve() in local.parents:
            _write_once(local, files[original][1])
            out[original] = str(local)
    return out


def _suspicious(keys, dask_scheduler=None) -> dict:
    """How many worker deaths each task has lived through (the scheduler's own count)."""
    tasks = dask_scheduler.tasks
    return {k: tasks[k].suspicious for k in keys if k in tasks}


def connect(scheduler: str, jobs: int, resources: dict):
    """(client, cluster or None) for --scheduler: 'local' starts a LocalCluster of `jobs` worker
    processes (one thread each: a worker owns its OpenCL queue); else the address of a running one."""
    try:
        import distributed
    except ImportError:
        raise IblbakeError(f"--scheduler needs Dask: {DASK_HINT}") from None
    import logging
    cluster = None
    try:
        if scheduler == "local":
            cluster = distributed.LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                                               resources=resources or None, dashboard_address=None,
                                               # the scheduler's HTTP routes (health, metrics) start even
                                               # without a dashboard, on 8787 unless told: a second sheet
                                               # running beside would print "Port 8787 is already in use"
                                               scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                                               env=split_cores(jobs),
                                               silence_logs=logging.ERROR)
            return distributed.Client(cluster), cluster
        return distributed.Client(scheduler, timeout=5), None
    except (OSError, TimeoutError, ValueError) as e:
        if cluster is not None:
            cluster.close()
        raise IblbakeError(f"--scheduler {scheduler}: cannot connect ({e}); start one with `dask scheduler` "
                           f"and `dask worker ADDRESS`, or use --scheduler local") from None


def render_cells_dask(scenes, cells, client, *, devices, bakes, resources=None, progress=None, keep_going=False,
                      resume=False, repeat: int = 0):
    """(every cell's CellResult, a summary) from a Dask cluster's workers. A cell is a task keyed
    by its identity, so a repeated cell is one task and a cell whose worker died is the same task
    rescheduled (Dask's own bookkeeping; counted in the summary). The workers' caches are
    `bakes.root` on their machines: one shared folder builds each bake once for all of them."""
    import distributed

    results = [sheet.CellResult(c) for c in cells]
    shared, futures = {}, {}
    t0 = time.perf_counter()
    for i, (sc, c) in enumerate(zip(scenes, cells)):
        if isinstance(sc, Exception):
            results[i].error = str(sc)
            continue
        files = {}
        for path, sha in bakes.input_hashes(sc).items():
            if sha not in shared:
                # on every worker (data held by one alone is lost with it, and every task needing it
                # is cancelled: "lost dependencies"), under a key of its own (a content hash would
                # collide with the same file's key being released from an earlier sweep)
                shared[sha] = client.scatter(Path(path).read_bytes(), hash=False, broadcast=True)
            files[path] = (sha, shared[sha])
        key = "iblbake-cell-" + sheet.cell_identity(sc, bakes)[:40]
        f = client.submit(_dask_cell, sc, c, list(devices), str(bakes.root), resume, files, repeat, key=key,
                          resources=resources or None)
        futures.setdefault(f, []).append(i)
    workers = {}
    try:
        for f in distributed.as_completed(list(futures)):
            try:
                out = f.result()
            except Exception as e:           # KilledWorker: the task outlived too many workers
                out = {"error": _error_text(e), "seconds": 0.0, "key": None, "rendered": False}
            for n, i in enumerate(futures[f]):
                _collect(results[i], out if n == 0 else {**out, "rendered": False}, workers, bakes, keep_going)
                if progress:
                    progress()
        deaths = client.run_on_scheduler(_suspicious, [f.key for f in futures])
    finally:
        for f in futures:
            f.cancel()
    retried = sum(len(futures[f]) for f in futures if deaths.get(f.key, 0) > 0)
    return results, _summary(results, workers, retried, scheduler=str(client.scheduler.address),
                             submit_to_done_s=round(time.perf_counter() - t0, 4))
