"""Nothing is lost (issue 7): SIGKILL/SIGINT at random points never leaves a partial output under
its final name nor a cache entry a later run would accept; outputs never overwrite what they should
not; a full disk or a read-only folder gives a one-line error and leaves nothing half-written."""

import contextlib
import json
import os
import random
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from iblbake.bake import cache
from iblbake.io import images

from tests.helpers import ROOT, mounted_tmpfs, read_only_folder, run_cli, scene_file, stress_scale, write_exr


def cli(*args):
    return [sys.executable, "-m", "iblbake.cli", *map(str, args)]


def cache_entries_ok(root: Path):
    """(complete entries, partial entries): every visible entry folder must verify."""
    good, bad = 0, []
    if not root.exists():
        return 0, []
    for d in root.iterdir():
        if d.is_dir() and not d.name.startswith("."):
            if cache.verify(d) is None:
                bad.append(d.name)
            else:
                good += 1
    return good, bad


def readable_image(path: Path, shape):
    try:
        img = images.read_exr(path) if path.suffix == ".exr" else _read_png(path)
    except Exception:
        return False
    return img.shape[:2] == shape and np.isfinite(img).all()


def _read_png(path):
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ValueError(oiio.geterror())
    data = inp.read_image(0, 0, 0, inp.spec().nchannels, oiio.UINT8)
    inp.close()
    if not isinstance(data, np.ndarray):
        raise ValueError("truncated")
    return data


def kill_loop(stress, name, cmd, runs, check, window, seed):
    """Start `cmd`, send SIGKILL or SIGINT after a random delay within `window`, check what is left
    on disk after every run; then a run left alone must succeed."""
    rng = random.Random(seed)
    partial = 0
    for k in range(runs):
        p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        time.sleep(rng.uniform(*window))
        sig = signal.SIGKILL if k % 2 else signal.SIGINT
        p.send_signal(sig)
        try:
            _, err = p.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            p.kill()
            raise
        if sig == signal.SIGINT and p.returncode not in (0, 130, -signal.SIGINT):
            pytest.fail(f"{name}: SIGINT gave exit {p.returncode}: {err.decode()[-300:]}")
        if sig == signal.SIGINT:
            assert b"Traceback" not in err, err.decode()[-500:]
        partial += check()
    stress.count("kill-runs", runs)
    stress.count("partial files found", partial)
    stress.check(f"kill {name} x{runs} (SIGKILL/SIGINT): partial outputs or cache entries", partial, 0, "count")
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    assert check() == 0


@pytest.fixture(scope="module")
def random_env(tmp_path_factory):
    d = tmp_path_factory.mktemp("env")
    return Path(write_exr(d / "e.exr", (np.random.default_rng(0).random((128, 256, 3)) * 3).astype(np.float32)))


@pytest.mark.kill
def test_kill_loop_mips(tmp_path, stress, random_env):
    root = tmp_path / "cache"
    cmd = cli("mips", random_env, "--cache", root, "--samples", "512", "--dfg-size", "64", "-q")

    def check():
        _, bad = cache_entries_ok(root)
        return len(bad)

    kill_loop(stress, "mips", cmd, stress_scale(12, 24), check, (0.2, 4.0), seed=3)
    good, bad = cache_entries_ok(root)
    assert good == 3 and not bad      # radiance, prefiltered, dfg


_CTRL_C_IN_EXTENSION_INIT = """
import enum, os, signal, sys
from iblbake import entry
entry.loaded()
create = enum.EnumType.__call__
def ctrl_c_then_create(cls, *args, **kw):
    # Called straight from an extension module's initialisation (the caller's frame is
    # importlib's): press Ctrl-C there, as a user might while `iblbake mips` loads pyopencl.
    if sys._getframe(1).f_code.co_filename.startswith("<frozen importlib"):
        os.kill(os.getpid(), signal.SIGINT)
    return create(cls, *args, **kw)
enum.EnumType.__call__ = ctrl_c_then_create
try:
    __import__(sys.argv[1])
    while True:
        pass
except KeyboardInterrupt:
    enum.EnumType.__call__ = create
    print(type(sys.modules[sys.argv[1]]).__name__)
    sys.exit(130)
"""


@pytest.mark.parametrize("module", ["pyopencl", "OpenImageIO"])
def test_ctrl_c_inside_an_extension_import_is_raised_after_it(module):
    """A KeyboardInterrupt raised while nanobind creates an enum aborts the process (exit -6: CI
    saw it once in `mips`' kill loop); once loaded, the CLI holds a Ctrl-C back until the import
    is done, then raises it."""
    p = subprocess.run([sys.executable, "-c", _CTRL_C_IN_EXTENSION_INIT, module],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 130, p.stderr[-500:]
    assert p.stdout.strip() == "module"


def test_ctrl_c_as_a_checked_read_opens_its_file_stays_a_ctrl_c(tmp_path, monkeypatch):
    """A Ctrl-C landing as os.fdopen returns, before its file object is bound, drops that object:
    the descriptor must be closed once, so the KeyboardInterrupt is what surfaces (CI's kill loop
    saw `render` exit 1 on an EBADF when the descriptor was closed twice)."""
    from iblbake.io import reads

    real = os.fdopen

    def fdopen_then_ctrl_c(*args, **kw):
        real(*args, **kw)              # the object, never bound, is dropped: it closes what it owns
        raise KeyboardInterrupt

    path = tmp_path / "x.bin"
    path.write_bytes(b"abc")
    monkeypatch.setattr(os, "fdopen", fdopen_then_ctrl_c)
    opened = len(os.listdir("/proc/self/fd"))
    with pytest.raises(KeyboardInterrupt):
        reads.read_bytes(path, 100)
    monkeypatch.undo()
    assert len(os.listdir("/proc/self/fd")) == opened      # and not leaked either
    assert reads.read_bytes(path, 100) == b"abc"


@pytest.mark.kill
def test_a_held_ctrl_c_at_the_end_of_a_run_does_not_kill_it_with_an_alarm(tmp_path):
    """A Ctrl-C held back by an import that ends the run: the run's work is done and it exits 0,
    not by the retry alarm firing after Python restored SIGALRM's default (exit -14)."""
    # The module presses Ctrl-C while it is imported and leaves an object whose teardown at exit
    # takes 0.1 s (a slow library teardown): time for a retry alarm still armed at the end to
    # fire after Python has restored SIGALRM's default action.
    (tmp_path / "presses_ctrl_c.py").write_text(
        "import os, signal, time\n"
        "class SlowTeardown:\n"
        "    def __del__(self):\n"
        "        end = time.monotonic() + 0.1\n"
        "        while time.monotonic() < end:\n"
        "            pass\n"
        "kept = SlowTeardown()\n"
        "os.kill(os.getpid(), signal.SIGINT)\n")
    script = "from iblbake import entry\nentry.loaded()\nimport presses_ctrl_c\n"
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60,
                       env={**os.environ, "PYTHONPATH": str(tmp_path)}, cwd=tmp_path)
    assert p.returncode == 0, (p.returncode, p.stderr[-500:])


def _scene(folder: Path, env: Path, **effects):
    return scene_file(folder, env, camera={"perspective": {"position": [0, 0, 4]}, "resolution": [160, 120]},
                      environment={"background": "show"},
                      materials={"base_color": [0.9, 0.6, 0.3], "metallic": 0.5, "roughness": 0.4},
                      effects={"specular": "importance", "samples": 64, **effects},
                      output={"frame": ["out/frame.png", "out/frame.exr"], "normal": "out/normal.exr",
                              "depth": "out/depth.exr"})


@pytest.mark.kill
def test_kill_loop_render(tmp_path, stress, random_env):
    scene = _scene(tmp_path, random_env)
    root = tmp_path / "cache"
    outs = [tmp_path / "out" / n for n in ("frame.png", "frame.exr", "normal.exr", "depth.exr")]
    cmd = cli("render", scene, "--cache", root, "-q")

    def check():
        bad = sum(1 for o in outs if o.exists() and not readable_image(o, (120, 160)))
        bad += len(cache_entries_ok(root)[1])
        for o in outs:             # the next run must not be able to pass on an old frame
            with contextlib.suppress(FileNotFoundError):
                o.unlink()
        return bad

    kill_loop(stress, "render", cmd, stress_scale(12, 24), check, (0.2, 3.5), seed=4)


@pytest.mark.kill
def test_kill_loop_sheet(tmp_path, stress, random_env):
    """A 3 x 3 sheet with its frames and layout: a kill at any point leaves no partial sheet, frame
    or layout under its final name and no partial cache entry."""
    scene = _scene(tmp_path, random_env)
    root = tmp_path / "cache"
    outs = [tmp_path / "sheet.png", tmp_path / "sheet.exr"]
    frames = tmp_path / "frames"
    layout = tmp_path / "sheet.json"
    cmd = cli("sheet", scene, "-o", outs[0], "-o", outs[1], "--cache", root, "-q", "--frames", frames,
              "--layout", layout, "--rows", "materials.m.roughness=0.1:0.9:3", "--columns", "effects.samples=8,32,64")

    def check():
        bad = sum(1 for o in outs if o.exists() and not readable_image(o, _shape(o)))
        # final names only: a SIGKILL may leave a hidden .NAME.tmp-* that no reader takes for a frame
        bad += sum(1 for f in frames.glob("[!.]*.png") if not readable_image(f, (120, 160)))
        if layout.exists():
            try:
                json.loads(layout.read_text())
            except ValueError:
                bad += 1
        bad += len(cache_entries_ok(root)[1])
        for o in [*outs, layout, *frames.glob("*")]:
            with contextlib.suppress(FileNotFoundError):
                o.unlink()
        return bad

    kill_loop(stress, "sheet", cmd, stress_scale(8, 24), check, (0.2, 3.0), seed=5)


def _shape(path: Path):
    """A finished sheet's size: whatever it is, it must read whole (the check is readability)."""
    import OpenImageIO as oiio
    spec = oiio.ImageInput.open(str(path))
    if spec is None:
        return (-1, -1)
    s = spec.spec()
    spec.close()
    return (s.height, s.width)


@pytest.mark.kill
def test_kill_loop_export_gltf(tmp_path, stress, random_env):
    """A .gltf light with its 30 face PNGs and a .glb: a kill leaves any PNG whole (or absent), the
    .gltf only once every PNG it names is there, no partial .glb and no partial cache entry."""
    root = tmp_path / "cache"
    gl, glb = tmp_path / "l.gltf", tmp_path / "l.glb"
    runs = [cli("export-gltf", random_env, "-o", out, "--cache", root, "--size", "64", "--min-size", "4", "-q")
            for out in (gl, glb)]

    def check():
        from iblbake.io import gltf
        bad = len(cache_entries_ok(root)[1])
        for png in tmp_path.glob("l_specular_*.png"):
            bad += not readable_image(png, _shape(png)) or _shape(png)[0] < 4
        if gl.exists():
            doc = json.loads(gl.read_text())
            bad += sum(not (tmp_path / im["uri"]).is_file() for im in doc["images"])
        if glb.exists():
            bad += not gltf.written_by_iblbake(glb) or glb.stat().st_size != int.from_bytes(glb.read_bytes()[8:12], "little")
        for o in [gl, glb, *tmp_path.glob("l_specular_*.png")]:
            o.unlink(missing_ok=True)
        return bad

    for k, cmd in enumerate(runs):
        kill_loop(stress, f"export-gltf {'.gltf' if k == 0 else '.glb'}", cmd, stress_scale(6, 12), check,
                  (0.2, 2.5), seed=6 + k)


@pytest.mark.kill
def test_kill_loop_sh(tmp_path, stress):
    env = write_exr(tmp_path / "e.exr", np.random.default_rng(0).random((256, 512, 3)).astype(np.float32))
    out = tmp_path / "out.json"
    cmd = cli("sh", env, "-o", out, "--backend", "numpy", "--bands", "8")

    def check():
        bad = 0
        if out.exists():      # finished before the signal: then it is complete JSON
            try:
                json.loads(out.read_text())
            except ValueError:
                bad = 1
            out.unlink()
        # SIGKILL can leave a hidden temp file (never under the final name); it is harmless
        leftovers = [x.name for x in tmp_path.iterdir() if x.name not in ("e.exr", "out.json")]
        return bad + sum(not x.startswith(".out.tmp-") for x in leftovers)

    kill_loop(stress, "sh", cmd, stress_scale(20, 24), check, (0.01, 0.8), seed=2)   # from start-up on


@pytest.mark.kill
def test_ctrl_c_on_a_fresh_install_is_exit_130(tmp_path):
    """Ctrl-C in the first milliseconds of a fresh clone's first run, every module compiled from
    source (a copy of the package with no __pycache__, PYTHONDONTWRITEBYTECODE): exit 130, 0 or
    the signal, never a traceback (a fresh clone's make test once got exit 1 from a Ctrl-C in
    _compile_bytecode; the editable install's import-hook finder imported pathlib and re inside
    site for 10-25 ms: the Makefile installs the plain path .pth now). The signal comes after the
    interpreter's own start-up for -m, measured here on an empty module (runpy and what it imports):
    before it, no line of iblbake has run."""
    import shutil
    import statistics
    copy = tmp_path / "src"
    shutil.copytree(ROOT / "iblbake", copy / "iblbake", ignore=shutil.ignore_patterns("__pycache__"))
    env = {**os.environ, "PYTHONPATH": str(copy), "PYTHONDONTWRITEBYTECODE": "1"}
    env.pop("CI", None)
    (copy / "empty_module.py").write_text("")
    floor = []
    for _ in range(3):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "empty_module"], env=env, check=True)
        floor.append(time.perf_counter() - t0)
    start = 1.5 * statistics.median(floor)
    src = write_exr(tmp_path / "e.exr", np.full((8, 16, 3), 0.5, np.float32))
    out = tmp_path / "sh.json"
    rng = random.Random(7)
    for _ in range(stress_scale(12, 40)):
        p = subprocess.Popen([sys.executable, "-m", "iblbake.cli", "sh", src, "-o", out, "--backend", "numpy"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
        time.sleep(rng.uniform(start, start + 0.25))
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=120)
        assert p.returncode in (0, 130, -signal.SIGINT) and b"Traceback" not in err, (p.returncode, err.decode()[-400:])
        if out.exists():
            assert json.loads(out.read_text())["format"] == "iblbake.sh"
    assert not list(copy.rglob("__pycache__"))        # every run compiled the package afresh


# --- overwriting and escaping ---------------------------------------------------------------------

def test_sh_overwrites_only_its_own_documents(tmp_path, stress):
    env = write_exr(tmp_path / "e.exr", np.full((8, 16, 3), 0.5, np.float32))
    precious = tmp_path / "notes.json"
    precious.write_text('{"mine": true}\n')
    p = run_cli("sh", env, "-o", precious, "--backend", "numpy")
    assert p.returncode == 1 and "--force" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    assert precious.read_text() == '{"mine": true}\n'
    # its own earlier output is replaced (Makefile reruns), and --force replaces anything
    own = tmp_path / "sh.json"
    for _ in range(2):
        assert run_cli("sh", env, "-o", own, "--backend", "numpy").returncode == 0
    assert run_cli("sh", env, "-o", precious, "--backend", "numpy", "--force").returncode == 0
    assert json.loads(precious.read_text())["format"] == "iblbake.sh"
    # never its input, even with --force
    before = Path(env).read_bytes()
    p = run_cli("sh", env, "-o", env, "--force", "--backend", "numpy")
    assert p.returncode == 1 and "input" in p.stderr and Path(env).read_bytes() == before
    stress.count("partial files found", 0)


def test_render_never_overwrites_its_inputs_or_leaves_its_folder(tmp_path, random_env):
    import shutil
    env = tmp_path / "env.exr"
    shutil.copy(random_env, env)
    scene = _scene(tmp_path, env)
    before = env.read_bytes()
    p = run_cli("render", scene, "-o", env)
    assert p.returncode == 1 and "is the panorama, which this command reads" in p.stderr, p.stderr
    assert env.read_bytes() == before
    p = run_cli("render", scene, "-o", scene.with_suffix(".png"), "--set", f"output.depth={env.name}")
    assert p.returncode == 1 and "output.depth" in p.stderr and env.read_bytes() == before, p.stderr
    for bad in ("../../escaped.png", "/tmp/abs/escaped.png"):
        p = run_cli("render", scene, "--set", f"output.frame=[{bad}]")
        if bad.startswith("/"):   # an absolute path in a scene is the user's explicit choice
            continue
        assert p.returncode == 1 and "leaves the scene's folder" in p.stderr, p.stderr
    assert not (tmp_path.parent.parent / "escaped.png").exists()


# --- disk full, read-only ----------------------------------------------------------------------

def _leftovers(folder: Path, keep):
    return sorted(x.name for x in folder.rglob("*") if x.name not in keep and not x.is_dir())


def _limited(fsize):
    def pre():
        resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
    return pre


def _one_line_failure(p, *needles):
    assert p.returncode == 1, (p.returncode, p.stderr[-400:])
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    for n in needles:
        assert n in p.stderr, (n, p.stderr)


@pytest.fixture(scope="module")
def warm(random_env, tmp_path_factory):
    """Build the kernels once without limits, so the limited runs only write their outputs."""
    d = tmp_path_factory.mktemp("warm")
    assert subprocess.run(cli("mips", random_env, "--cache", d / "c", "--size", "32", "-q")).returncode == 0
    scene = _scene(d, random_env)
    assert subprocess.run(cli("render", scene, "--cache", d / "c", "-q", "-o", d / "warm.exr")).returncode == 0
    assert subprocess.run(cli("render", scene, "--cache", d / "c", "-q", "-o", d / "warm.png")).returncode == 0
    return d


@pytest.mark.slow
def test_file_size_limit_fails_cleanly(tmp_path, stress, random_env, warm):
    """A write that hits the file-size limit (RLIMIT_FSIZE: what a full disk looks like to a
    writer) gives a one-line error naming the file; no final or temp file is left."""
    out = tmp_path / "sh.json"
    p = subprocess.run(cli("sh", random_env, "-o", out, "--backend", "numpy", "--bands", "16"),
                       capture_output=True, text=True, preexec_fn=_limited(4096))
    _one_line_failure(p, "sh.json")
    # PoCL writes up to ~1 MB of preprocessed source into its own cache on every run (and its
    # LLVM aborts if that fails), so the OpenCL commands get 4 MB and outputs larger than that
    frame = tmp_path / "f.exr"
    p = subprocess.run(cli("render", _scene(tmp_path, random_env), "-o", frame, "--cache", warm / "c",
                           "--set", "camera.resolution=[1280,960]"),
                       capture_output=True, text=True, preexec_fn=_limited(4 << 20))
    _one_line_failure(p, "f.exr")
    big = write_exr(tmp_path / "big.exr", np.random.default_rng(1).random((1024, 2048, 3)).astype(np.float32))
    root = tmp_path / "cache"
    p = subprocess.run(cli("mips", big, "--cache", root, "--only", "radiance"),
                       capture_output=True, text=True, preexec_fn=_limited(4 << 20))
    _one_line_failure(p, str(root))
    left = _leftovers(tmp_path, {"scene.yaml", "big.exr"})
    assert cache_entries_ok(root) == (0, [])
    assert all(x.endswith(".lock") for x in left), left
    stress.count("partial files found", len([x for x in left if not x.endswith(".lock")]))


@pytest.mark.slow           # its warm-up builds over 3 s on the 2-core CPU: make test, not make check
def test_full_disk_fails_cleanly(tmp_path, stress, random_env, warm):
    """A 256 KiB tmpfs: sh, render and mips fail in one line and leave nothing (no temp files
    either, since the writer removes its own)."""
    with mounted_tmpfs(tmp_path / "small", "size=256k") as disk:
        filler = disk / "filler"
        with open(filler, "wb") as f:          # leave about 8 KiB free
            with contextlib.suppress(OSError):
                f.write(b"\0" * (248 << 10))
        p = run_cli("sh", random_env, "-o", disk / "sh.json", "--backend", "numpy", "--bands", "16")
        _one_line_failure(p, "sh.json")
        p = run_cli("render", _scene(tmp_path, random_env), "-o", disk / "f.exr", "--cache", warm / "c")
        _one_line_failure(p, "f.exr")
        p = run_cli("mips", random_env, "--cache", disk / "cache", "--size", "32")
        _one_line_failure(p, "cache")
        left = _leftovers(disk, {"filler"})
        assert all(x.endswith(".lock") for x in left), left
        assert cache_entries_ok(disk / "cache") == (0, [])


def test_read_only_folder_fails_cleanly(tmp_path, stress, random_env, warm):
    with read_only_folder(tmp_path / "ro") as ro:
        p = run_cli("sh", random_env, "-o", ro / "sh.json", "--backend", "numpy")
        _one_line_failure(p, "sh.json")
        p = run_cli("render", _scene(tmp_path, random_env), "-o", ro / "sub" / "f.png", "--cache", warm / "c")
        _one_line_failure(p, "f.png")
        p = run_cli("render", _scene(tmp_path, random_env), "-o", ro / "f.png", "--cache", warm / "c")
        _one_line_failure(p, "f.png")
        p = run_cli("mips", random_env, "--cache", ro / "cache", "--size", "32")
        _one_line_failure(p, "cache")
        p = run_cli("mips", random_env, "--cache", ro, "--size", "32")
        _one_line_failure(p, str(ro))
        assert not any(ro.iterdir())


@pytest.mark.kill
def test_ctrl_c_during_a_fresh_dfg_bake_is_prompt(tmp_path):
    """A fresh cache bakes the DFG table (67M samples: 5 s on a 2-core CPU); Ctrl-C during it ends
    the bake within a second and a half, not at its end (it was one launch: 5-8 s): the table is
    baked a band of rows a launch, and the signal lands between bands."""
    code = ("import sys, time; from pathlib import Path; from iblbake.bake import mips; "
            "b = mips.Baker('opencl'); b.dfg(8, 8, False); print('ready', flush=True); "
            f"mips.bake_dfg(b, Path({str(tmp_path / 'c')!r}), 128, 4096, False)")
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert p.stdout.readline().strip() == b"ready"     # the program built: the table's bake begins
    time.sleep(1.0)
    sent = time.time()
    p.send_signal(signal.SIGINT)
    p.wait(timeout=60)
    waited = time.time() - sent
    assert p.returncode != 0 and b"KeyboardInterrupt" in p.stderr.read()
    assert waited < 1.5, waited
    assert not list((tmp_path / "c").glob("dfg-*/dfg.exr"))        # nothing half-baked under its name
