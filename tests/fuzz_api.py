"""Fuzzes every public function of the Python API (iblbake.__all__ and the methods of what they
return) with random arguments, of the documented types (edge values too) and of wrong ones, in this
process under the memory limit its parent set (RLIMIT_AS): each call must succeed or raise an
iblbake.Error of one line; any other exception (a raw TypeError, a MemoryError: more memory than
the limit) or a Python warning (numpy's reach stderr) is a finding.

    python tests/fuzz_api.py FOLDER SEED CASES

FOLDER holds sky.exr (written here) and the bake cache. One JSON line a case: {"start": i, "call"}
first (so the parent knows which call a killed process was in), then {"case", "call", "outcome":
ok | error | raw, "message", "seconds", "peak_rss": the process's largest resident size so far}. Valid calls are kept
small (tiny frames and panoramas) so a case takes milliseconds: the memory and range checks are
what is fuzzed, not the renderer.
"""

import json
import math
import random
import resource
import sys
import time
import traceback
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

import iblbake  # noqa: E402


class Stop(Exception):
    """Raised from accuracy's before_run: the study stops before anything renders (an outcome ok)."""


def _gen():
    return (i for i in range(3))


# wrong values for any argument: every kind a caller might pass by mistake (no function: one
# given as a callback is called, and what it raises is the caller's)
WRONG = [None, True, False, -1, 0, 1, 2 ** 40, -2 ** 63, 10 ** 30, 1.5, -0.0, math.nan, math.inf, -math.inf, "", "x",
         "3", b"x", [], [1], [1, 2, 3], (), {}, {"a": 1}, np.int64(3), np.float32(2.5), np.bool_(True),
         np.array([1, 2]), np.zeros((2, 2, 3)), object(), Path("/nonexistent/x"), _gen]


def wrong(rng):
    v = rng.choice(WRONG)
    return v() if v is _gen else v


class Case:
    """A call's keyword arguments: the valid ones drawn from `good`, then one or two replaced by
    an edge value or a wrong one."""

    def __init__(self, rng, good: dict, edges: dict):
        self.kw = {k: rng.choice(v) for k, v in good.items()}
        for k in rng.sample(sorted(good), k=min(len(good), rng.choice((0, 0, 1, 1, 2)))):
            self.kw[k] = rng.choice(edges.get(k, [])) if edges.get(k) and rng.random() < 0.6 else wrong(rng)


def scene_doc(sky, res=8):
    return {"camera": {"perspective": {"position": [0, 0, 3], "fov_y": 40}, "resolution": [res, res]},
            "environment": {"path": sky},
            "materials": {"m": {"base_color": [0.8, 0.8, 0.8], "roughness": 0.5}},
            "objects": [{"sphere": {"radius": 1}, "material": "m"}],
            "effects": {"diffuse": "sh", "specular": "off"}}


def mutate_scene(rng, doc):
    """A scene mapping with one value somewhere replaced by a wrong one (a key too, at times)."""
    import copy
    doc = copy.deepcopy(doc)
    node = doc
    while isinstance(node, dict) and node and rng.random() < 0.7:
        key = rng.choice(sorted(node, key=str))
        if not isinstance(node[key], dict) or rng.random() < 0.3:
            if rng.random() < 0.2:
                node[rng.choice([3, None, (1, 2), "bogus"])] = node.pop(key)
            else:
                node[key] = wrong(rng)
            return doc
        node = node[key]
    if rng.random() < 0.1:
        doc["self"] = doc                         # a mapping that contains itself
    return doc


def calls(rng, ctx):
    """(name, thunk) of one random call of each public function and method."""
    sky, pano, folder = ctx["sky"], ctx["pano"], ctx["folder"]
    shapes = [(4, 8, 3), (1, 1, 3), (3, 5, 3), (0, 4, 3), (4, 8), (4, 8, 4), (2, 2, 2, 3)]
    arrays = [np.ones(rng.choice(shapes), np.float32), np.full((4, 8, 3), np.nan), -np.ones((4, 8, 3)),
              np.broadcast_to(np.float32(1), (1 << 16, 1 << 17, 3)), np.ones((4, 8, 3), complex),
              np.array([["a"]]), [[[1, 2, 3]]], np.ones((4, 8, 3), np.float16)]
    c = lambda good, edges=None: Case(rng, good, edges or {}).kw       # noqa: E731
    names_ok = [None, {"bands": "--bands"}]
    dev = ["cpu"]

    kw = c({"path": [sky, folder / "missing.exr"], "primaries": ["auto", "keep", "convert"],
            "layout": ["auto", "equirect"], "nonfinite": ["error", "zero"], "negative": ["keep", "clamp"],
            "transfer": ["auto", "linear"], "max_pixels": [None, 1 << 22], "names": names_ok},
           {"max_pixels": [1, 100, 2 ** 62, -5]})
    yield "load_panorama", shown(lambda: iblbake.load_panorama(**kw), kw)
    kw2 = c({"pixels": arrays, "name": ["a"], "nonfinite": ["error", "zero", "clamp"],
             "negative": ["keep", "clamp", "error"]})
    yield "Panorama.from_pixels", shown(lambda: iblbake.Panorama.from_pixels(**kw2), kw2)
    kw3 = c({"panorama": [pano], "bands": [1, 3], "window": [None, "hann"], "rotate_y": [0.0, 30.0],
             "intensity": [1.0], "backend": ["numpy", "auto"], "device": [None], "error": [True, False],
             "names": names_ok}, {"bands": [16, 17, 0], "rotate_y": [1e300, -1e300], "intensity": [1e300, 0.0]})
    yield "sh", shown(lambda: _sh_methods(rng, iblbake.sh(**kw3)), kw3)
    bname = rng.choice(["l1_geomerics", "zh3", "sg", "sg", "ambient_dice", "haar", "haar", "sh", "x", 3])
    opts = {"sg": {"sg_lobes": rng.choice([5, 12, 7, 9.0]), "sg_fit": rng.choice(["nnls", "least_squares", 1])},
            "haar": {"haar_coefficients": rng.choice([16, 256, 15, 2 ** 40])}}.get(bname, {})
    opts = rng.choice([opts, opts, {}, {"bogus": 1}])
    kw4 = c({"intensity": [1.0], "error": [True, False]}, {"intensity": [1e300]})
    yield "basis", shown(lambda: _basis_methods(rng, iblbake.basis(pano, bname, **kw4, **opts)),
                         {"name": bname, **kw4, **opts})
    kw5 = c({"panorama": [pano], "size": [None, 4, 8], "levels": [None, 2, 3], "layout": ["equirect", "cubemap",
             "octahedral"], "min_size": [1, 8], "method": ["auto", "fis", "spectral", "convolve"],
             "samples": [16, 64], "backend": ["numpy"], "device": dev, "progress": [None, lambda _n: None]},
            {"size": [1, 2 ** 20, 2 ** 40, 8192], "levels": [32, 33, 40, 2 ** 20], "min_size": [2 ** 40],
             "samples": [2 ** 21, 2 ** 40], "backend": ["opencl"]})
    yield "prefilter", shown(lambda: iblbake.prefilter(**kw5), kw5)
    kw6 = c({"size": [2, 8, 16], "samples": [8, 64], "multiscatter": [False, True], "backend": ["numpy"],
             "device": dev}, {"size": [4097, 1, 2 ** 40], "samples": [2 ** 21, 2 ** 40], "backend": ["opencl"]})
    yield "dfg", shown(lambda: iblbake.dfg(**kw6), kw6)
    doc = scene_doc(sky)
    kw7 = c({"path_or_dict": [doc, mutate_scene(rng, doc), mutate_scene(rng, doc)],
             "overrides": [(), "effects.sh_bands=2"],
             "folder": [folder], "outputs": [None, folder / "x.png"], "names": names_ok},
            {"overrides": [["camera.resolution=[100000, 100000]"], ["x"], ["effects.sh_bands=1e300"]]})
    yield "load_scene", shown(lambda: iblbake.load_scene(**kw7), kw7)
    sc = iblbake.load_scene(doc)
    kw8 = c({"scene": [sc, doc], "device": dev, "cache": [ctx["cache"]], "warn": [None, lambda _m: None],
             "progress": [None], "profile_paths": [False]},
            {"scene": [mutate_scene(rng, doc), iblbake.load_scene(doc, ["camera.resolution=[16384, 16384]"])]})
    yield "render", shown(lambda: iblbake.render(**kw8), kw8)
    kw9 = c({"device": dev, "cache": [ctx["cache"]], "reuse": [True, False]}, {"cache": [folder / "sky.exr"]})
    yield "Renderer", shown(lambda: iblbake.Renderer(**kw9).render(doc), kw9)
    probes = {**doc, "probes": {"counts": [3, 2, 3], "rays": 16},
              "objects": doc["objects"] + [{"plane": {"point": [0, -1, 0], "size": 4}, "material": "m"}]}
    kw10 = c({"scene": [probes], "device": dev, "cache": [ctx["cache"]], "warn": [None], "progress": [None]},
             {"scene": [mutate_scene(rng, probes)]})
    yield "bake_probes", shown(lambda: iblbake.bake_probes(**kw10), kw10)
    kw11 = c({"scene": [doc], "ladder": [None, "realtime"], "max_side": [8], "repeats": [1], "max_samples": [8],
              "target_noise": [0.01], "visibility": [True], "flip": [False], "cache": [ctx["cache"]], "device": dev,
              "jobs": [1]}, {"max_side": [8192, 8193], "max_samples": [1 << 20], "repeats": [100, 101]})

    def study():
        try:
            iblbake.accuracy(**kw11, before_run=_stop)
        except Stop:
            pass
    yield "accuracy", shown(study, kw11)


def shown(thunk, kw):
    """The thunk, with its arguments as the start line shows them (to reproduce a finding)."""
    thunk.args = {k: " ".join(repr(v).split())[:80] for k, v in kw.items()}
    return thunk


def _stop(*_a):
    raise Stop


def _sh_methods(rng, s):
    for m in ("to_filament", "to_threejs", "to_gltf", "to_glsl"):
        getattr(s, m)()
    s.export(rng.choice(["iblbake", "glsl", "filament", "x", 3]))


def _basis_methods(rng, b):
    """The Basis's methods, with valid arguments mostly (a wrong one at times)."""
    good = [[[0.0, 1.0, 0.0]], [0, 1, 0], np.zeros((0, 3)), [[[0, 1, 0]]]]
    bad = [[[0, 2, 0]], "up", [[math.nan, 0, 1]], np.broadcast_to(np.array([0.0, 1.0, 0.0]), (1 << 28, 3)), None]
    normals = rng.choice(good * 3 + bad)
    b.irradiance(normals)
    if b.specular:
        b.specular_radiance(normals, rng.choice([normals, normals, [[0.0, 0.6, 0.8]]]),
                            rng.choice([0.5, 0.5, [0.5], 2.0, math.nan, "r", np.ones((1 << 20,))]))
    b.to_glsl()
    b.export(rng.choice(["iblbake", "glsl", "iblbake", "x"]))


def main(folder, seed, n):
    folder = Path(folder)
    sky = folder / "sky.exr"
    if not sky.exists():
        from iblbake.io import images
        v = (np.arange(16)[:, None, None] + 0.5) / 16
        images.write_exr(sky, (np.where(v < 0.5, [0.6, 0.8, 1.0], [0.1, 0.08, 0.05]) * np.ones((16, 32, 1)))
                         .astype(np.float32))
    ctx = {"sky": str(sky), "folder": folder, "cache": folder / "cache", "pano": iblbake.load_panorama(sky)}
    rng = random.Random(seed)
    for i in range(n):
        name, thunk = rng.choice(list(calls(rng, ctx)))
        print(json.dumps({"start": i, "call": name, "args": getattr(thunk, "args", "")}), flush=True)
        t0 = time.perf_counter()
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            try:
                thunk()
                outcome, msg = "ok", ""
            except iblbake.Error as e:
                outcome, msg = ("error", str(e)) if "\n" not in str(e).strip() else ("raw", f"two lines: {e}")
            except Exception:               # noqa: BLE001 - every other exception is the finding
                outcome, msg = "raw", traceback.format_exc()[-1500:]
        if said and outcome != "raw":       # a Python warning would reach the user's stderr
            outcome, msg = "raw", f"warning {said[0].category.__name__}: {said[0].message} ({said[0].filename}:" \
                                  f"{said[0].lineno})"
        print(json.dumps({"case": i, "call": name, "outcome": outcome, "message": msg,
                          "seconds": round(time.perf_counter() - t0, 4),
                          "peak_rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}), flush=True)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]))
