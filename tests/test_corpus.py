"""The real-time GI corpus (examples/corpus/, docs/benchmarks.md "Real-time GI on scenes it was not
built for"): scene by scene, the study's real-time rungs against the converged reference. Probes are
no worse than SH with GTAO on the diffuse term, the reflection probes (with and without SSR) no
worse than the distant chain on the specular term, each within twice the reference's own noise (a
difference the reference cannot tell), or the scene's documented, measured exception. And the
issue's gold sphere, region by region. Issue 59: the ordinary interiors held to the truth in
absolute terms (every region, the frame, each half of the gold sphere)."""

from pathlib import Path

import numpy as np
import pytest

from iblbake.render import render
from iblbake.render.bakes import Bakes
from tests.helpers import REGION_BOUND, corpus_cases, outside

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
    if not (ROOT / "examples" / "corpus" / "meshes" / "skylight_room.obj").exists():
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


# Issue 59: ordinary interiors held to the truth in absolute terms, not only against what the probes
# replace. A region (an object the camera sees in full-coverage pixels, at least MIN_PIXELS of them:
# a sliver's mean is its reference's noise) is within the bound when its mean luminance is within
# it of the truth's and its worst channel's |mean difference| within it of the truth's mean
# (core/metrics mean_errors); the frame's relative RMSE of the term, less the reference's own
# noise (in quadrature), is what seams along wall edges and blotches raise while region means
# hide them.
INTERIORS = ("corridor", "two_storey", "quad_room", "l_room", "probe_box_walls")
FRAME_BOUND = 0.30         # the diffuse term's relative RMSE over the frame
PART_BOUND = 0.10          # a reflection probe at a metal object's centre, each half of the object
# Measured misses, each bound about 1.2x the figure measured at 40 px (docs/benchmarks.md and
# docs/status.md, issue 59): the patch studio's lamps throw through a window or skylight is sharper
# than the probe grid resolves (the region means hold; the frame's RMSE is the patch spread over the
# floor around it: QUALITY below, the lamps extracted as lights, closes it): two_storey 56.7% (72.3%
# at the median's spacing; cells of the nearer quarter resolve more of the patch) and
# probe_box_walls 58.8% (its own box) under studio at 40 px (two_storey under city 28.5%, within
# the bound). thin_wall's dim sphere under studio: x1.07 (x1.44 at the median's). The reflection probe has
# none left here: quad_room's gold sphere under studio was x1.25 on its window half (32% at 64 px)
# while the distant chain's lobe filled the edge of the window its points see but the probe does not.
# Since `environment.sun: auto` lights the extracted lamps per pixel (64 px, 1024-sample references)
# every frame is within 24% (two_storey under studio 55% -> 11%, probe_box_walls 60% -> 10%): none missed.
FRAME_MISSES: dict = {}
# The seams (core/metrics.py edge_over_interior: the luminance ratio to the truth on the one-pixel band
# either side of every junction over the ratio away from them, or its inverse, whichever is larger):
# measured at 40 px, 256-sample references, 0.93-1.08 on every interior under either panorama, two_storey
# under city 1.137 (1.19 with probe_irradiance's step in a junction's own cells alone, 1.22 with none:
# its floor by the window wall, in cells with one wall, read the floor's layer, 0.3 cell and its
# relocation above it, where the window's light grows fast with height; the step now reaches a point
# within a cell of a junction, from where its layer's probes stand; docs/conventions.md "Junctions").
# Its band is the truth's now (x1.01); what is left is its floor's interior, x0.89. Issue 47's bright
# lines along every wall edge read far above these.
SEAM_BOUND = 1.15
SEAM_MISSES: dict = {}
# Read in taps (TAPS below; 64 px), no half misses now: metal_box's cube under studio was 11.4% on its
# +x face's worst channel (its upper part, which mirrors the box's open corner, 1.46-1.58x too bright in
# red and blue) while each tap's sky was the probe's over its open share alone: a studio lamp the probe
# saw in a sliver of the opening spread over all the face sees of it (kernels/reflection_probes.h
# rprobe_tap_sky): 3.0% now (10.9-11.4% before over the capture's seeds 1-3, 0.5-4.4% now). Its worst
# half under studio, -x 9.3% (the red wall), is the capture's path noise at 64 samples a texel: 3.4% and
# 0.7% with seeds 2 and 3, 1.6% at 256 samples; under city -x 8.6% (7.9% at 256 samples), as before.
# window_room's chrome sphere under studio (its probe at the room's centre) now mirrors the clay sphere
# where it stands through the capture's distance (kernels/reflection_probes.h rprobe_hit): 5.1% (x1.04)
# on the half facing it; pinned on the wall behind by the box alone it was 24.3% (x1.21). metal_box
# under city was x0.88 on its -x face (13%) while each tap's read of the scene was floored at level 2
# (the black floor under the cube bled into the lit floor beside it): x0.93 (8%) at the tap's own level.
# With `environment.sun: auto` the extracted lamps' and sun's specular was the lights pass's
# representative point (Karis 2013), 0.88-0.95 of a disk light's exact energy on a glossy lobe:
# resting's gold sphere under studio x0.88-0.93 on every half (15.2% worst); with soft shadows the
# pass now integrates the disk (kernels/lights.cl, tests/test_lights.py): x0.95-1.00 (7.0%; 2.4%
# under city). window_room's chrome sphere was 13.5% / 12.5% (studio / city), not the extraction's:
# its probe did not exclude it (the other corpus probes exclude their metal object), so its lower
# half marched into its own image in the capture (-y x1.08 / x0.91 at 1,024 capture samples in
# either sun mode, x1.03 / x1.03 excluded), and the 64-sample capture's noise moves the halves by
# up to 8% over seeds (9.4% / 7.6% with the lamps in the panorama was one seed); its probe excludes
# it now: 7.5% / 9.6%. Measured at 64 px, 1024-sample references; each bound 1.2x.
PART_MISSES: dict = {}


def absolute_study(name, panorama, panoramas, runtime, cache, term, label, extra=(), max_side=40, max_samples=256,
                   target_noise=0.03):
    """The term's converged reference (40 px; two seeds, each to 3% or 256 samples: the region
    means' noise is well under a percent) and the real-time rung `label` against it, the rung
    with the scene keys `extra` ([(key, value)]) on top (the reference without them). `name`: a
    corpus scene's, or a scene file's path. A metal object's halves want more (max_side,
    max_samples): at 40 px and 256 samples the studio's specular reference is 14% noisy a pixel and
    its small halves move by 5-10%."""
    from iblbake.study import accuracy as acc, ladder
    other = {"diffuse": "specular", "specular": "diffuse"}[term]
    settings = acc.Settings(max_side=max_side, repeats=1, target_noise=target_noise, max_samples=max_samples,
                            flip=False)
    st = acc.Study(name if isinstance(name, Path) else ROOT / "examples" / "corpus" / f"{name}.yaml",
                   [f"environment.path={panoramas[panorama]}", f"effects.{other}=off"], settings,
                   runtime=runtime, bakes=Bakes(cache))
    st.render_reference(term)
    rung = next(r for r in ladder.realtime_ladder(st.scene, st.fx) if r.label == label)
    return st, st.run_rung(ladder.Rung(rung.term, rung.label, rung.values + list(extra)))


@pytest.mark.external
@pytest.mark.slow
@pytest.mark.parametrize("panorama", ["studio", "city"])
@pytest.mark.parametrize("name", INTERIORS + ("thin_wall",))
def test_default_probes_hold_each_interior_to_the_truth(name, panorama, runtime, tmp_path, panoramas):
    """Default `probes: {}` (the probe box on the walls in probe_box_walls) within REGION_BOUND
    of the converged reference on every region, the frame within FRAME_BOUND and its seams within
    SEAM_BOUND, or their measured misses (docs/benchmarks.md
    "The corpus in absolute terms" has the figures: on the code of issue 47 the corridor's
    far end is 10-20x too bright, and every interior is outside one bound or the other)."""
    if not (ROOT / "examples" / "corpus" / "meshes" / "skylight_room.obj").exists():
        pytest.fail("the corpus meshes are missing: run `make meshes`")
    st, row = absolute_study(name, panorama, panoramas, runtime, tmp_path / "cache", "diffuse", "probes")
    noise = st.reference["diffuse"]["noise"]
    frame = max(row["relative_rmse"] ** 2 - noise ** 2, 0.0) ** 0.5
    bad = outside(row["region_absolute"], REGION_BOUND)
    bound = FRAME_MISSES.get((name, panorama), FRAME_BOUND)
    seam, seam_bound = row["edge_over_interior"], SEAM_MISSES.get((name, panorama), SEAM_BOUND)
    assert not bad and frame <= bound and max(seam, 1 / seam) <= seam_bound, \
        f"{name} under {panorama}: regions over {REGION_BOUND:.0%}: {bad}; frame {frame:.1%} (bound {bound:.0%}); " \
        f"seams {seam:.3f} (bound {seam_bound})"


def thin_wall_variant(folder, scale: float) -> Path:
    """A scene the automatic spacing was not tuned on: thin_wall scaled by `scale`, its wall wound
    the other way, the dim sphere smaller and moved towards the back wall."""
    import yaml
    data = yaml.safe_load((ROOT / "examples" / "corpus" / "thin_wall.yaml").read_text())
    meshes = ROOT / "examples" / "corpus" / "meshes"
    lines = (meshes / "rooms_wall.obj").read_text().splitlines()
    flipped = [" ".join(["f", *reversed(ln.split()[1:])]) if ln.startswith("f ") else ln for ln in lines]
    (folder / "wall.obj").write_text("\n".join(flipped) + "\n")
    cam = data["camera"]["perspective"]
    cam.update(position=[scale * x for x in cam["position"]], look_at=[scale * x for x in cam["look_at"]])
    spheres = [o["sphere"] for o in data["objects"] if "sphere" in o]
    spheres[1].update(center=[1.0, 0.4, -0.3], radius=0.4)
    for s in spheres:
        s.update(center=[scale * x for x in s["center"]], radius=scale * s["radius"])
    data["objects"][2]["mesh"] = {"path": str(meshes / "rooms_shell.obj"), "scale": scale}
    data["objects"][3]["mesh"] = {"path": str(folder / "wall.obj"), "scale": scale}
    path = folder / "variant.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.external
@pytest.mark.slow
@pytest.mark.parametrize("scale", [0.01, 100.0])
def test_default_probes_hold_a_thin_wall_room_they_were_not_tuned_on(scale, runtime, tmp_path, panoramas):
    """thin_wall_variant under studio at default `probes: {}`: every region within REGION_BOUND
    (the automatic spacing, the biases and the rules are in the interior's own units)."""
    path = thin_wall_variant(tmp_path, scale)
    st, row = absolute_study(path, "studio", panoramas, runtime, tmp_path / "cache", "diffuse", "probes")
    bad = outside(row["region_absolute"], REGION_BOUND)
    assert not bad, f"the thin wall's variant at scale {scale}: regions over {REGION_BOUND:.0%}: {bad}"


def metal_halves_over(name, panorama, panoramas, runtime, cache, extra=()):
    """(halves, bound): the halves of a corpus scene's metal object whose specular term under its
    reflection probe (extra: scene keys on the rung) lies outside their bound (PART_MISSES, else
    PART_BOUND), judged at 64 px against 1024-sample references, as every metal object's are."""
    if not (ROOT / "examples" / "corpus" / "meshes" / "skylight_room.obj").exists():
        pytest.fail("the corpus meshes are missing: run `make meshes`")
    st, row = absolute_study(name, panorama, panoramas, runtime, cache, "specular", "reflection probes", extra,
                             max_side=64, max_samples=1024)
    assert row.get("part_absolute"), "the study judges the metal object's halves"
    bound = PART_MISSES.get((name, panorama), PART_BOUND)
    return outside(row["part_absolute"], bound), bound


@pytest.mark.external
@pytest.mark.slow
@pytest.mark.parametrize("panorama", ["studio", "city"])
def test_the_reflection_probe_holds_each_half_of_the_metal_object(panorama, runtime, tmp_path, panoramas):
    """quad_room's reflection probe at the gold sphere's centre excluding it: the specular term on
    each half of the sphere (core/metrics halves: +x, -x, +y, ...) within PART_BOUND of the
    converged reference, the half facing the window too (on the code of issue 47, 2.2-2.4x too
    bright under studio; within 7% under city; with the distant chain filling the window's edge
    the points see but the probe does not, x1.39 (50%) at 40 px under studio, now within 10%). resting's gold sphere is not here: within 10% on
    every half at 48 and 64 px, with references of 256 to 8192 samples (docs/benchmarks.md).
    At 64 px, 1024-sample references, as the other metal objects' halves are judged: at 40 px and
    256 samples the reference's halves sit 4-7% off the finer one's (one read: x1.02-1.07 there,
    x0.97-1.03 here); with the lamps extracted (`environment.sun: auto`) the window half under
    studio x0.967, every half within 4.5%."""
    bad, bound = metal_halves_over("quad_room", panorama, panoramas, runtime, tmp_path / "cache")
    assert not bad, f"quad_room under {panorama}: halves over {bound:.0%}: {bad}"


# A reflection probe at (or in the room of) a metal object, its capture excluding the object, read
# in TAPS taps over the material's lobe (reflection_probes.N.taps; kernels/reflection_probes.h
# rprobe_taps): each half of the object within PART_BOUND or its measured miss in PART_MISSES
# (each about 1.2x the figure measured at 64 px). Measured worst halves (references of 1024
# samples): resting 1.4% (studio), 0.8% (city); quad_room 6.5%, 5.2%; window_room 7.7%, 7.2%;
# metal_box 9.3%, 8.6% (its -x face, the red wall; the capture's noise under studio, above).
TAPS = 64
TAPS_SCENES = ("quad_room", "window_room", "metal_box", "resting")


@pytest.mark.external
@pytest.mark.slow
@pytest.mark.parametrize("name, panorama", corpus_cases(TAPS_SCENES, keep={("resting", "studio"), ("metal_box", "city")}))
def test_the_reflection_probe_in_taps_holds_each_half_of_the_metal_object(name, panorama, runtime, tmp_path,
                                                                          panoramas):
    """The corpus' metal objects under their reflection probe read in TAPS taps, each half within
    PART_BOUND of the converged reference or its measured miss (taps at a fixed share of the lobe's
    level, before: city's sun aliased between them, resting's gold sphere 54% off on its -x half
    (x1.36) and 51% on +y at 64 px; metal_box under studio 14%, 11.4% while each tap's sky was the
    probe's over its open share alone)."""
    bad, bound = metal_halves_over(name, panorama, panoramas, runtime, tmp_path / "cache",
                                   [("reflection_probes.0.taps", TAPS)])
    assert not bad, f"{name} under {panorama} with {TAPS} taps: halves over {bound:.0%}: {bad}"


# The default reading (reflection_probes.N.grazing_taps: 16 taps where the view grazes the surface,
# one read elsewhere; kernels/reflection_probes.h rprobe_grazing): each half of the corpus' metal
# objects within PART_BOUND at 64 px, 1024-sample references (measured worst halves, studio / city,
# at `sun: auto`, stop 70: quad_room 3.9% / 3.1%, resting 7.0% / 2.4%, metal_box 6.3% / 9.4%,
# window_room 7.5% / 9.6% (its probe excluding its sphere; 13.5% / 12.5% before); with `sun: none`:
# quad_room 6% / 5%, resting 4.5% / 2%, window_room 9.4% / 7.7%, metal_box 6.7% / 9.6%). One read
# everywhere (the default before) missed four: resting's lower half under studio 13.5% (the split
# sum at grazing angles), window_room's chrome sphere 16.6% / 20.2%, metal_box's cube under city
# 14.5%.
@pytest.mark.external
@pytest.mark.slow
@pytest.mark.parametrize("name, panorama", corpus_cases(TAPS_SCENES, keep={("resting", "studio"),
                                                                          ("window_room", "city")}))
def test_the_reflection_probe_at_its_default_holds_each_half_of_the_metal_object(name, panorama, runtime, tmp_path,
                                                                                 panoramas):
    """The corpus' metal objects under their reflection probe at its defaults (taps at grazing
    views), each half within PART_BOUND of the converged reference or its measured miss."""
    bad, bound = metal_halves_over(name, panorama, panoramas, runtime, tmp_path / "cache")
    assert not bad, f"{name} under {panorama} at the default reading: halves over {bound:.0%}: {bad}"


# The documented quality setting for interiors (docs/manual.md "Irradiance probes in interiors"):
# the panorama's sun and lamps extracted as lights with soft shadows, so the patch a window or
# skylight throws is lit per pixel with its shadow and the probes hold the rest (their paths light
# what they meet by the extracted lights too), 4096 rays a probe for the noise of that bounce.
# Every region within QUALITY_BOUND, the frame within FRAME_BOUND, or their measured misses (each
# bound about 1.2x the figure at 40 px): quad_room's floor under city is within it on the finer
# automatic cells (x1.09, 11%; x1.12, 15.4% on the median's), and where two_storey's slab of no thickness meets its walls the top row of wall
# pixels takes the storey above through the probes' visibility (15 pixels, two thirds of the
# frame's squared error; the lamps' patch, which was the rest, is gone).
QUALITY = (("environment.sun", "extract"), ("environment.sun_lights", 4), ("environment.sun_shadows", "soft"),
           ("probes.rays", 4096))
QUALITY_BOUND = 0.15
# l_room's ceiling under city x1.11, its worst channel 15.0% at 40 px on the finer automatic cells
# (every region of the six within 13.9% under city on the coarser cells but quad_room's floor)
QUALITY_MISSES = {("l_room", "city"): 0.18}
QUALITY_FRAME: dict = {}


@pytest.mark.external
@pytest.mark.slow
@pytest.mark.parametrize("panorama", ["studio", "city"])
@pytest.mark.parametrize("name", INTERIORS + ("window_room",))
def test_the_quality_setting_holds_each_interior(name, panorama, runtime, tmp_path, panoramas):
    """QUALITY on top of the scene's probes: every region within QUALITY_BOUND of the converged
    reference and the frame's relative RMSE (less the reference's noise) within FRAME_BOUND, or
    QUALITY_MISSES' and QUALITY_FRAME's measured figures. Measured at 40 px, the frame less noise:
    studio 7.8% corridor, 17.2% two_storey, 7.8% quad_room, 9.9% l_room, 18.5% probe_box_walls,
    14.0% window_room, every region within 12.3%; city 7.2%, 21.4%, 16.9%, 17.7%, 11.0%, 16.2%,
    every region within 13.9% but quad_room's floor, 15.4%. On the code before `sun_lights` studio,
    which has no sun, lost nothing: its frames were 83% (two_storey), 60% (probe_box_walls) and 56%
    (window_room) at 64 px."""
    if not (ROOT / "examples" / "corpus" / "meshes" / "skylight_room.obj").exists():
        pytest.fail("the corpus meshes are missing: run `make meshes`")
    # the reference to its full 256 samples: with the lamps extracted its frame reaches 3% noise sooner
    # (the near half's), and the corridor's far end (27 pixels lit after several bounces) stopped
    # short read the probes x1.27 where 4096 samples read them x1.10
    st, row = absolute_study(name, panorama, panoramas, runtime, tmp_path / "cache", "diffuse", "probes", QUALITY,
                             target_noise=0.0)
    noise = st.reference["diffuse"]["noise"]
    frame = max(row["relative_rmse"] ** 2 - noise ** 2, 0.0) ** 0.5
    bound = QUALITY_MISSES.get((name, panorama), QUALITY_BOUND)
    bad = outside(row["region_absolute"], bound)
    most = QUALITY_FRAME.get((name, panorama), FRAME_BOUND)
    assert not bad and frame <= most, \
        f"{name} under {panorama}: regions over {bound:.0%}: {bad}; frame {frame:.1%} (bound {most:.0%})"
