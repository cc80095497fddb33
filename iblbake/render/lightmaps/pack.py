"""xatlas' charting and packing of a lightmap's meshes (render/lightmaps/uv.py layout), run in a child
process: the PyPI wheel of xatlas (0.0.11, Young's xatlas with its own worker threads) now and then
dies of a segmentation fault inside Atlas.generate on a loaded machine (measured here: 1 of about
4,500 packs of a small scene, three at once on 2 cores; CI lost a test worker to it), which would take
the command, a pytest worker or a user's program with it. The child is this file run as a script by
the same interpreter (it imports numpy and xatlas alone); one killed by a signal is run again, up to
TRIES times, then the bake stops with one line. xatlas is deterministic: a rerun packs the same atlas.
The child also leaves without destroying the atlas, whose destructor can hang (below).

The meshes go to the child's standard input and its atlas comes back on its standard output, each as
one .npz (numpy's format, read without pickle): in, per mesh i `v{i}` (n, 3) float32, `f{i}` (m, 3)
uint32 and, where the mesh keeps its own charts, `uv{i}` (n, 2) float32, and `options`
(texels_per_unit, padding, use_input_mesh_uvs, meshes); out, `size` (width, height, atlases) and per mesh
`vmap{i}`, `idx{i}`, `uv{i}` as xatlas.Atlas gives them."""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys

import numpy as np

TRIES = 3
# the child: this file by path, not `-m iblbake...` (that would import the package's render modules)
COMMAND = [sys.executable, __file__]


def charts(meshes, texels_per_unit: float, padding: int, use_input_uvs: bool, *, what: str = "lightmap"):
    """xatlas' atlas of `meshes` [(vertices (n, 3), faces (m, 3), uv (n, 2) or None)], packed at
    `texels_per_unit` with `padding` texels between charts: (width, height, atlases, [(vmap, idx, uv)
    per mesh]). Raises IblbakeError naming `what` where the child dies TRIES times."""
    from iblbake.errors import IblbakeError

    arrays = {"options": np.array([texels_per_unit, padding, use_input_uvs, len(meshes)], np.float64)}
    for i, (v, f, uv) in enumerate(meshes):
        arrays[f"v{i}"], arrays[f"f{i}"] = np.asarray(v, np.float32), np.asarray(f, np.uint32)
        if uv is not None:
            arrays[f"uv{i}"] = np.asarray(uv, np.float32)
    sent = io.BytesIO()
    np.savez(sent, **arrays)
    for _ in range(TRIES):
        run = subprocess.run(COMMAND, input=sent.getvalue(), capture_output=True, check=False)
        if run.returncode >= 0:
            break
    if run.returncode < 0:
        name = signal.Signals(-run.returncode).name
        raise IblbakeError(f"{what}: xatlas died ({name}) packing the charts {TRIES} times; give another "
                           f"texels_per_unit or check the meshes' triangles")
    if run.returncode:
        last = run.stderr.decode(errors="replace").strip().splitlines()[-1:] or ["no message"]
        raise RuntimeError(f"xatlas' child process failed (exit {run.returncode}): {last[0]}")
    with np.load(io.BytesIO(run.stdout), allow_pickle=False) as got:
        w, h, count = (int(x) for x in got["size"])
        return w, h, count, [(got[f"vmap{i}"], got[f"idx{i}"], got[f"uv{i}"]) for i in range(len(meshes))]


def _child():
    import resource

    import xatlas

    # a crash writes no core file into the user's folder (where a shell's `ulimit -c` would allow one)
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))

    with np.load(io.BytesIO(sys.stdin.buffer.read()), allow_pickle=False) as got:
        density, padding, use_uvs, n = got["options"]
        n = int(n)
        atlas = xatlas.Atlas()
        for i in range(n):
            atlas.add_mesh(got[f"v{i}"], got[f"f{i}"], None, got[f"uv{i}"] if f"uv{i}" in got.files else None)
    opts, pack = xatlas.ChartOptions(), xatlas.PackOptions()
    opts.use_input_mesh_uvs = bool(use_uvs)
    pack.texels_per_unit, pack.padding, pack.bilinear, pack.resolution = float(density), int(padding), True, 0
    pack.blockAlign = False
    atlas.generate(opts, pack)
    out = {"size": np.array([atlas.width, atlas.height, atlas.atlas_count], np.int64)}
    for i in range(n):
        out[f"vmap{i}"], out[f"idx{i}"], out[f"uv{i}"] = atlas[i]
    buf = io.BytesIO()
    np.savez(buf, **out)
    sys.stdout.buffer.write(buf.getvalue())
    sys.stdout.buffer.flush()
    return atlas


if __name__ == "__main__":
    # leave with the atlas alive: xatlas' destructor wakes its workers without their lock and joins
    # them, and a worker between its check and its wait sleeps for ever (seen here once in the same
    # stress of some thousands of packs); the process' end frees everything
    atlas = _child()
    os._exit(0)
