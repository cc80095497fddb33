"""Nothing a user owns is overwritten, and every size is refused before work starts (issue 36):
every writing option of every command against every kind of file the command reads, two outputs
on one path, bake sizes over the machine's memory, malformed sweep ranges and --set values, one
rule for missing output folders."""

import hashlib
import json
import os
from pathlib import Path

import click
import numpy as np
import pytest
import yaml

from iblbake.cli.main import COMMANDS, cli
from iblbake.io import images
from iblbake.study import sweep

from tests.helpers import run_cli, write_exr

# Every path-valued option of every command, as what it does with the path. A new option that
# takes a path fails test_every_path_option_is_known until it is placed here (and, if it
# writes, walked below).
READS = {("accuracy", "ladder_path"), ("compare", "layout_path"), ("deps", "outputs")}
FOLDERS = {("accuracy", "cache_dir"), ("cache", "cache_dir"), ("mips", "cache_dir"), ("export-gltf", "cache_dir"),
           ("render", "cache_dir"), ("sheet", "cache_dir"), ("probes", "cache_dir"), ("lightmap", "cache_dir")}
WRITES = {("sh", "output"), ("sh", "depfile"), ("basis", "output"), ("basis", "depfile"), ("basis", "specular_table"),
          ("mips", "ktx2_path"), ("mips", "ktx2_irradiance"),
          ("mips", "ktx2_sheen"), ("mips", "depfile"), ("export-gltf", "output"), ("export-gltf", "depfile"),
          ("render", "outputs"), ("render", "depfile"), ("sheet", "outputs"), ("sheet", "layout_path"),
          ("sheet", "depfile"), ("sheet", "frames_dir"), ("sheet", "html_dir"), ("accuracy", "out_dir"),
          ("probes", "out_dir"), ("lightmap", "out_dir")}


def _path_options():
    ctx = click.Context(cli)
    for name in COMMANDS:
        cmd = cli.get_command(ctx, name)
        for sub in (cmd.commands.values() if isinstance(cmd, click.Group) else [cmd]):
            for p in sub.params:
                if isinstance(p, click.Option) and isinstance(p.type, click.Path):
                    yield name, p.name


def test_every_path_option_is_known():
    assert set(_path_options()) == READS | FOLDERS | WRITES


@pytest.fixture
def files(tmp_path):
    env = Path(write_exr(tmp_path / "in.exr", np.full((16, 32, 3), 0.5, np.float32)))
    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump({
        "camera": {"resolution": [16, 16]}, "environment": {"path": env.name},
        "materials": {"m": {"base_color": [0.5, 0.5, 0.5], "roughness": 0.5}},
        "objects": [{"sphere": {"radius": 1}, "material": "m"}],
        "effects": {"diffuse": "sh", "specular": "prefiltered"}}))
    return {"env": env, "scene": scene, "dir": tmp_path}


def _digest(*paths):
    return [hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in paths]


def _link(target: Path, link: Path) -> Path:
    link.parent.mkdir(parents=True, exist_ok=True)
    os.symlink(target, link)
    return link


# (command, option, build(files) -> argv with the option naming a link to what `read` names)
CASES = [
    ("sh", "output", "env", lambda f, p: ["sh", f["env"], "-o", p], ".json"),
    ("sh", "depfile", "env", lambda f, p: ["sh", f["env"], "--depfile", p], ".d"),
    ("basis", "output", "env", lambda f, p: ["basis", f["env"], "--basis", "zh3", "-o", p], ".json"),
    ("basis", "depfile", "env", lambda f, p: ["basis", f["env"], "--basis", "zh3", "--depfile", p], ".d"),
    ("basis", "specular_table", "env", lambda f, p: ["basis", f["env"], "--basis", "ambient_dice",
                                                      "--specular-table", p], ".exr"),
    ("mips", "ktx2_path", "env", lambda f, p: ["mips", f["env"], "--ktx2", p], ".ktx2"),
    ("mips", "ktx2_irradiance", "env", lambda f, p: ["mips", f["env"], "--ktx2-irradiance", p], ".ktx2"),
    ("mips", "ktx2_sheen", "env", lambda f, p: ["mips", f["env"], "--ktx2-sheen", p], ".ktx2"),
    ("mips", "depfile", "env", lambda f, p: ["mips", f["env"], "--depfile", p], ".d"),
    ("export-gltf", "output", "env", lambda f, p: ["export-gltf", f["env"], "-o", p], ".glb"),
    ("export-gltf", "depfile", "env", lambda f, p: ["export-gltf", f["env"], "-o", f["dir"] / "l.glb",
                                                     "--depfile", p], ".d"),
    ("render", "outputs", "env", lambda f, p: ["render", f["scene"], "-o", p], ".exr"),
    ("render", "outputs", "scene", lambda f, p: ["render", f["scene"], "-o", p], ".png"),
    ("render", "depfile", "scene", lambda f, p: ["render", f["scene"], "-o", f["dir"] / "x.png", "--depfile", p], ".d"),
    ("sheet", "outputs", "env", lambda f, p: ["sheet", f["scene"], "-o", p], ".exr"),
    ("sheet", "layout_path", "scene", lambda f, p: ["sheet", f["scene"], "-o", f["dir"] / "s.png", "--layout", p], ".json"),
    ("sheet", "depfile", "env", lambda f, p: ["sheet", f["scene"], "-o", f["dir"] / "s.png", "--depfile", p], ".d"),
    ("sheet", "frames_dir", "env", lambda f, p: ["sheet", f["scene"], "-o", f["dir"] / "s.png", "--frames", p.parent,
                                                 "--frames-exr"], "frames/r00_c00.exr"),
    ("sheet", "html_dir", "scene", lambda f, p: ["sheet", f["scene"], "-o", f["dir"] / "s.png", "--html", p.parent],
     "page/index.html"),
    ("accuracy", "out_dir", "scene", lambda f, p: ["accuracy", f["scene"], "-o", p.parent], "acc/table.md"),
    ("accuracy", "out_dir", "env", lambda f, p: ["accuracy", f["scene"], "-o", p.parent.parent], "acc/report/0001.js"),
    ("probes", "out_dir", "env", lambda f, p: ["probes", f["scene"], "-o", p.parent], "vol/distance.exr"),
    ("lightmap", "out_dir", "env", lambda f, p: ["lightmap", f["scene"], "--set", "lightmap.texels_per_unit=4", "-o",
                                                  p.parent], "lm/lightmap_irradiance.exr"),
]


def test_the_walk_covers_every_writing_option():
    assert {(c, o) for c, o, *_ in CASES} == WRITES


@pytest.mark.slow
@pytest.mark.parametrize("command, option, read, argv, name", CASES, ids=[f"{c[0]}-{c[1]}-{c[2]}" for c in CASES])
def test_no_output_is_an_input(files, stress, command, option, read, argv, name):
    """Each writing option given (through a symlink) a file the command reads: one line naming the
    option and what the file is, exit 1, the file unchanged, nothing else written."""
    target = files[read]
    link = _link(target, files["dir"] / (name if "/" in name else f"link{name}"))
    before = _digest(files["env"], files["scene"])
    listing = sorted(p.name for p in files["dir"].rglob("*"))
    p = run_cli(*argv(files, link))
    assert p.returncode == 1, (p.returncode, p.stderr)
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    assert "which this command reads" in lines[0] and str(link.name) in lines[0], lines[0]
    assert ("scene file" if read == "scene" else "panorama") in lines[0], lines[0]
    changed = sum(a != b for a, b in zip(_digest(files["env"], files["scene"]), before))
    stress.check(f"overwrite walk: {command} {option} onto {read} (a link)", changed, 0, "inputs changed")
    assert sorted(p.name for p in files["dir"].rglob("*")) == listing


def test_a_hard_link_to_the_input_is_the_input(files):
    hard = files["dir"] / "hard.json"
    os.link(files["env"], hard)
    p = run_cli("sh", files["env"], "-o", hard, "--force")
    assert p.returncode == 1 and "is the input panorama" in p.stderr, p.stderr


@pytest.mark.parametrize("argv, words", [
    (["sh", "{env}", "-o", "{dir}/a.json", "--depfile", "{dir}/a.json"], "--depfile"),
    (["mips", "{env}", "--ktx2", "{dir}/a.ktx2", "--ktx2-irradiance", "{dir}/a.ktx2"], "--ktx2-irradiance"),
    (["render", "{scene}", "-o", "{dir}/a.png", "-o", "{dir}/a.png"], "-o"),
    (["sheet", "{scene}", "-o", "{dir}/a.png", "--layout", "{dir}/a.png"], "--layout"),
    (["export-gltf", "{env}", "-o", "{dir}/l.gltf", "--depfile", "{dir}/l_specular_0_px.png"], "--depfile"),
])
def test_two_outputs_never_share_a_path(files, argv, words):
    p = run_cli(*[a.format(**files) for a in argv])
    assert p.returncode == 1, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"Error: {words} ") and "own path" in lines[0], p.stderr
    assert not any(files["dir"].glob("a.*")) and not any(files["dir"].glob("l*"))


# --- sizes --------------------------------------------------------------------------------------

@pytest.mark.parametrize("argv, layout", [
    (["mips", "{env}", "--size", "100000"], "equirect"),
    (["mips", "{env}", "--size", "30000", "--layout", "cubemap", "--only", "prefiltered"], "cubemap"),
    (["export-gltf", "{env}", "-o", "{dir}/l.glb", "--size", "131072"], "cubemap"),
])
def test_bake_sizes_over_memory_are_refused_before_any_work(files, stress, argv, layout):
    """The old code baked the radiance entry, then died with MemoryError (37.3 GiB) and left a
    .lock in the cache (mips), or ran 8 s into INVALID_BUFFER_SIZE (export-gltf)."""
    cache = files["dir"] / "cache"
    p = run_cli(*[a.format(**files) for a in argv], "--cache", cache)
    assert p.returncode == 1, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "--size" in lines[0] and f"the {layout} chain needs" in lines[0], p.stderr
    fits = int(lines[0].rsplit(" ", 1)[1])
    assert 256 <= fits < int(argv[argv.index("--size") + 1])
    left = len(list(cache.iterdir())) if cache.exists() else 0
    stress.check(f"size limit: {argv[0]} --size {argv[argv.index('--size') + 1]} {layout} (fits {fits})", left, 0,
                 "cache entries made")
    if argv[0] == "export-gltf":
        assert fits & (fits - 1) == 0          # the largest power of two, as --size must be


def test_the_largest_size_that_fits_is_the_boundary(monkeypatch):
    """check_chain_fits bisects to the exact boundary of its own memory model."""
    from iblbake.bake import mips
    from iblbake.io import memory
    host = 3 << 30
    monkeypatch.setattr(memory, "host_bytes_available", lambda: host)
    sizes_of = lambda s: mips.PrefilterOptions("equirect", s).resolved(0)["sizes"]   # noqa: E731
    with pytest.raises(Exception) as e:
        mips.check_chain_fits("equirect", 50000, sizes_of, None, "--size")
    fits = int(str(e.value).rsplit(" ", 1)[1])
    assert mips.chain_bytes("equirect", sizes_of(fits))[0] <= host < mips.chain_bytes("equirect", sizes_of(fits + 1))[0]
    mips.check_chain_fits("equirect", fits, sizes_of, None, "--size")      # fits: no error


# --- command-line values ------------------------------------------------------------------------

@pytest.mark.parametrize("spec", ["0:1:", "0:1", "0:1:abc", "0:1:3:cubic", "0:1:3:linear:x", "a:b:3", "0:1:2.5",
                                  "0:1:3,0.5"])
def test_malformed_ranges_name_the_syntax(spec):
    with pytest.raises(Exception) as e:
        sweep.parse_cli_axis(f"materials.m.roughness={spec}", "--rows")
    assert e.value.exit_code == 2 and "START:STOP:COUNT[:linear|geometric]" in str(e.value)


def test_range_spacings():
    for tail, geometric in (("", False), (":linear", False), (":geometric", True), (":log", True)):
        assert sweep.parse_cli_axis(f"effects.samples=1:256:9{tail}")["range"] == {
            "start": 1, "stop": 256, "count": 9, "geometric": geometric}
    assert sweep.parse_cli_axis("environment.path='a:b.exr',c.exr")["values"] == ["a:b.exr", "c.exr"]


def test_a_malformed_range_fails_before_rendering(files):
    p = run_cli("sheet", files["scene"], "-o", files["dir"] / "s.png", "--rows", "materials.m.roughness=0:1:")
    assert p.returncode == 2 and "START:STOP:COUNT" in p.stderr and "Traceback" not in p.stderr, p.stderr
    assert not (files["dir"] / "s.png").exists()


@pytest.mark.parametrize("setting, words", [
    ("camera.resolution=", "no value after '='"), ("camera.resolution", "expected KEY.PATH=VALUE"),
    ("camera.resolution=[1,", "not valid YAML")])
def test_malformed_set_is_a_usage_error(files, setting, words):
    p = run_cli("render", files["scene"], "-o", files["dir"] / "x.png", "--set", setting)
    assert p.returncode == 2 and words in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert not (files["dir"] / "x.png").exists()


def test_a_folder_as_the_panorama_is_named_a_folder(files):
    (files["dir"] / "pano").mkdir()
    p = run_cli("render", files["scene"], "-o", files["dir"] / "x.png", "--set", "environment.path=pano")
    assert p.returncode == 1 and "environment.path" in p.stderr and "is a folder" in p.stderr, p.stderr


@pytest.mark.parametrize("argv, words", [
    (["sh", "{env}", "-o", "{dir}/x.xyz"], "--format iblbake is written as .json"),
    (["sh", "{env}", "--format", "filament", "-o", "{dir}/x.json"], "written as .txt"),
    (["mips", "{env}", "--ktx2", "{dir}/x.png"], "a KTX2 cube map is written as .ktx2"),
])
def test_an_output_extension_that_says_nothing_is_refused(files, argv, words):
    p = run_cli(*[a.format(**files) for a in argv])
    assert p.returncode == 2 and words in p.stderr, p.stderr
    assert not list(files["dir"].glob("x.*"))


def test_sh_validates_every_input_before_writing(files):
    out = files["dir"] / "out"
    p = run_cli("sh", files["env"], files["dir"] / "missing.exr", "-o", f"{out}/", "--backend", "numpy")
    assert p.returncode == 1 and "missing.exr: no such file" in p.stderr, p.stderr
    assert not out.exists()
    bad = files["dir"] / "bad.exr"
    bad.write_bytes(b"not an image")
    p = run_cli("sh", files["env"], bad, "-o", f"{out}/", "--backend", "numpy")
    assert p.returncode == 1 and "bad.exr" in p.stderr and not out.exists(), p.stderr


@pytest.mark.slow
def test_missing_output_folders_are_made_by_every_command(files):
    """One rule: a missing folder is created when the output is written (never before the work,
    so a failed command leaves none)."""
    d = files["dir"]
    for argv, made in (
            (["sh", files["env"], "-o", d / "a" / "sh.json", "--backend", "numpy", "--no-error"], d / "a" / "sh.json"),
            (["render", files["scene"], "-o", d / "b" / "f.png"], d / "b" / "f.png"),
            (["sheet", files["scene"], "-o", d / "c" / "s.png", "--layout", d / "c2" / "l.json"], d / "c2" / "l.json"),
            (["export-gltf", files["env"], "-o", d / "e" / "l.glb", "--size", "16", "--min-size", "8"], d / "e" / "l.glb"),
            (["mips", files["env"], "--ktx2", d / "f" / "p.ktx2", "--size", "16"], d / "f" / "p.ktx2")):
        p = run_cli(*argv, "-q")
        assert p.returncode == 0 and made.is_file(), (argv[0], p.stderr)
    # a folder under a file cannot be made: one line, before any work
    p = run_cli("sh", files["env"], "-o", files["env"] / "x.json")
    assert p.returncode == 1 and "is not a folder" in p.stderr and len(p.stderr.strip().splitlines()) == 1


def test_a_failed_accuracy_leaves_no_folder(files):
    bad = files["dir"] / "ladder.yaml"
    bad.write_text(yaml.safe_dump({"rungs": [{"key": "effects.sampels", "values": [1]}]}))
    p = run_cli("accuracy", files["scene"], "--ladder", bad, "-o", files["dir"] / "study")
    assert p.returncode == 1 and "effects.sampels" in p.stderr
    assert not (files["dir"] / "study").exists()


def test_accuracy_is_in_the_usage_list():
    p = run_cli("--help")
    listed = {line.split()[1] for line in p.stdout.splitlines() if line.strip().startswith("iblbake ")}
    assert listed == set(COMMANDS)


def test_two_panoramas_onto_one_name_are_refused(files):
    other = files["dir"] / "b"
    other.mkdir()
    second = Path(write_exr(other / "in.exr", np.full((16, 32, 3), 0.25, np.float32)))
    p = run_cli("sh", files["env"], second, "-o", f"{files['dir']}/out/", "--backend", "numpy")
    assert p.returncode == 1 and "is also -o" in p.stderr and not (files["dir"] / "out").exists(), p.stderr


def test_progress_time_left_skips_the_cold_first_stage_and_warnings_clear_the_bar(monkeypatch):
    """The first stage pays kernel builds (click's own ETA read 2 min 49 s left of a 6 s render);
    a warning printed under a bar starts on a cleared line (it printed mid-line)."""
    import io
    import sys
    import time

    from iblbake.cli.options import Console

    class Terminal(io.StringIO):
        def isatty(self):
            return True
    err = Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    monkeypatch.delenv("CI", raising=False)
    clock = [0.0]
    monkeypatch.setattr(time, "perf_counter", lambda: clock[0])
    con = Console(False, False)
    with con.stages([f"stage {k}" for k in range(10)], label="render") as step:
        clock[0] = 100.0
        step()                       # a cold first stage of 100 s
        clock[0] = 101.0
        step()                       # then 1 s a stage: 8 left
        con.warn("careful")
        clock[0] = 102.0
        step()
    text = err.getvalue()
    assert "8 s left" in text and "7 s left" in text and "min" not in text
    assert "\r\x1b[2Kiblbake: warning: careful\n" in text


# --- one overwrite rule (issue 43): a file iblbake did not write is replaced only with --force ----

FOREIGN = {".png": None, ".exr": None, ".json": b'{"mine": true}\n', ".ktx2": b"\xabKTX 20\xbb\r\n\x1a\nnot ours",
           ".d": b"all:\n\techo mine\n", ".md": b"# my notes\n", ".csv": b"a,b\n1,2\n", ".glsl": b"// my shader\n",
           ".gltf": b'{"asset": {"version": "2.0", "generator": "Blender"}}',
           ".html": b"<!DOCTYPE html><html><body>my page</body></html>\n", ".js": b"// my script\n",
           ".bin": b"\x00\x01my buffer"}


def _foreign(path: Path) -> bytes:
    """A file of `path`'s kind that some other tool wrote (Pillow's PNG, an EXR without iblbake's mark)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    suffix = path.suffix.lower()
    if suffix == ".png":
        from PIL import Image
        Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(path)
    elif suffix == ".exr":
        import OpenImageIO as oiio
        out = oiio.ImageOutput.create(str(path))
        out.open(str(path), oiio.ImageSpec(4, 4, 3, oiio.FLOAT))
        out.write_image(np.zeros((4, 4, 3), np.float32))
        out.close()
    else:
        path.write_bytes(FOREIGN[suffix])
    return path.read_bytes()


def test_the_mark_tells_iblbakes_files_from_others(tmp_path):
    """guard.written_by_iblbake: each writer's mark is read back; another tool's file of every kind is not."""
    from iblbake.io import atomic, depfile, guard, ktx2
    from iblbake.study import report
    d = tmp_path
    images.write_png(d / "a.png", np.zeros((4, 4, 3), np.uint8))
    images.write_exr(d / "a.exr", np.zeros((4, 4, 3), np.float32))
    atomic.write_bytes(d / "a.ktx2", ktx2.cube_bytes([np.zeros((6, 4, 4, 3), np.float32)], "rgba16f", {},
                                                     writer=guard.mark()))
    atomic.write_json(d / "a.json", {"generator": guard.mark(), "cells": []})
    depfile.write(d / "a.d", [(["x.png"], ["scene.yaml"])])
    atomic.write_text(d / "a.md", report.markdown([], {}))
    atomic.write_text(d / "a.csv", report.csv_text([], {}))
    report.plot([{"term": "diffuse", "label": "SH 3", "time_s": 1e-3, "relative_rmse": 0.1, "configured": True}],
                {"diffuse": ["SH 3"]}, d / "plot.png", "t")
    # a glTF's buffer carries no mark: it is iblbake's where the .gltf beside it is and names it
    atomic.write_json(d / "m.gltf", {"asset": {"version": "2.0", "generator": guard.mark()}, "buffers": [{"uri": "m.bin"}]})
    atomic.write_bytes(d / "m.bin", b"\0" * 8)
    for name in ("a.png", "a.exr", "a.ktx2", "a.json", "a.d", "plot.png", "m.bin"):
        assert guard.written_by_iblbake(d / name), name
    for name in ("a.md", "a.csv"):
        assert guard.written_by_iblbake(d / name, report.header_lines()) and not guard.written_by_iblbake(d / name)
    for suffix in FOREIGN:
        f = d / "other" / f"x{suffix}"
        _foreign(f)
        assert not guard.written_by_iblbake(f, report.header_lines()), suffix


# (command, option, argv(files, path), output name): every writing option onto another tool's file
OVERWRITES = [
    ("sh", "output", lambda f, p: ["sh", f["env"], "-o", p], "x.json"),
    ("sh", "depfile", lambda f, p: ["sh", f["env"], "--depfile", p], "x.d"),
    ("basis", "output", lambda f, p: ["basis", f["env"], "--basis", "zh3", "-o", p], "x.json"),
    ("basis", "depfile", lambda f, p: ["basis", f["env"], "--basis", "zh3", "--depfile", p], "x.d"),
    ("basis", "specular_table", lambda f, p: ["basis", f["env"], "--basis", "ambient_dice", "--specular-table", p],
     "x.exr"),
    ("mips", "ktx2_path", lambda f, p: ["mips", f["env"], "--ktx2", p], "x.ktx2"),
    ("mips", "ktx2_irradiance", lambda f, p: ["mips", f["env"], "--ktx2-irradiance", p], "x.ktx2"),
    ("mips", "ktx2_sheen", lambda f, p: ["mips", f["env"], "--ktx2-sheen", p], "x.ktx2"),
    ("mips", "depfile", lambda f, p: ["mips", f["env"], "--depfile", p], "x.d"),
    ("export-gltf", "output", lambda f, p: ["export-gltf", f["env"], "-o", p], "x.gltf"),
    ("export-gltf", "depfile", lambda f, p: ["export-gltf", f["env"], "-o", f["dir"] / "l.glb", "--depfile", p], "x.d"),
    ("render", "outputs", lambda f, p: ["render", f["scene"], "-o", p], "x.png"),
    ("render", "outputs", lambda f, p: ["render", f["scene"], "-o", p], "x.exr"),
    ("render", "depfile", lambda f, p: ["render", f["scene"], "-o", f["dir"] / "y.png", "--depfile", p], "x.d"),
    ("sheet", "outputs", lambda f, p: ["sheet", f["scene"], "-o", p], "x.png"),
    ("sheet", "layout_path", lambda f, p: ["sheet", f["scene"], "-o", f["dir"] / "s.png", "--layout", p], "x.json"),
    ("sheet", "depfile", lambda f, p: ["sheet", f["scene"], "-o", f["dir"] / "s.png", "--depfile", p], "x.d"),
    ("sheet", "frames_dir", lambda f, p: ["sheet", f["scene"], "-o", f["dir"] / "s.png", "--frames", p.parent],
     "frames/r00_c00.png"),
    ("sheet", "html_dir", lambda f, p: ["sheet", f["scene"], "-o", f["dir"] / "s.png", "--html", p.parent],
     "page/index.html"),
    ("accuracy", "out_dir", lambda f, p: ["accuracy", f["scene"], "-o", p.parent], "study/table.md"),
    ("accuracy", "out_dir", lambda f, p: ["accuracy", f["scene"], "-o", p.parent], "study/index.html"),
    ("probes", "out_dir", lambda f, p: ["probes", f["scene"], "-o", p.parent], "vol/probes.glsl"),
    ("probes", "out_dir", lambda f, p: ["probes", f["scene"], "-o", p.parent], "vol/probes.json"),
    ("lightmap", "out_dir", lambda f, p: ["lightmap", f["scene"], "--set", "lightmap.texels_per_unit=4", "-o", p.parent],
     "lm/lightmap.bin"),
]


def test_the_overwrite_walk_covers_every_writing_option():
    assert {(c, o) for c, o, *_ in OVERWRITES} == WRITES


@pytest.mark.slow
@pytest.mark.parametrize("command, option, argv, name", OVERWRITES,
                         ids=[f"{c[0]}-{c[1]}-{c[3]}" for c in OVERWRITES])
def test_a_file_iblbake_did_not_write_needs_force(files, stress, command, option, argv, name):
    """probes -o DIR replaced a user's probes.json and probes.glsl, accuracy -o DIR a user's
    table.md, render -o any PNG, all silently; sh and export-gltf asked for --force. One rule now:
    refused in one line before any work, the file unchanged."""
    target = files["dir"] / name
    before = _foreign(target)
    p = run_cli(*argv(files, target))
    assert p.returncode == 1, (p.returncode, p.stderr)
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "--force" in lines[0] and target.name in lines[0], p.stderr
    stress.check(f"overwrite rule: {command} {option} onto another tool's {target.suffix}",
                 int(target.read_bytes() != before), 0, "files changed")


@pytest.mark.slow
def test_force_replaces_and_own_files_are_replaced_without_it(files):
    """render: its own earlier frame is replaced without --force; another tool's only with it."""
    frame = files["dir"] / "f.png"
    _foreign(frame)
    assert run_cli("render", files["scene"], "-o", frame).returncode == 1
    p = run_cli("render", files["scene"], "-o", frame, "--force")
    assert p.returncode == 0, p.stderr
    from iblbake.io import guard
    assert guard.written_by_iblbake(frame)
    frame.write_bytes(frame.read_bytes())          # touched, still iblbake's
    p = run_cli("render", files["scene"], "-o", frame)
    assert p.returncode == 0, p.stderr
    vol = files["dir"] / "vol"
    _foreign(vol / "probes.json")
    assert run_cli("probes", files["scene"], "-o", vol, "--force", "-q").returncode == 0
    assert json.loads((vol / "probes.json").read_text())["format"] == "iblbake-probes"
    assert run_cli("probes", files["scene"], "-o", vol, "-q").returncode == 0      # now its own


# --- failures leave nothing (issue 43) -------------------------------------------------------------

def test_a_probe_grid_error_leaves_no_output_folder(files):
    """probes made its -o folder before baking: a grid error (max below min) left it empty."""
    out = files["dir"] / "fresh" / "vol"
    p = run_cli("probes", files["scene"], "-o", out, "--set", "probes.min=[1,1,1]", "--set", "probes.max=[0,0,0]")
    assert p.returncode == 1 and "probes.max" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert not (files["dir"] / "fresh").exists()


def test_mips_bakes_every_panorama_before_writing_any_output(files):
    """mips a.exr bad.exr --ktx2 DIR/ wrote a.ktx2, then failed on bad.exr (sh validates all first)."""
    bad = files["dir"] / "bad.exr"
    bad.write_bytes(b"not an image")
    out = files["dir"] / "ktx"
    p = run_cli("mips", files["env"], bad, "--ktx2", f"{out}/", "--size", "8", "--min-size", "4",
                "--depfile", files["dir"] / "m.d", "--cache", files["dir"] / "cache")
    assert p.returncode == 1 and "bad.exr" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert not out.exists() and not (files["dir"] / "m.d").exists()


@pytest.mark.parametrize("argv", [
    ["render", "{scene}", "-o", "{dir}/f.png"], ["sheet", "{scene}", "-o", "{dir}/f.png"],
    ["mips", "{env}", "--ktx2", "{dir}/f.ktx2"], ["export-gltf", "{env}", "-o", "{dir}/f.glb"]],
    ids=lambda a: a[0])
def test_a_depfile_into_a_read_only_folder_fails_before_any_work(files, argv):
    """render found it only after the frame was written (exit 1 with the frame on disk)."""
    from tests.helpers import read_only_folder
    with read_only_folder(files["dir"] / "ro") as ro:
        p = run_cli(*[a.format(**files) for a in argv], "--depfile", ro / "f.d", "--cache", files["dir"] / "c")
        assert p.returncode == 1 and "f.d" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
        assert "not writable" in p.stderr, p.stderr
    assert not list(files["dir"].glob("f.*")) and not (files["dir"] / "c").exists()
