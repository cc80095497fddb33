"""Render every example scene in every shading mode and the whole gallery of sheets through the
CLI, or compare two such runs.

    python scripts/example_frames.py render DIR     # DIR/<scene>-<variant>.png, DIR/sheets/*.png
    python scripts/example_frames.py compare A B    # pixel differences, one line per image

Used to check that a refactor leaves every frame pixel-identical: render before, render after,
compare. It drives only the command line, so it runs against any version of iblbake: for an older
source tree, `PYTHONPATH=TREE python scripts/example_frames.py render DIR`. The gallery is
examples/Makefile's, built into DIR/sheets with its own cache and every cell's frame beside each
sheet (SHEET.png.frames/); a sheet with time captions is timed once (--repeat 1), and its PNG
differs by its captions, so its cells are compared through the frames.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENES = ("quick", "sphere_grid", "mesh", "lights", "textured")
# (name, --set overrides); small frames keep the reference modes quick on a 2-core CPU
VARIANTS = {
    "default": [],
    "importance": ["effects.specular=importance", "effects.samples=32"],
    "importance_mip0": ["effects.specular=importance", "effects.samples=16", "effects.force_mip0=true"],
    "sh8_hann": ["effects.sh_bands=8", "effects.sh_window=hann", "effects.specular=off"],
    "reference": ["effects.diffuse=reference", "effects.specular=reference",
                  "effects.reference.max_samples=64", "camera.resolution=[160,90]"],
    "blur_bg": ["environment.background=show", "environment.blur=0.4"],
    "color_bg": ["environment.background=[0.2,0.3,0.4]", "effects.tonemap=hable"],
}


def render(out: Path):
    out.mkdir(parents=True, exist_ok=True)
    exe = Path(sys.executable).with_name("iblbake")
    for scene in SCENES:
        for name, sets in VARIANTS.items():
            path = out / f"{scene}-{name}.png"
            cmd = [str(exe), "render", str(ROOT / "examples" / "scenes" / f"{scene}.yaml"), "-o", str(path),
                   "-q", *[a for s in sets for a in ("--set", s)]]
            subprocess.run(cmd, check=True)
            print(path)
    sheets = out.resolve() / "sheets"
    sheet = f"{exe} sheet -q --repeat 1 --cache {sheets / 'cache'} --frames $@.frames"
    subprocess.run(["make", "-s", "-C", str(ROOT / "examples"), f"OUT={sheets}", f"SHEET={sheet}"], check=True)


def compare(a: Path, b: Path) -> int:
    import numpy as np
    import OpenImageIO as oiio

    bad = 0
    for pa in sorted(a.rglob("*.png")):
        pb = b / pa.relative_to(a)
        x = oiio.ImageBuf(str(pa)).get_pixels(oiio.UINT8).astype(int)
        y = oiio.ImageBuf(str(pb)).get_pixels(oiio.UINT8).astype(int)
        d = np.abs(x - y)
        differ = int((d.max(axis=-1) > 0).sum())
        bad += differ > 0
        print(f"{str(pa.relative_to(a)):<44} pixels differing {differ:7d} of {d.shape[0] * d.shape[1]:7d}, max {int(d.max())}")
    return 1 if bad else 0


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "render":
        render(Path(sys.argv[2]))
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(compare(Path(sys.argv[2]), Path(sys.argv[3])))
    else:
        sys.exit(__doc__)
