"""The real-time GI corpus (examples/corpus/, docs/benchmarks.md "Real-time GI on scenes it was not
built for"): scene by scene, the study's real-time rungs against the converged reference. Probes are
no worse than SH with GTAO on the diffuse term, the reflection probes (with and without SSR) no
worse than the distant chain on the specular term, each within twice the reference's own noise (a
difference the reference cannot tell), or the scene's documented, measured exception. And the
issue's gold sphere, region by region."""

from pathlib import Path

import numpy as np
import pytest

from iblbake.render import render
from iblbake.render.bakes import Bakes

ROOT = Path(__file__).resolve().parents[1]
CORPUS = sorted((ROOT / "examples" / "corpus").glob("*.yaml"))
# a scene's measured exception to an ordering: (scene, better rung, worse rung) -> why
EXCEPTIONS: dict = {}


@pytest.fixture(scope="module")
def runtime():
    from iblbake.device.runtime import Runtime
    return Runtime()


def study(path, runtime, cache, max_side=40):
    from iblbake.study import accuracy as acc, ladder
    settings = acc.Settings(max_side=max_side, repeats=1, target_noise=0.02, max_samples=512, flip=False)
    st = acc.Study(path, [], settings, runtime=runtime, bakes=Bakes(cache))
    for t in st.terms:
        st.render_reference(t)
    rows = {r.label: st.run_rung(r) for r in ladder.realtime_ladder(st.scene, st.fx)}
    return st, rows


@pytest.mark.external
@pytest.mark.slow
@pytest.mark.parametrize("path", CORPUS, ids=[p.stem for p in CORPUS])
def test_each_mode_is_no_worse_than_what_it_replaces(path, runtime, tmp_path, panoramas):
    if not (ROOT / "examples" / "corpus" / "meshes" / "garden.glb").exists():
        pytest.fail("the corpus meshes are missing: run `make meshes`")
    st, rows = study(path, runtime, tmp_path / "cache")
    pairs = []
    if "probes" in rows:
        pairs.append(("probes", "SH + GTAO", "diffuse"))
    for label in ("reflection probes", "reflection probes + SSR"):
        if label in rows:
            pairs.append((label, "distant", "specular"))
    assert pairs, "a corpus scene tests some ordering"
    for better, worse, term in pairs:
        if (path.stem, better, worse) in EXCEPTIONS:
            continue
        slack = 2 * st.reference[term]["noise_each"]
        a, b = rows[better]["relative_rmse"], rows[worse]["relative_rmse"]
        assert a <= b + slack, f"{path.stem}: {better} {a:.3f} > {worse} {b:.3f} (+ {slack:.3f} noise)"


@pytest.mark.external
@pytest.mark.slow
@pytest.mark.parametrize("panorama", ["studio", "city"])
def test_the_gold_sphere_mirrors_the_floor(tmp_path, runtime, panoramas, panorama):
    """The issue's rough gold sphere on a grey floor (examples/corpus/resting.yaml), its lower half
    (which mirrors the lit floor): the reflection probe at its centre, the sphere excluded from its
    own capture, brings the half's error (its mean colour's, against the converged reference) to
    at most half the distant chain's (measured at 64 px: studio 5.7% against 16.7%, city 1.7%
    against 74.4%; before the capture's sky was kept apart and the floor read at its distance-
    narrowed level, 1.1% and 3.6%; the probe's capture of the sphere's inside had made it 133-139%
    off), and SSR on top of it is no worse than the probe alone (measured: the same) nor noisier
    than the reference (its pixel noise, each pixel less its 3 x 3 neighbours' mean: 0.065 and
    0.046 against 0.105 and 0.061; the level narrowed to the capture's base, 0.23 and 0.11)."""
    from scipy.ndimage import binary_erosion, uniform_filter

    from iblbake.render import twin as rr
    from iblbake.scene import load, pack

    path = ROOT / "examples" / "corpus" / "resting.yaml"
    sets = [f"environment.path={panoramas[panorama]}", "camera.resolution=[64,64]", "environment.background=hide"]
    bakes = Bakes(tmp_path / "cache")

    def spec(*extra):
        sc = load.load(path, sets + list(extra))
        f = render(sc, runtime=runtime, cache=bakes)
        if "effects.ssr=on" in extra:              # its rays read the lit frame: both terms, less the diffuse
            d = render(load.load(path, sets + [e for e in extra if "ssr" not in e] + ["effects.specular=off"]),
                              runtime=runtime, cache=bakes)
            return f.hdr[..., :3] - d.hdr[..., :3]
        return render(load.load(path, sets + list(extra) + ["effects.diffuse=off"]), runtime=runtime,
                             cache=bakes).hdr[..., :3]

    ref = spec("effects.specular=reference", "effects.reference.max_samples=2048", "effects.reference.target_noise=0")
    sc = load.load(path, sets)
    gb = rr.primary(sc["camera"], pack.scene_arrays(sc))
    lower = ((gb["kind"] == 1) & gb["hit"] & (gb["pos"][:, 1] < 1.0)).reshape(64, 64)
    lower = binary_erosion(lower, np.ones((3, 3), bool))       # whole pixels of the sphere only

    def err(img):
        a, b = img[lower].mean(0), ref[lower].mean(0)
        return float(np.abs(a - b).sum() / b.sum())

    def noise(img):
        y = img.mean(-1)
        r = (y - uniform_filter(y, 3))[binary_erosion(lower, np.ones((3, 3), bool))]
        return float(np.sqrt((r ** 2).mean()) / y[lower].mean())

    distant = spec("effects.reflection_probes=false")
    probe = spec("effects.reflection_probes=true")
    both = spec("effects.reflection_probes=true", "effects.ssr=on")
    assert err(probe) <= 0.5 * err(distant), (err(probe), err(distant))
    assert err(both) <= err(probe) + 0.005, (err(both), err(probe))
    assert noise(both) <= noise(ref), (noise(both), noise(ref))
