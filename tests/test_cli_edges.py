"""What a new user met at the command line's edges (issue 60): `deps` without a target and its
--json, the exit codes the manual lists."""

import json
import re
from pathlib import Path

import numpy as np

from .conftest import ROOT, run_cli, scene_file, write_exr


def one_line_error(p, code, *words):
    assert p.returncode == code, (p.returncode, p.stderr)
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    for w in words:
        assert w in lines[0], lines[0]


def test_deps_names_a_target_or_asks_for_one(tmp_path):
    """A scene without output.frame made itself the rule's target (`scene.yaml: scene.yaml sky.exr`):
    make would think the scene file was built from itself. Now -o names it, or exit 2 says so."""
    sky = write_exr(tmp_path / "sky.exr", np.full((8, 16, 3), 0.5, np.float32))
    scene = scene_file(tmp_path, sky)
    p = run_cli("deps", scene, cwd=tmp_path)
    one_line_error(p, 2, "scene.yaml", "output.frame", "-o")
    assert p.stdout == ""
    p = run_cli("deps", scene, "-o", "f.png", "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert doc["targets"] == [str(tmp_path / "f.png")]
    assert doc["prerequisites"] == [str(scene), str(tmp_path / "sky.exr")]
    assert doc["rule"] == "f.png: \\\n  scene.yaml \\\n  sky.exr\n\nscene.yaml:\nsky.exr:\n"
    p = run_cli("deps", scene, "-o", "f.png", cwd=tmp_path)
    assert p.returncode == 0 and p.stdout == doc["rule"], p.stderr


def test_every_command_takes_json():
    """The README: every command prints --json on request (deps had none)."""
    import importlib

    from iblbake.cli.main import COMMANDS
    for name, (module, attr) in COMMANDS.items():
        cmd = getattr(importlib.import_module(f"iblbake.cli.{module}"), attr)
        subs = getattr(cmd, "commands", {}) or {name: cmd}
        for sub, c in subs.items():
            assert "--json" in [o for p in c.params for o in getattr(p, "opts", [])], (name, sub)


def test_the_manual_lists_every_exit_code():
    """Exit 3 (no OpenCL device, a kernel that failed) was documented nowhere."""
    from iblbake import errors
    text = (ROOT / "docs" / "manual.md").read_text()
    table = text[text.index("## Exit codes"):text.index("## Commands")]
    listed = {int(c) for c in re.findall(r"^\| (\d+) \|", table, re.M)}
    used = {c.exit_code for c in vars(errors).values() if isinstance(c, type) and hasattr(c, "exit_code")}
    assert used | {0, 130} == listed, listed
