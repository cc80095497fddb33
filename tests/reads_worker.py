"""Feeds special files (devices, FIFOs, links to them, oversized sparse files) to every reader of
iblbake in a child process and reports each outcome (issue 43: nothing read without a limit).

    python tests/reads_worker.py FOLDER CASES.json

CASES.json: [[kind, path], ...]. One JSON line per case: {"kind", "path", "outcome", "message",
"seconds"}: "error" (an IblbakeError: the CLI's one line), "ok" (returned), "memory"
(MemoryError: the reader had no limit), "crash" (another exception). The child runs under a
3 GiB address-space limit, so a reader of /dev/zero without a limit fails fast instead of taking
the machine; a thread opens each FIFO for writing after 2 s and closes it, so a reader blocked
on one gets an end of file instead of hanging the test.
"""

import json
import os
import resource
import sys
import threading
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from iblbake.errors import IblbakeError  # noqa: E402

UNBLOCK_AFTER_S = 2.0


def unblock(fifo: str, stop: threading.Event):
    """Open the FIFO for writing (non-blocking: only once a reader has it open) and close it."""
    end = time.monotonic() + 30
    stop.wait(UNBLOCK_AFTER_S)
    while not stop.is_set() and time.monotonic() < end:
        try:
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        except OSError:
            stop.wait(0.05)


def scene_doc(folder: Path, **patch) -> Path:
    doc = {"camera": {"resolution": [16, 16]}, "environment": {"path": str(folder / "sky.exr")},
           "materials": {"m": {"base_color": [0.5, 0.5, 0.5]}},
           "objects": [{"sphere": {"radius": 1}, "material": "m"}]}
    for k, v in patch.items():
        doc[k] = v
    p = folder / f"scene-{len(list(folder.glob('scene-*')))}.yaml"
    p.write_text(yaml.safe_dump(doc))
    return p


def run(kind: str, path: str, folder: Path):
    from iblbake.scene import load as scene_load
    if kind == "scene":
        return scene_load.load(path)
    if kind == "ladder":
        from iblbake.render.plan import effect_modes
        from iblbake.study import ladder
        sc = scene_load.load(scene_doc(folder))
        return ladder.ladder_from_file(path, sc, effect_modes(sc))
    if kind == "panorama":
        from iblbake.bake import inputs
        return inputs.read_environment(path)
    if kind == "scene-panorama":
        return scene_load.load(scene_doc(folder, environment={"path": path}))
    if kind == "mesh":
        from iblbake.scene import geometry
        sc = scene_load.load(scene_doc(folder, objects=[{"mesh": {"path": path}, "material": "m"}]))
        return geometry.build_triangles(sc.data["objects"], {0: 0}, sc.source, {})
    if kind == "texture":
        from iblbake.scene import materials
        sc = scene_load.load(scene_doc(folder, materials={"m": {"base_color_map": {"path": path}}}))
        return materials.load_textures(materials.table(sc)[0], sc.source)
    if kind in ("gltf-buffer", "gltf-image"):
        from iblbake.scene import geometry, materials
        gl = folder / f"{kind}.gltf"
        doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": os.path.relpath(path, folder), "byteLength": 36}]}
        if kind == "gltf-image":
            doc = {"asset": {"version": "2.0"}, "images": [{"uri": os.path.relpath(path, folder)}],
                   "textures": [{"source": 0}], "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]}
        gl.write_text(json.dumps(doc))
        sc = scene_load.load(scene_doc(folder, objects=[{"mesh": {"path": str(gl)}}]))
        if kind == "gltf-image":
            return materials.load_textures(materials.file_materials(str(gl), "x"), "x")
        return geometry.build_triangles(sc.data["objects"], {0: 0}, sc.source, {0: 0})
    if kind == "layout":
        from iblbake.study import compare
        return compare.read_layout(path, "ref.png")
    if kind == "compare":
        from iblbake.study import compare
        return compare.read(path)
    if kind == "manifest":
        from iblbake.bake import cache
        entry = folder / "entry"
        entry.mkdir(exist_ok=True)
        m = entry / cache.MANIFEST
        if m.is_symlink() or m.exists():
            m.unlink()
        os.symlink(path, m)
        if cache.verify(entry) is not None:
            raise AssertionError("a special manifest verified")
        return None
    raise ValueError(kind)


def main():
    folder = Path(sys.argv[1])
    cases = json.loads(Path(sys.argv[2]).read_text())
    from iblbake.io import images
    images.write_exr(folder / "sky.exr", np.full((8, 16, 3), 0.5, np.float32))
    resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))
    for kind, path in cases:
        stop = threading.Event()
        t = None
        if os.path.exists(path) and Path(os.path.realpath(path)).is_fifo():
            t = threading.Thread(target=unblock, args=(os.path.realpath(path), stop), daemon=True)
            t.start()
        t0 = time.perf_counter()
        try:
            run(kind, path, folder)
            outcome, message = "ok", ""
        except IblbakeError as e:
            outcome, message = "error", str(e)
        except MemoryError:
            outcome, message = "memory", "MemoryError"
        except Exception:
            outcome, message = "crash", traceback.format_exc()[-600:]
        stop.set()
        if t:
            t.join()
        print(json.dumps({"kind": kind, "path": path, "outcome": outcome, "message": message,
                          "seconds": round(time.perf_counter() - t0, 5)}), flush=True)


if __name__ == "__main__":
    main()
