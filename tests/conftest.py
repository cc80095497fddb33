import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest
import platformdirs
from hypothesis import settings
from hypothesis.configuration import set_hypothesis_home_dir

from tests.helpers import PANORAMA_NAMES, ROOT, STRESS, box_downsample

# `make test` (and CI) replays the same generated examples every run, so a result is reproducible;
# `make stress` (IBLBAKE_STRESS=1) draws new ones each time to keep searching.
# Hypothesis keeps its files (example database, constants cache) in the per-user cache folder, not
# in the working tree; `make test` needs no database (derandomized), `make stress` keeps its finds.
set_hypothesis_home_dir(os.path.join(platformdirs.user_cache_dir("iblbake"), "hypothesis"))
settings.register_profile("reproducible", derandomize=True, database=None)
settings.register_profile("search", derandomize=False)
settings.load_profile("search" if os.environ.get("IBLBAKE_STRESS") else "reproducible")

# Tests bake into a temporary folder, never into the working tree: a render or bake that names no
# cache folder of its own lands here (subprocesses inherit it).
_SESSION_CACHE = tempfile.mkdtemp(prefix="iblbake-test-cache-")
os.environ["IBLBAKE_CACHE"] = _SESSION_CACHE


def _tree_state():
    """Every file git would list in the working tree (tracked changes, untracked, ignored), or
    None outside a git checkout."""
    try:
        out = subprocess.run(["git", "status", "--porcelain", "--ignored", "--untracked-files=all"], cwd=ROOT,
                             capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return set(out.stdout.splitlines()) if out.returncode == 0 else None


_TREE_BEFORE = _tree_state()

# `make check-locals`: every kernel built in-process with its uninitialised locals poisoned (NaN)
if os.environ.get("IBLBAKE_POISON_LOCALS"):
    from tests import poison_locals
    poison_locals.install()


def pytest_sessionfinish(session, exitstatus):
    """`make test` leaves the working tree as it found it: nothing generated, nothing changed
    (Python's own __pycache__ aside). A new file fails the run and is named."""
    shutil.rmtree(_SESSION_CACHE, ignore_errors=True)
    after = _tree_state()
    if _TREE_BEFORE is None or after is None:
        return
    new = sorted(x for x in after - _TREE_BEFORE if "__pycache__" not in x and ".pytest_cache" not in x)
    if new:
        tr = session.config.pluginmanager.get_plugin("terminalreporter")
        tr.ensure_newline()
        tr.write_line(f"the test run left files in the working tree: {new[:10]}", red=True)
        session.exitstatus = 1


PANORAMAS = ROOT / "examples" / "panoramas"


@pytest.fixture(scope="session")
def rt():
    """The OpenCL runtime on the device iblbake would pick (tests need a working one: make opencl)."""
    from iblbake.device import runtime as cl
    return cl.Runtime()


@pytest.fixture(scope="session")
def panoramas():
    paths = {n: PANORAMAS / f"{n}.exr" for n in PANORAMA_NAMES}
    missing = [str(p) for p in paths.values() if not p.exists()]
    if missing:
        pytest.fail(f"example panoramas missing ({missing[0]}...): run `make assets`")
    return paths


@pytest.fixture(scope="session")
def load_panorama(panoramas):
    from iblbake.io import images
    cache = {}

    def load(name):
        if name not in cache:
            cache[name] = images.read_panorama(panoramas[name])[0]
        return cache[name]
    return load


@pytest.fixture(scope="module")
def small_panoramas(tmp_path_factory, load_panorama):
    """city and studio at 256x128: the same light, faster to bake (tests of plumbing)."""
    from iblbake.io import images
    d = tmp_path_factory.mktemp("small")
    out = {}
    for name in ("city", "studio"):
        out[name] = d / f"{name}.exr"
        images.write_exr(out[name], box_downsample(load_panorama(name), 4).astype(np.float32))
    return out


@pytest.fixture(scope="session")
def lobed_sky(tmp_path_factory):
    """A smooth 64 x 32 sky of three lobes of colour, no sun: the probe and SSR tests' panorama."""
    from iblbake.io import images
    p = tmp_path_factory.mktemp("lobed") / "sky.exr"
    v, u = np.meshgrid((np.arange(32) + 0.5) / 32, (np.arange(64) + 0.5) / 64, indexing="ij")
    img = np.stack([1 + 0.8 * np.cos(2 * np.pi * u), 1 + 0.6 * np.cos(np.pi * v), 1 + 0.5 * np.sin(2 * np.pi * u)], -1)
    images.write_exr(p, img.astype(np.float32))
    return p


# --- the stress report (issue 7): every stress case records its bound and what it measured ---------


class StressLog:
    """Rows of (case, bound, measured, pass) and counters, printed as the `make stress` table."""

    COUNTERS = ("inputs fuzzed", "crashes", "kill-runs", "partial files found")

    def __init__(self):
        self.rows = []
        self.counts = {k: 0 for k in self.COUNTERS}

    def check(self, case: str, measured: float, bound: float, what: str = "error"):
        """Record and assert measured <= bound (a NaN measurement fails)."""
        measured = float(measured)
        ok = measured <= bound
        self.rows.append((case, what, bound, measured, ok))
        assert ok, f"{case}: {what} {measured:.3g} exceeds the bound {bound:.3g}"

    def count(self, name: str, n: int = 1):
        self.counts[name] = self.counts.get(name, 0) + n

    def table(self) -> str:
        out = ["| case | measured | bound | result |", "|---|---|---|---|"]
        for case, what, bound, measured, ok in self.rows:
            out.append(f"| {case} | {what} {measured:.3g} | <= {bound:.3g} | {'pass' if ok else 'FAIL'} |")
        out += ["", "| count | value |", "|---|---|"]
        out += [f"| {k} | {v} |" for k, v in self.counts.items()]
        return "\n".join(out) + "\n"


_STRESS_LOG = StressLog()


@pytest.fixture(scope="session")
def stress():
    return _STRESS_LOG


def pytest_terminal_summary(terminalreporter):
    if not _STRESS_LOG.rows:
        return
    text = _STRESS_LOG.table()
    terminalreporter.write_sep("-", f"stress table ({len(_STRESS_LOG.rows)} cases)")
    terminalreporter.write(text)
    dest = os.environ.get("IBLBAKE_STRESS_REPORT")
    if dest:
        import datetime
        import platform
        from iblbake.io.atomic import write_text
        stats = terminalreporter.stats
        head = (f"# Stress table\n\nWritten by `make stress` ({'IBLBAKE_STRESS=1, ' if STRESS else ''}"
                f"{len(stats.get('passed', []))} passed, {len(stats.get('failed', []))} failed, "
                f"{len(stats.get('skipped', []))} skipped) on {platform.machine()} with {os.cpu_count()} cores, "
                f"{datetime.date.today().isoformat()}. Each row's bound is asserted by a test; the measured "
                f"value is this run's.\n\n")
        Path(dest).parent.mkdir(parents=True, exist_ok=True)
        write_text(dest, head + text)
        terminalreporter.write_line(f"stress table written to {dest}")


