"""docs/api.md's examples run: each in a fresh folder after the page's setup snippet (the
examples are the API's documentation, so a renamed argument or a changed result fails here)."""

import contextlib
import io
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "api.md"
# a fenced python block, with the HTML comment on the line before it where there is one
BLOCK = re.compile(r"(?:<!-- (\w+) -->\n)?```python\n(.*?)```", re.S)


def _blocks():
    found = [(tag or "", code) for tag, code in BLOCK.findall(PAGE.read_text())]
    setup = [code for tag, code in found if tag == "setup"]
    assert len(setup) == 1, "docs/api.md has one <!-- setup --> block"
    return setup[0], [(tag, code) for tag, code in found if tag != "setup"]


SETUP, EXAMPLES = _blocks()


def _title(code: str) -> str:
    """The section's function: the first iblbake.NAME( the example calls."""
    m = re.search(r"iblbake\.(\w+)\(", code)
    return m.group(1) if m else "example"


@pytest.mark.parametrize("code", [pytest.param(code, id=f"{i}-{_title(code)}",
                                               marks=[pytest.mark.slow] if tag == "slow" else [])
                                  for i, (tag, code) in enumerate(EXAMPLES)])
def test_example_runs(code, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "__docs__"}
    with contextlib.redirect_stdout(io.StringIO()):
        exec(compile(SETUP, "docs/api.md setup", "exec"), namespace)
        exec(compile(code, f"docs/api.md {_title(code)} example", "exec"), namespace)


def test_every_public_function_has_an_example():
    import iblbake
    shown = {name for _, code in EXAMPLES for name in re.findall(r"iblbake\.(\w+)\b", code)}
    functions = {n for n in iblbake.__all__ if n[0].islower()}
    assert functions <= shown, f"no example in docs/api.md calls {sorted(functions - shown)}"


@pytest.mark.parametrize("code", [pytest.param(code, id=f"{i}-{_title(code)}")
                                  for i, (tag, code) in enumerate(EXAMPLES)
                                  if tag != "slow" and re.search(r"print\(.*#", code)])
def test_what_an_example_says_it_prints_is_what_it_prints(code, tmp_path, monkeypatch):
    """A `print(...)  # TEXT` comment shows what the line prints ('...' where it leaves some out):
    load_scene's showed `did you mean diffuse?` where the message says `did you mean 'diffuse'?`."""
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "__docs__"}
    out = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()):
        exec(compile(SETUP, "docs/api.md setup", "exec"), namespace)
    with contextlib.redirect_stdout(out):
        exec(compile(code, f"docs/api.md {_title(code)} example", "exec"), namespace)
    shown = [m.group(1) for m in re.finditer(r"print\(.*#\s*(.*)$", code, re.M)]
    for comment in shown:
        for part in filter(None, (p.strip() for p in comment.split("..."))):
            assert part in out.getvalue(), f"the docs say {comment!r}; it printed {out.getvalue()!r}"
