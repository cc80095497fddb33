"""Nothing lost on a full disk (issue 43): every writer of every command, run once onto a small
tmpfs and then again with the tmpfs filled to the last byte, fails in one line naming the file,
keeps every earlier output byte for byte, and leaves no temp file and no folder of its own.

OpenImageIO's PNG writer reported no error on a full disk: `render -o keep.png` exited 0 saying
`wrote keep.png`, and keep.png was an empty file (the earlier frame gone); `sheet -o x.png`
likewise. PNGs are now encoded in memory and written by atomic.write_bytes, which checks every
write and fsyncs before the rename.
"""

import contextlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from iblbake.errors import IblbakeError
from iblbake.io import images

from tests.helpers import mounted_tmpfs, scene_file, write_exr


@contextlib.contextmanager
def filled(disk: Path):
    """The tmpfs with not a byte left (a filler file written until ENOSPC), emptied afterwards."""
    filler = disk / ".filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT, 0o600)
    for block in (64 << 10, 512, 1):
        with contextlib.suppress(OSError):
            while True:
                os.write(fd, b"\0" * block)
    os.close(fd)
    try:
        yield
    finally:
        filler.unlink()


def _tree(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != ".filler"}


def test_a_png_onto_a_full_disk_keeps_the_old_file(tmp_path, stress):
    """The library's writer: an IblbakeError naming the file, the earlier frame byte for byte."""
    img = (np.random.default_rng(0).random((96, 128, 3)) * 255).astype(np.uint8)
    with mounted_tmpfs(tmp_path / "disk", "size=1m") as disk:
        images.write_png(disk / "keep.png", img)
        before = (disk / "keep.png").read_bytes()
        with filled(disk):
            with pytest.raises(IblbakeError) as e:
                images.write_png(disk / "keep.png", img[::-1])
            assert "keep.png" in str(e.value) and "No space left" in str(e.value)
            assert (disk / "keep.png").read_bytes() == before
            left = sorted(p.name for p in disk.iterdir() if p.name != ".filler")
        assert left == ["keep.png"], left
    stress.check("full disk: a PNG over an earlier one (library)", 0, 0, "bytes of the old file changed")


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("fullin")
    env = Path(write_exr(d / "sky.exr", (0.5 + np.random.default_rng(1).random((16, 32, 3))).astype(np.float32)))
    scene = scene_file(d, env, camera={"perspective": {"position": [0, 0, 4]}, "resolution": [32, 24]},
                       materials={"base_color": [0.8, 0.6, 0.4], "metallic": 0.5, "roughness": 0.5},
                       objects=[{"sphere": {"radius": 1}, "material": "m"},
                                {"plane": {"point": [0, -1, 0], "normal": [0, 1, 0], "size": 6}, "material": "m"}],
                       effects={"diffuse": "sh", "specular": "prefiltered"},
                       probes={"counts": 3, "rays": 64})
    ladder = d / "ladder.yaml"
    ladder.write_text(yaml.safe_dump({"rungs": [{"key": "effects.sh_bands", "values": [2]}]}))
    return {"env": env, "scene": scene, "ladder": ladder, "cache": d / "cache"}


# (case, argv with {out} the folder on the tmpfs, the outputs it writes under {out})
WRITERS = [
    ("sh -o json + depfile", ["sh", "{env}", "-o", "{out}/sh.json", "--depfile", "{out}/sh.d", "--backend", "numpy"]),
    ("sh --format glsl", ["sh", "{env}", "--format", "glsl", "-o", "{out}/sh.glsl", "--backend", "numpy"]),
    ("basis -o json + table + depfile", ["basis", "{env}", "--basis", "ambient_dice", "-o", "{out}/b.json",
                                         "--specular-table", "{out}/t.exr", "--depfile", "{out}/b.d"]),
    ("mips --ktx2 --ktx2-irradiance --ktx2-sheen + depfile",
     ["mips", "{env}", "--size", "8", "--min-size", "4", "--ktx2", "{out}/p.ktx2", "--ktx2-irradiance", "{out}/i.ktx2",
      "--irradiance-size", "4", "--ktx2-sheen", "{out}/s.ktx2", "--depfile", "{out}/m.d", "--cache", "{cache}"]),
    ("mips cache entries", ["mips", "{env}", "--size", "8", "--min-size", "4", "--cache", "{out}/cache"]),
    ("export-gltf .gltf (PNG faces)", ["export-gltf", "{env}", "-o", "{out}/l.gltf", "--size", "8", "--min-size", "4",
                                       "--depfile", "{out}/l.d", "--cache", "{cache}"]),
    ("export-gltf .glb", ["export-gltf", "{env}", "-o", "{out}/l.glb", "--size", "8", "--min-size", "4",
                          "--cache", "{cache}"]),
    ("render -o png exr + AOVs + depfile", ["render", "{scene}", "-o", "{out}/keep.png", "-o", "{out}/keep.exr",
                                             "--set", "output.normal={out}/n.exr", "--depfile", "{out}/f.d",
                                             "--allow-outside", "--cache", "{cache}"]),    # the AOV: another disk
    ("sheet -o png exr, --frames, --layout, depfile, --html",
     ["sheet", "{scene}", "-o", "{out}/x.png", "-o", "{out}/x.exr", "--frames", "{out}/frames", "--frames-exr",
      "--html", "{out}/page",
      "--layout", "{out}/x.json", "--depfile", "{out}/x.d", "--columns", "materials.m.roughness=0.2,0.8",
      "--cache", "{cache}"]),
    ("probes -o DIR", ["probes", "{scene}", "-o", "{out}/probes", "--cache", "{cache}"]),
    ("accuracy -o DIR", ["accuracy", "{scene}", "-o", "{out}/study", "--ladder", "{ladder}", "--max-side", "16",
                         "--repeats", "1", "--max-samples", "16", "--no-flip", "--set", "effects.specular=off",
                         "--cache", "{cache}"]),
]


def _run(argv, inputs, out):
    args = [a.format(out=out, **inputs) for a in argv]
    return subprocess.run([sys.executable, "-m", "iblbake.cli", *args, "-q"], capture_output=True, text=True,
                          timeout=600)


@pytest.mark.slow
@pytest.mark.parametrize("case, argv", WRITERS, ids=[w[0] for w in WRITERS])
def test_every_writer_keeps_the_old_files_on_a_full_disk(tmp_path, stress, inputs, case, argv):
    with mounted_tmpfs(tmp_path / "disk", "size=16m") as disk:
        out = disk / "o"
        out.mkdir()
        p = _run(argv, inputs, out)
        assert p.returncode == 0, p.stderr[-800:]
        before = _tree(out)
        assert before, case
        with filled(disk):             # (a cache hit writes nothing: the cache bakes another size)
            p = _run(argv + (["--size", "4"] if "cache entries" in case else []), inputs, out)
            after = _tree(out)
            temps = [n for n in after if Path(n).name.startswith(".") and ".tmp-" in n]
        assert p.returncode == 1, (case, p.returncode, p.stderr[-800:])
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in p.stderr, p.stderr[-800:]
        assert "No space left" in lines[0] and str(out) in lines[0], lines[0]
        changed = sorted(n for n in before if after.get(n) != before[n])
        stress.check(f"full disk: {case}: earlier outputs changed or lost", len(changed), 0, "files")
        stress.check(f"full disk: {case}: temp files left", len(temps), 0, "files")
        assert after.keys() - before.keys() <= {n for n in after if n.endswith(".lock")}, after.keys() - before.keys()
        if "cache entries" in case:     # the cache folder is made before any bake, by design
            return
        # onto an empty folder on the full disk: no folder of its own is left behind
        with filled(disk):
            p = _run(argv, inputs, disk / "fresh" / "o")
            assert p.returncode == 1, (case, p.stderr[-800:])
            made = sorted(str(x.relative_to(disk)) for x in disk.rglob("*") if "fresh" in str(x)
                          and not x.name.endswith(".lock"))
        stress.check(f"full disk: {case}: folders left in a fresh output folder", len(made), 0, "paths")
    stress.count("partial files found", len(changed) + len(temps))
