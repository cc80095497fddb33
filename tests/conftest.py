import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PANORAMAS = ROOT / "examples" / "panoramas"
PANORAMA_NAMES = ("city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset")


@pytest.fixture(scope="session")
def rt():
    """The OpenCL runtime on the device iblbake would pick (tests need a working one: make opencl)."""
    from iblbake import cl
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
    from iblbake import images
    cache = {}

    def load(name):
        if name not in cache:
            cache[name] = images.read_panorama(panoramas[name])[0]
        return cache[name]
    return load


def write_exr(path, image, half=False):
    from iblbake import images
    images.write_exr(path, np.asarray(image, dtype=np.float32), half=half)
    return str(path)


def run_cli(*args, cwd=None, env=None):
    """Run the installed CLI in a subprocess (end-to-end: exit codes, stderr, no tracebacks)."""
    full_env = dict(os.environ)
    full_env.pop("IBLBAKE_DEBUG", None)
    if env:
        full_env.update(env)
    return subprocess.run([sys.executable, "-m", "iblbake.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, env=full_env, timeout=600)


def rel_err(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))
