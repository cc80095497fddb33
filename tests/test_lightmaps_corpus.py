"""Lightmaps on the corpus (issue 62, docs/benchmarks.md "Lightmaps on the corpus' interiors"): each
interior's lightmap at DENSITY texels a unit and SAMPLES rays a texel (RAYS' where the light comes
through a small opening from small lamps), read at the camera's primary hits into the diffuse term
(the atlas holding the panorama whole, `environment.sun: none`: the lights `sun: auto` extracts are
the frame's, not the atlas'), against the converged reference's diffuse term, region by region (the
luminance ratio and the worst channel, as tests/test_corpus.py judges the probes), for both bases;
and the same on scenes the lightmaps were not tuned on: the open box wound either way, at scales
0.01 and 100 (the density scaled with the scene: the same texels), and with a glTF floor that brings
its own TEXCOORD_1. The settings are benchmarks/bench_lightmaps.py's `--max-side 40 --target-noise
0.01 --max-samples 4096` (at tests/test_corpus.py's 256 samples window_room's reference under city
is 20% noisy a pixel, and its clay sphere's mean a few percent off)."""

from pathlib import Path

import numpy as np
import pytest

from iblbake.render import lightmaps
from tests.helpers import MIN_PIXELS, corpus_cases, outside

ROOT = Path(__file__).resolve().parents[1]
DENSITY, SAMPLES = 8, 1024
CORPUS_BOUND = 0.10        # issue 62: every region of static geometry within 10% of the converged reference
# Rays a texel: 1024, but 4096 where studio's small lamps are seen through a small or far opening
# (a texel's uniform rays find them rarely: at 1024 the corridor's far end read x0.79-0.94 over three
# seeds, l_room's sphere x1.09, probe_box_walls' cube x0.90; docs/benchmarks.md) and in l_room (its
# ceiling, lit from the window's far leg, x0.92 under city at 1024, x0.97 at 4096).
RAYS = {("corridor", "studio"): 4096, ("l_room", "studio"): 4096, ("l_room", "city"): 4096,
        ("probe_box_walls", "studio"): 4096}
# Each interior's worst region (the larger of |ratio - 1| and the worst channel, the worse basis,
# regions of at least MIN_PIXELS pixels) measured at these settings; the bound is 1.2x it (never
# above CORPUS_BOUND).
# corridor under city re-measured at stop 75: 6.1% (its far end x0.94; 4.6% when first measured),
# over seeds 1-2 at 1024 and 4096 rays 3.8-9.2% (the far end x0.91-0.97, the sphere x1.00-1.07):
# the light it holds comes after bounces, and the seed, fixed here, decides which of them a texel finds
WORST = {
    ("corridor", "studio"): 0.021, ("corridor", "city"): 0.061,
    ("quad_room", "studio"): 0.015, ("quad_room", "city"): 0.017,
    ("l_room", "studio"): 0.042, ("l_room", "city"): 0.039,
    ("two_storey", "studio"): 0.027, ("two_storey", "city"): 0.035,
    ("probe_box_walls", "studio"): 0.040, ("probe_box_walls", "city"): 0.044,
    ("window_room", "studio"): 0.051, ("window_room", "city"): 0.064,
}
INTERIORS = ("corridor", "two_storey", "quad_room", "l_room", "probe_box_walls", "window_room")


def regions(name, panorama, panoramas, cache, sets=(), density=DENSITY, rays=SAMPLES):
    """({basis: the regions of at least MIN_PIXELS pixels (study region_absolute)} of the scene's
    lightmap against its reference, the bake's report)."""
    from iblbake.device.runtime import Runtime
    from iblbake.render.bakes import Bakes
    from iblbake.render.lightmaps import read
    from iblbake.render.units import Job
    from iblbake.study import accuracy as acc

    if not (ROOT / "examples" / "corpus" / "meshes" / "skylight_room.obj").exists():
        pytest.fail("the corpus meshes are missing: run `make meshes`")
    settings = acc.Settings(max_side=40, repeats=1, target_noise=0.01, max_samples=4096, flip=False)
    rt, bakes = Runtime(), Bakes(cache)
    st = acc.Study(ROOT / "examples" / "corpus" / f"{name}.yaml",
                   [f"environment.path={panoramas[panorama]}", f"lightmap.texels_per_unit={density}",
                    f"lightmap.samples={rays}", "environment.sun=none", *sets], settings, runtime=rt, bakes=bakes)
    ref = st.render_reference("diffuse")
    lm = lightmaps.bake(Job(st.scene, rt, bakes), st.scene.data["lightmap"])
    out = {}
    for basis in lightmaps.BASES:
        hdr = read.diffuse_frame(st.scene, bakes.geometry(st.scene), lm, ref["hdr"].shape[:2], basis)
        got = st.region_metrics(hdr, ref["hdr"], st.metric_mask("diffuse", hdr))["region_absolute"]
        out[basis] = {n: e for n, e in got.items() if e["pixels"] >= MIN_PIXELS}
        print(name, panorama, basis, {n: (round(e["ratio"], 3), round(e["absolute"], 3)) for n, e in got.items()})
    return out, lm["report"]


@pytest.mark.external
@pytest.mark.slow
@pytest.mark.parametrize("name, panorama", corpus_cases(INTERIORS, keep={("quad_room", "studio"), ("window_room", "city"),
                                                                         ("two_storey", "city")}))
def test_lightmap_holds_each_interior_to_the_truth(name, panorama, tmp_path, panoramas):
    """Every region of the interior within 1.2x WORST's measured figure under both bases, at RAYS'
    rays a texel (measured 1.5-6.4%)."""
    bound = min(1.2 * WORST[(name, panorama)], CORPUS_BOUND)
    rays = RAYS.get((name, panorama), SAMPLES)
    for basis, held in regions(name, panorama, panoramas, tmp_path / "cache", rays=rays)[0].items():
        assert len(held) >= 2, held
        bad = outside(held, bound)
        assert not bad, f"{name} under {panorama}, {basis}: regions over {bound:.1%}: {bad}"


def gltf_floor(folder):
    """The open box's floor (box_floor_out.obj: 2 x 2 at y = 0, facing up) as a GLB bringing a
    TEXCOORD_1 of its own (a square chart in a corner of the unit square, as an asset's lightmap UVs)."""
    from tests.helpers import quad_glb
    v = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], float)
    uv1 = np.array([[0.1, 0.1], [0.5, 0.1], [0.5, 0.5], [0.1, 0.5]])
    return quad_glb(folder / "floor.glb", vertices=v, faces=np.array([[0, 2, 1], [0, 3, 2]]), uv1=uv1)


UNTUNED = {   # scene, the density (8 a unit at the box's size), scene keys on top, the worst region measured
    "box_in": ("box_in", DENSITY, (), 0.043), "box_out": ("box_out", DENSITY, (), 0.043),
    "small": ("small", DENSITY / 0.01, (), 0.038), "large": ("large", DENSITY / 100, (), 0.032),
    "gltf_texcoord_1": ("box_out", DENSITY, ("gltf",), 0.043),
}


@pytest.mark.external
@pytest.mark.slow
@pytest.mark.parametrize("case", [c if c in ("small", "gltf_texcoord_1") else pytest.param(c, marks=pytest.mark.corpus)
                                  for c in UNTUNED])
def test_lightmap_on_scenes_it_was_not_tuned_on(case, tmp_path, panoramas):
    """The open box wound inwards and outwards, scaled by 0.01 and 100 (its density with it), with a
    glTF floor's own TEXCOORD_1 charts: every region within 1.2x the measured figure under city, both
    bases (measured 3.2-4.3%)."""
    name, density, extra, worst = UNTUNED[case]
    sets = [f"objects.1.mesh.path={gltf_floor(tmp_path)}"] if "gltf" in extra else []
    got, report = regions(name, "city", panoramas, tmp_path / "cache", sets, density)
    assert report["uv_sources"]["1"] == ("texcoord_1" if sets else "xatlas")
    for basis, held in got.items():
        assert len(held) >= 4, held
        bad = outside(held, 1.2 * worst)
        assert not bad, f"{case}, {basis}: regions over {1.2 * worst:.1%}: {bad}"
