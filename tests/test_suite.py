"""The test suite's own layout: test modules share helpers through tests/helpers.py,
tests/probe_helpers.py and conftest.py's fixtures, never by importing one another (a test module
imported by another is collected twice under two names, and its fixtures leak into the other)."""

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def _is_test_module(name: str) -> bool:
    """A dotted module name that is a test module of tests/ (or its conftest)."""
    last = name.rsplit(".", 1)[-1]
    return last.startswith("test_") or last == "conftest"


def cross_imports(folder: Path) -> list:
    """'FILE:LINE imports MODULE' for every import, function-level ones too, of a test module or
    conftest.py by a module of `folder`."""
    bad = []
    for f in sorted(folder.glob("*.py")):
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = ("tests." if node.level else "") + (node.module or "")
                names = [base] + [f"{base.rstrip('.')}.{a.name}" for a in node.names]
            else:
                continue
            for n in names:
                if (n.startswith("tests.") or n.startswith("test_") or n == "conftest") and _is_test_module(n):
                    bad.append(f"{f.name}:{node.lineno} imports {n}")
    return bad


def test_no_test_module_imports_another():
    bad = cross_imports(TESTS)
    assert not bad, f"share it through tests/helpers.py or a conftest fixture instead: {bad}"


def test_the_check_finds_each_spelling(tmp_path):
    spellings = ["from tests.test_render import x", "from .conftest import run_cli", "from . import test_sheet",
                 "import tests.test_probes", "def f():\n    from .test_sh import gauss_sphere"]
    for k, text in enumerate(spellings):
        (tmp_path / f"test_{k}.py").write_text(text + "\n")
    (tmp_path / "test_fine.py").write_text("from tests.helpers import run_cli\nfrom tests import poison_locals\n")
    assert [b.split(":")[0] for b in cross_imports(tmp_path)] == [f"test_{k}.py" for k in range(len(spellings))]
