"""The stored reference sheet of tests/test_compare.py: a 2 x 2 sweep of one scene under city
(box-filtered to 256x128 from Blender's CC0 city.exr, `make assets`), 64 x 48 cells.
Regenerate it (after a deliberate change to what the renderer draws) with

    .venv/bin/python tests/make_reference.py

which rewrites tests/reference/sheet_small.png and sheet_small.json."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml

HERE = Path(__file__).resolve().parent
REFERENCE = HERE / "reference"
ARGS = ["--rows", "materials.gold.roughness=0.1,0.6", "--columns", "materials.gold.metallic=0,1",
        "--cell-size", "64x48", "--title", "reference sheet"]


def small_city(folder: Path) -> Path:
    """city.exr box-filtered 4x4 in solid angle (the same as the tests' small_panoramas)."""
    sys.path.insert(0, str(HERE.parent))
    from iblbake.core import conventions
    from iblbake.io import images
    img = images.read_panorama(HERE.parent / "examples" / "panoramas" / "city.exr")[0]
    h, w = img.shape[:2]
    om = conventions.equirect_row_solid_angles(w, h)[:, None, None]
    wimg = (img * om).reshape(h // 4, 4, w // 4, 4, 3).sum((1, 3))
    wsum = om.reshape(h // 4, 4).sum(1)[:, None, None] * 4
    out = folder / "city_small.exr"
    images.write_exr(out, (wimg / wsum).astype(np.float32))
    return out


def scene(folder: Path) -> Path:
    env = small_city(folder)
    doc = {"camera": {"perspective": {"position": [0, 0.4, 4], "fov_y": 40}, "resolution": [64, 48]},
           "environment": {"path": env.name, "background": "show"},
           "materials": {"gold": {"base_color": [1.0, 0.78, 0.34], "metallic": 1, "roughness": 0.3},
                         "paint": {"base_color": [0.8, 0.1, 0.1], "roughness": 0.5}},
           "objects": [{"sphere": {"center": [-0.6, 0, 0], "radius": 0.5}, "material": "gold"},
                       {"sphere": {"center": [0.6, 0, 0], "radius": 0.5}, "material": "paint"}],
           "effects": {"specular": "prefiltered"}}
    p = folder / "reference.yaml"
    p.write_text(yaml.safe_dump(doc))
    return p


def render_sheet(folder: Path, extra=()) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name("iblbake")
    return subprocess.run([str(exe), "sheet", str(scene(folder)), "-o", str(folder / "sheet.png"),
                           "--layout", str(folder / "sheet.json"), "--cache", str(folder / "cache"), "-q",
                           *ARGS, *extra], capture_output=True, text=True)


if __name__ == "__main__":
    import shutil
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        r = render_sheet(Path(d))
        if r.returncode:
            sys.exit(r.stderr)
        REFERENCE.mkdir(exist_ok=True)
        shutil.copy(Path(d) / "sheet.png", REFERENCE / "sheet_small.png")
        shutil.copy(Path(d) / "sheet.json", REFERENCE / "sheet_small.json")
    print(f"wrote {REFERENCE}/sheet_small.png and sheet_small.json")
