"""kernels/ ships inside the package: an editable install and a built wheel both find it."""

import pytest
import subprocess
import sys
import zipfile
from pathlib import Path

from iblbake.device import programs as cl

ROOT = Path(__file__).resolve().parents[1]
KERNELS = sorted(p.relative_to(ROOT / "kernels").as_posix() for p in (ROOT / "kernels").rglob("*")
                 if p.suffix in (".cl", ".h"))     # paths/ too


def test_installed_package_finds_every_kernel():
    for name in KERNELS:
        assert cl.kernel_source(name).strip()
    # includes are inlined (the text hashed and built is what the compiler sees)
    assert '#include "' not in cl.kernel_source("mips.cl")


@pytest.mark.slow
def test_wheel_contains_the_kernels(tmp_path):
    import shutil
    src = tmp_path / "src"           # a copy: the build leaves build/ and egg-info beside its source
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "iblbake", "kernels"):
        (shutil.copytree if (ROOT / name).is_dir() else shutil.copy)(ROOT / name, src / name)
    p = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q",
                        "-w", str(tmp_path), str(src)], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    wheel = next(tmp_path.glob("iblbake-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    for k in KERNELS:
        assert f"iblbake/kernels/{k}" in names, k
    for page in ("report.html", "report.js", "report.css"):     # the report's page (study/html.py)
        assert f"iblbake/study/page/{page}" in names, page
    # every module of the source tree is in the wheel (a package missing from pyproject's list
    # imports in a checkout and fails only once installed)
    for py in (ROOT / "iblbake").rglob("*.py"):
        assert py.relative_to(ROOT).as_posix() in names, py


def test_source_checkout_without_install_finds_the_kernels(tmp_path):
    """PYTHONPATH=<checkout> python -m iblbake.cli with no install: the kernels come from kernels/.
    -S skips site's .pth files (where the editable install's finder lives); the dependencies'
    folder is put back on the path by hand."""
    import sysconfig
    site = sysconfig.get_paths()["purelib"]
    code = (f"import sys; sys.path.insert(0, {str(ROOT)!r}); sys.path.append({site!r}); "
            "import importlib.util as u; assert u.find_spec('iblbake.kernels') is None, 'installed'; "
            "from iblbake.device import programs; print(len(programs.kernel_source('paths/reference.cl')))")
    p = subprocess.run([sys.executable, "-S", "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert p.returncode == 0, p.stderr[-2000:]
    assert int(p.stdout) > 1000


HEAVY = ("numpy", "pyopencl", "OpenImageIO", "OpenEXR", "trimesh", "matplotlib", "yaml", "flip_evaluator")


def test_help_imports_nothing_heavy():
    """`iblbake --help` and every command's --help stay instant (Makefiles and shells call them
    often): none of them imports numpy, pyopencl, OpenImageIO or any other heavy module."""
    code = ("import contextlib, io, sys\n"
            "from iblbake.entry import main\n"
            "for args in ([], ['sh'], ['mips'], ['render'], ['sheet'], ['accuracy'], ['compare'], ['cache'], ['devices']):\n"
            "    sys.argv = ['iblbake', *args, '--help']\n"
            "    with contextlib.redirect_stdout(io.StringIO()):\n"
            "        try: main()\n"
            "        except SystemExit: pass\n"
            f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.strip() == "[]", p.stdout


def test_the_install_adds_no_import_hook_to_start_up():
    """make install's editable install is a path in a .pth (editable_mode=compat), not setuptools'
    import-hook finder, which site imported for 10-25 ms before any line of iblbake could hold a
    Ctrl-C back (tests/test_nothing_lost.py)."""
    import sysconfig
    site = Path(sysconfig.get_paths()["purelib"])
    assert not list(site.glob("__editable___iblbake*finder.py"))
