"""Nothing read without a limit (issue 43): every path iblbake reads (scenes, ladders, panoramas,
meshes, glTF buffers and images, textures, layouts, frames to compare, cached files) is checked
to be a regular file within its kind's size limit before it is opened. /dev/zero, /dev/urandom, a
FIFO, a link to one and a 3 GB sparse file each fail at once in one line naming the file and the
limit (they read forever, blocked, or filled memory: `render /dev/zero` grew 350 MB/s into a
MemoryError, `sh FIFO.exr` never finished)."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import scene_file, write_exr

WORKER = Path(__file__).with_name("reads_worker.py")
# every reader, by the suffix its files have
KINDS = {"scene": ".yaml", "ladder": ".yaml", "panorama": ".exr", "scene-panorama": ".exr", "mesh": ".glb",
         "texture": ".png", "gltf-buffer": ".bin", "gltf-image": ".png", "layout": ".json", "compare": ".png",
         "manifest": ".json"}
SPARSE = 3 << 30          # a 3 GB file that takes no disk (a hole)


def specials(folder: Path, suffix: str) -> dict:
    """name -> path of each special input, the links and the sparse file named with `suffix`."""
    folder.mkdir(parents=True, exist_ok=True)
    fifo = folder / f"fifo{suffix}"
    if not fifo.exists():
        os.mkfifo(fifo)
    out = {"/dev/zero": Path("/dev/zero"), "/dev/urandom": Path("/dev/urandom"), "fifo": fifo}
    for name, target in (("link to /dev/zero", "/dev/zero"), ("link to a fifo", fifo)):
        link = folder / f"{name.replace(' ', '-').replace('/', '')}{suffix}"
        if not link.is_symlink():
            os.symlink(target, link)
        out[name] = link
    sparse = folder / f"sparse{suffix}"
    with open(sparse, "wb") as f:
        f.truncate(SPARSE)
    out["3 GB sparse"] = sparse
    return out


def test_every_reader_refuses_special_and_oversized_files_at_once(tmp_path, stress):
    cases = []
    for kind, suffix in KINDS.items():
        for name, path in specials(tmp_path / kind, suffix).items():
            if kind == "manifest" and name == "3 GB sparse":
                path = tmp_path / kind / "sparse-manifest.json"
                path.write_bytes(b"")
                with open(path, "wb") as f:
                    f.truncate(SPARSE)
            cases.append((kind, str(path), name))
    spec = tmp_path / "cases.json"
    spec.write_text(json.dumps([c[:2] for c in cases]))
    # a glTF naming /dev/zero is refused first as a path out of its folder (tests/test_trust.py):
    # allowed here, so that the bounded read behind that rule is what this test sees
    p = subprocess.run([sys.executable, str(WORKER), str(tmp_path), str(spec)], capture_output=True, text=True,
                       timeout=900, env={**os.environ, "IBLBAKE_ALLOW_OUTSIDE": "1"})
    results = [json.loads(line) for line in p.stdout.splitlines()]
    assert p.returncode == 0 and len(results) == len(cases), p.stderr[-2000:]
    bad = []
    for (kind, path, name), r in zip(cases, results):
        msg = r["message"]
        if kind == "manifest":      # a cache file is no input: the entry is rebuilt, nothing waits on it
            ok = r["outcome"] == "ok"
        else:
            ok = r["outcome"] == "error" and path in msg and len(msg.splitlines()) == 1 and (
                ("not a regular file" in msg and "of at most" in msg) if name != "3 GB sparse" else
                ("3 GiB, over the limit of" in msg))
        if not (ok and r["seconds"] < 1.0):
            bad.append(f"{kind} {name}: {r['outcome']} in {r['seconds']} s: {msg[:300]}")
    assert not bad, f"{len(bad)} of {len(cases)}:\n" + "\n".join(bad)
    for (kind, _, name), r in zip(cases, results):
        stress.check(f"bounded read: {kind} from {name}", r["seconds"], 1.0, "seconds to refuse")
    stress.count("inputs fuzzed", len(cases))


def _cli(*args, timeout=60):
    """The CLI with a short limit: a hang is a failure, not a stuck test run."""
    try:
        return subprocess.run([sys.executable, "-m", "iblbake.cli", *map(str, args)], capture_output=True,
                              text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(f"iblbake {' '.join(map(str, args))} did not finish in {timeout} s")


def _one_line(p, *needles):
    assert p.returncode == 1, (p.returncode, p.stderr[-500:])
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in p.stderr, p.stderr[-800:]
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


def test_commands_name_the_special_file_and_the_limit(tmp_path):
    """The CLI's line: render /dev/zero, render FIFO.yaml, sh FIFO.exr, accuracy --ladder /dev/zero,
    each at once (they read forever or blocked)."""
    env = write_exr(tmp_path / "e.exr", np.full((8, 16, 3), 0.5, np.float32))
    scene = scene_file(tmp_path, env)
    fifo_yaml, fifo_exr = tmp_path / "s.yaml", tmp_path / "p.exr"
    os.mkfifo(fifo_yaml)
    os.mkfifo(fifo_exr)
    t0 = time.perf_counter()
    _one_line(_cli("render", "/dev/zero"), "/dev/zero", "a character device", "1 MiB")
    _one_line(_cli("render", fifo_yaml), str(fifo_yaml), "a FIFO", "1 MiB")
    _one_line(_cli("sh", fifo_exr, "--backend", "numpy"), str(fifo_exr), "a FIFO", "GiB")
    _one_line(_cli("accuracy", scene, "--ladder", "/dev/zero"), "/dev/zero", "1 MiB")
    assert time.perf_counter() - t0 < 30


def test_an_output_that_is_a_fifo_is_refused_not_read(tmp_path):
    """sh's overwrite check read the existing output's head: a FIFO there blocked it."""
    env = write_exr(tmp_path / "e.exr", np.full((8, 16, 3), 0.5, np.float32))
    out = tmp_path / "out.json"
    os.mkfifo(out)
    _one_line(_cli("sh", env, "-o", out, "--backend", "numpy"), str(out), "not a regular file")
