"""Feeds fuzzed inputs to one iblbake loader in a child process and reports each outcome.

    python tests/fuzz_worker.py KIND CACHE_DIR FILE...     (KIND: mesh, image or scene)

One JSON line per input: {"file", "outcome", "message", "seconds"}, where outcome is
"ok" (accepted; a scene is also rendered and its frame checked finite), "error" (an IblbakeError:
what the CLI prints as its one line), "crash" (any other exception: a defect; the message is the
traceback) or "nonfinite" (accepted but produced NaN/Inf). A line {"start": FILE} comes first, so
the parent knows which input a native crash (the child dying on a signal) belongs to.
Run as a child so that a segfault in a native decoder or an allocation bomb cannot take the test
runner down with it.
"""

import json
import signal
import sys
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from iblbake.errors import IblbakeError  # noqa: E402

PER_INPUT_LIMIT_S = 60


class Hang(Exception):
    pass


def _alarm(signum, frame):
    raise Hang(f"no answer within {PER_INPUT_LIMIT_S} s")


def load_mesh(path, cache):
    """The mesh as a scene object: a glTF with its own materials (parsed too), the rest with a scene
    material; texture coordinates and tangents built as for a textured scene."""
    from iblbake.scene import geometry, materials
    from iblbake.scene.bvh import build_bvh
    obj, counts = {"mesh": {"path": path}, "material": "m"}, {}
    if path.lower().endswith((".gltf", ".glb")):
        del obj["material"]
        counts = {0: len(materials.file_materials(path, "fuzz.yaml: objects.0.mesh"))}
    tris = geometry.build_triangles([obj], {0: 0}, "fuzz.yaml", counts, attributes=True)
    if len(tris):
        lo, hi = geometry.triangle_bounds(tris)
        build_bvh(lo, hi)
    return True


def load_image(path, cache):
    from iblbake.io import images
    img, _ = images.read_panorama(path, max_pixels=1 << 22)
    return bool(np.isfinite(img).all())


def load_scene(path, cache):
    from iblbake.render import render
    from iblbake.scene import load as scene
    sc = scene.load(path)
    # keep every accepted mutation cheap to render: tiny frame, few reference samples
    sc.data["camera"]["resolution"] = [24, 16]
    sc.data["camera"]["spp"] = min(sc.data["camera"]["spp"], 2)
    fx = sc.data["effects"]
    fx["samples"] = min(fx["samples"], 64)
    fx["reference"]["max_samples"] = min(fx["reference"]["max_samples"], 32)
    fx["prefilter"]["samples"] = min(fx["prefilter"]["samples"], 64)
    frame = render(sc, cache_root=Path(cache), warn=lambda _: None)
    return bool(np.isfinite(frame.hdr).all())   # the PNG is made from it (uint8, always finite)


LOADERS = {"mesh": load_mesh, "image": load_image, "scene": load_scene}


def main():
    kind, cache, files = sys.argv[1], sys.argv[2], sys.argv[3:]
    load = LOADERS[kind]
    signal.signal(signal.SIGALRM, _alarm)
    for f in files:
        print(json.dumps({"start": f}), flush=True)
        t0 = time.perf_counter()
        signal.alarm(PER_INPUT_LIMIT_S)
        try:
            outcome, message = ("ok" if load(f, cache) else "nonfinite"), ""
        except IblbakeError as e:
            outcome, message = "error", str(e)
        except Hang as e:
            outcome, message = "hang", str(e)
        except BaseException:   # noqa: BLE001 -- exactly what the fuzzer hunts for
            outcome, message = "crash", traceback.format_exc()[-2000:]
        finally:
            signal.alarm(0)
        print(json.dumps({"file": f, "outcome": outcome, "message": message,
                          "seconds": round(time.perf_counter() - t0, 4)}), flush=True)


if __name__ == "__main__":
    main()
