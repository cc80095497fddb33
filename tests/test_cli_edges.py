"""What a new user met at the command line's edges (issue 60): `deps` without a target and its
--json, every command's --json, the exit codes the manual lists, a missing mesh named by sheet and
accuracy as render names it, and the gallery's Makefile making the meshes its sheets read."""

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import ROOT, run_cli, scene_file, write_exr


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


def test_sheet_and_accuracy_name_a_missing_mesh_as_render_does(tmp_path):
    """A mesh file not made yet: `sheet` and `accuracy` ended in `internal error: FileNotFoundError`
    (they hash the scene's files before any render); now the line render prints, key and file, with
    the scene's line that names it (a new user's trial: every other error had one)."""
    sky = write_exr(tmp_path / "sky.exr", np.full((8, 16, 3), 0.5, np.float32))
    scene = scene_file(tmp_path, sky, objects=[{"mesh": {"path": "gone.ply"}, "material": "m"}],
                       camera={"resolution": [8, 8]})
    line = f"objects.0.mesh: mesh {tmp_path / 'gone.ply'} not found"
    p = run_cli("render", scene, "-o", tmp_path / "f.png")
    one_line_error(p, 1, f"{scene}:", line)
    assert re.match(rf"Error: {re.escape(str(scene))}:\d+: ", p.stderr), p.stderr     # the line naming it
    p = run_cli("sheet", scene, "-o", tmp_path / "s.png", "--columns", "effects.diffuse=sh,off",
                "--cache", tmp_path / "c")
    one_line_error(p, 1, line)
    p = run_cli("accuracy", scene, "-o", tmp_path / "acc", "--cache", tmp_path / "c")
    one_line_error(p, 1, line)
    assert not (tmp_path / "s.png").exists() and not (tmp_path / "acc").exists()
    # a path given by --set is blamed on the flag, not on the line of the file it replaced (trial72)
    p = run_cli("render", scene, "-o", tmp_path / "f.png", "--set", "objects.0.mesh.path=also_gone.ply")
    one_line_error(p, 1, f"{scene}: --set", f"objects.0.mesh: mesh {tmp_path / 'also_gone.ply'} not found")


# the scripts that make the gallery's meshes and textures (the top Makefile's `meshes` target)
MAKERS = {"meshes/knot.ply": "make_mesh.py", "meshes/tiles.glb": "make_textured.py",
          "textures/": "make_textured.py", "corpus/meshes/": "make_corpus.py"}


def test_the_gallery_makes_the_meshes_its_sheets_read(tmp_path):
    """`make -C examples` in a checkout without `make meshes`: every sheet that reads a mesh or a
    texture was run before anything made them (internal error: FileNotFoundError). A dry run in a
    copy without them: each such sheet comes after the script that makes every file it reads."""
    import shutil
    import subprocess
    ex = ROOT / "examples"
    for name in ("Makefile", "sheets", "scenes", "make_mesh.py", "make_textured.py", "make_corpus.py"):
        (shutil.copytree if (ex / name).is_dir() else shutil.copy)(ex / name, tmp_path / name)
    r = subprocess.run(["make", "-n", "-C", str(tmp_path), "IBLBAKE=IBL", "PYTHON=PY"], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    made, checked = set(), 0
    for cmd in r.stdout.splitlines():
        if cmd.startswith("PY "):
            made.add(cmd.split()[1])
        elif cmd.startswith("IBL sheet"):
            yaml_file = next(w for w in cmd.split() if w.endswith(".yaml"))
            reads = re.findall(r"path: \.\./((?:meshes|textures|corpus/meshes)/[^,}\s]+)",
                               (tmp_path / yaml_file).read_text())
            for f in reads:
                maker = next(m for prefix, m in MAKERS.items() if f.startswith(prefix))
                assert maker in made, (yaml_file, f, r.stdout)
                checked += 1
    assert checked >= 13, r.stdout          # mesh, ao, textured (6 files), roughness_map, probe_bases (5)


@pytest.mark.slow         # 7.6 s: three renders and bakes in subprocesses
def test_a_depfile_names_a_non_utf8_file_by_its_bytes(tmp_path):
    """A scene or output named by bytes that are not UTF-8 crashed --depfile (UnicodeEncodeError in
    the write); the rule is written with the raw bytes, as `deps` prints it."""
    sky = write_exr(tmp_path / "sky.exr", np.full((8, 16, 3), 0.5, np.float32))
    scene = scene_file(tmp_path, sky, name=os.fsdecode(b"\xfd.yaml"),
                       camera={"perspective": {"position": [0, 0, 3], "fov_y": 45}, "resolution": [8, 8]})
    out = os.fsdecode(b"\xfc.png")
    p = run_cli("render", scene.name, "-o", out, "--depfile", "x.d", "-q", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert (tmp_path / "x.d").read_bytes() == b"\xfc.png: \\\n  \xfd.yaml \\\n  sky.exr\n\n\xfd.yaml:\nsky.exr:\n"
    p = run_cli("sh", "sky.exr", "-o", out.replace(".png", ".json"), "--depfile", os.fsdecode(b"\xff.d"),
                "--backend", "numpy", "-q", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert (tmp_path / os.fsdecode(b"\xff.d")).read_bytes().startswith(b"\xfc.json: \\\n  sky.exr\n")


def test_json_names_a_non_utf8_file_in_valid_unicode(tmp_path):
    """A name that is not UTF-8 reached --json as a lone surrogate ('\\udcfd' escapes: strict readers
    refuse it, jq shows U+FFFD): its bytes are written as Python's backslashreplace shows them."""
    sky = write_exr(tmp_path / "sky.exr", np.full((8, 16, 3), 0.5, np.float32))
    scene = scene_file(tmp_path, sky, name=os.fsdecode(b"\xfd.yaml"),
                       camera={"perspective": {"position": [0, 0, 3], "fov_y": 45}, "resolution": [8, 8]})
    p = run_cli("deps", scene.name, "-o", os.fsdecode(b"\xfc.png"), "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "\\udc" not in p.stdout
    doc = json.loads(p.stdout)
    assert doc["targets"] == [f"{tmp_path}/\\xfc.png"], doc
    assert f"{tmp_path}/\\xfd.yaml" in doc["prerequisites"], doc


def test_usage_errors_are_one_line(tmp_path):
    """click's own usage errors (a value out of an option's range, an unknown command or option, a
    missing argument) took three lines (Usage, Try, Error): one line, naming the command's help."""
    one_line_error(run_cli("sh", tmp_path / "x.exr", "--bands", "0"), 2, "--bands", "iblbake sh --help")
    one_line_error(run_cli("shh"), 2, "shh", "iblbake --help")
    one_line_error(run_cli("sheet", tmp_path / "s.yaml", "-o", tmp_path / "x.png", "--jobs", "0"), 2, "--jobs")
    one_line_error(run_cli("render", "--no-such-option"), 2, "--no-such-option")
