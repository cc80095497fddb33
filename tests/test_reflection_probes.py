"""Local reflection probes (`reflection_probes:`, read by `specular: prefiltered`): a capture of
an unoccluded sky holds it as its sky, and the probe then reproduces `prefiltered`;
with a box proxy a mirror floor shows a marked point of a wall where the closed-form ray-box
intersection puts it; the frame against the shade pass's twin; what runs where probes are not
read; one-line errors; a probe at a gold sphere's centre in a window room and on a floor, half by
half against the reference; the note where a room's specular mirrors the distant sky."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from iblbake.render import plan, render
from iblbake.io import images
from iblbake.render.bakes import Bakes
from iblbake.scene import load, pack
from tests.helpers import BakeContext, load_scene, run_cli


write = load_scene


@pytest.fixture
def sky(lobed_sky):
    return lobed_sky


def window(folder, sky, probes, name="window"):
    """A single-sided metal plate facing the camera; the probe behind it, whose rays pass through
    its back: the probe sees the sky alone."""
    return write(folder, name, {
        "camera": {"perspective": {"position": [0, 0.3, 3], "look_at": [0, 0, 0], "fov_y": 40}, "resolution": [32, 32]},
        "environment": {"path": str(sky)},
        "materials": {"metal": {"base_color": [0.9, 0.8, 0.7], "metallic": 1, "roughness": 0.35,
                                "double_sided": False}},
        "objects": [{"plane": {"point": [0, 0, 0], "normal": [0, 0, 1], "size": 2}, "material": "metal"}],
        "reflection_probes": probes,
        "effects": {"diffuse": "off", "specular": "prefiltered"}})


def captures(bakes):
    """(image, cached) of every capture the store holds."""
    return [v[:2] for v in bakes.held("reflection").values()]


@pytest.mark.slow       # make test; make check keeps under 3 minutes
def test_a_capture_of_the_open_sky_holds_the_sky_alone(tmp_path, rt, sky):
    """A capture that sees only the sky holds no scene radiance and no coverage, and the sky past
    the scene in its sky channels (read along the reflected ray itself); at the panorama's own
    resolution and one ray a texel, through its centre, that is the panorama texel for texel, so
    with or without parallax, a box or a sphere proxy, the probe shades the plate exactly as
    `prefiltered` does (measured 0)."""
    bakes = Bakes(tmp_path / "cache")
    distant = render(window(tmp_path, sky, [], "plain"), runtime=rt, cache=bakes)
    hit = distant.hdr[..., 3] > 0.999
    for shape, parallax in (("box", False), ("box", True), ("sphere", True)):
        probe = {"position": [0, 0, -1], "size": 32, "samples": 1, "parallax": parallax, "shape": shape,
                 **({"min": [-2, -2, -2], "max": [2, 2, 2]} if shape == "box" else {"radius": 3})}
        with_probe = render(window(tmp_path, sky, [probe], f"w{shape}{parallax}"), runtime=rt, cache=bakes)
        for image, _cached in captures(bakes):
            assert image.shape == (32, 64, 8) and not image[..., :4].any() and not image[..., 7].any()
            assert np.array_equal(image[..., 4:7], images.read_exr(sky)[..., :3])
        a, b = with_probe.hdr[hit][:, :3], distant.hdr[hit][:, :3]
        assert hit.sum() > 200 and np.abs(a - b).max() / b.max() < 1e-6


@pytest.mark.slow       # make test; make check keeps under 3 minutes
def test_a_probe_inside_a_sphere_sees_it_all_around(tmp_path, rt, sky):
    """A probe inside a glowing sphere of radius 3 (emission E, black, the sky shut out; its
    inside is a back face, which captures shade as the camera does): every texel of the capture
    covered, E to float32 where it sees the glow, E on average where it sees the small metal
    sphere's reflection of it; its distance channel (Z) the glowing sphere's distance along the
    texel's rays (their mean: within 0.2% of the texel centre's, measured 0.04%)."""
    from iblbake.core import conventions
    sc = load_scene(tmp_path, "inside", {
        "camera": {"perspective": {"position": [0, 0, 1], "look_at": [0, 0, 0]}, "resolution": [8, 8]},
        "environment": {"path": str(sky)},
        "materials": {"glow": {"base_color": [0, 0, 0], "emissive": [0.5, 1.0, 2.0], "specular": 0},
                      "metal": {"base_color": [1, 1, 1], "metallic": 1, "roughness": 0.2}},
        "objects": [{"sphere": {"radius": 3}, "material": "glow"},
                    {"sphere": {"radius": 0.3}, "material": "metal"}],
        "reflection_probes": [{"shape": "sphere", "position": [0, 1, 0], "radius": 2.9, "size": 16, "samples": 2}],
        "effects": {"diffuse": "off", "specular": "prefiltered"}})
    bakes = Bakes(tmp_path / "cache")
    render(sc, runtime=rt, cache=bakes)
    (image, _cached), = captures(bakes)
    assert (image[..., 3] == 1).all()
    ratio = image[..., :3] / [0.5, 1.0, 2.0]
    assert np.abs(ratio[:14] - 1).max() < 1e-6
    # the bottom two rows see the small metal sphere: its reflection of the glow, through Russian
    # roulette at 2 paths a texel, GGX's single-scattering loss on top (measured 0.8% low)
    assert abs(ratio[14:].mean() - 1) < 0.05
    d = conventions.equirect_texel_dirs(32, 16)
    b = d[..., 1]                                   # o = (0, 1, 0): the ray's far root on radius 3
    want = -b + np.sqrt(b * b + 8.0)
    assert np.abs(image[:14, :, 7] / want[:14] - 1).max() < 0.002


def room(folder, parallax, name):
    """A closed 4 x 3 x 4 room, a mirror floor, a small bright square on the wall x = -2 (the only
    light), a box probe the size of the room away from its centre; the camera looks at the floor."""
    walls = [([0, 3, 0], [0, -1, 0]), ([-2, 1.5, 0], [1, 0, 0]), ([2, 1.5, 0], [-1, 0, 0]),
             ([0, 1.5, -2], [0, 0, 1]), ([0, 1.5, 2], [0, 0, -1])]
    objs = [{"plane": {"point": [0, 0, 0], "size": 4}, "material": "mirror"}]
    objs += [{"plane": {"point": p, "normal": nrm, "size": 4}, "material": "wall"} for p, nrm in walls]
    objs.append({"plane": {"point": [-1.98, 1.2, 0.3], "normal": [1, 0, 0], "size": 0.25}, "material": "mark"})
    black = Path(folder) / "black.exr"
    if not black.exists():
        images.write_exr(black, np.zeros((8, 16, 3), np.float32))
    return write(folder, name, {
        "camera": {"perspective": {"position": [1.6, 1.3, 1.4], "look_at": [-0.6, 0, 0.2], "fov_y": 60},
                   "resolution": [128, 96]},
        "environment": {"path": str(black)},
        "materials": {"mirror": {"base_color": [1, 1, 1], "metallic": 1, "roughness": 0},
                      "wall": {"base_color": [0.5, 0.5, 0.5], "roughness": 1, "specular": 0},
                      "mark": {"base_color": [0, 0, 0], "emissive": [40, 40, 40], "specular": 0}},
        "objects": objs,
        "reflection_probes": [{"position": [0.6, 1.6, 0.7], "min": [-2, 0, -2], "max": [2, 3, 2], "size": 128,
                               "samples": 4, "bounces": 1, "parallax": parallax}],
        "effects": {"diffuse": "off", "specular": "prefiltered"},
        "output": {"normal": "n.exr"}})


def project(cam, x, w, h):
    """The pixel position (x right, y down) of point x (scene/pack.py camera_vectors: right and up
    span half the view at distance 1)."""
    pos, fwd, right, up, _ortho = pack.camera_vectors(cam)
    d = np.asarray(x) - pos
    z = d @ fwd
    sx, sy = d @ right / (right @ right) / z, d @ up / (up @ up) / z
    return np.array([(sx + 1) / 2 * w, (1 - sy) / 2 * h])


@pytest.mark.slow       # make test; make check keeps under 3 minutes
def test_parallax_puts_a_wall_mark_where_the_mirror_shows_it(tmp_path, rt):
    """The mark mirrored in the floor appears along the camera's ray to its mirror image
    (-1.98, -1.2, 0.3); with the box proxy the probe's reflection of it lands within 2 pixels of
    there (a capture texel is 1.7 pixels here; measured 0.32), without parallax 12 pixels or more
    away (measured 18.8)."""
    spots = {}
    for parallax in (True, False):
        sc = room(tmp_path, parallax, f"room_{parallax}")
        f = render(sc, runtime=rt, cache_root=tmp_path / "cache")
        floor = f.aovs["normal"][..., 1] > 0.99
        lum = f.hdr[..., :3].mean(-1) * floor
        ys, xs = np.nonzero(lum > 0.25 * lum.max())
        wts = lum[ys, xs]
        spots[parallax] = np.array([(xs + 0.5) @ wts, (ys + 0.5) @ wts]) / wts.sum()
    cam = sc.data["camera"]
    want = project(cam, [-1.98, -1.2, 0.3], *cam["resolution"])
    assert np.linalg.norm(spots[True] - want) < 2.0, (spots, want)
    assert np.linalg.norm(spots[False] - want) > 12.0, (spots, want)


@pytest.mark.slow           # over 3 s on the 2-core CPU: make test, not make check
@pytest.mark.parametrize("taps, grazing", [(0, 0), (16, 0), (0, 16)])
def test_frame_matches_the_twin(tmp_path, rt, taps, grazing):
    """The room frame (two probes: the box and a sphere around the mark's corner, overlapping; a
    grey ball off the box's walls, which the box probe's reads march to through its distance
    chain, rprobe_hit) against the shade pass's twin on its G-buffer with the same chains
    (measured 3.3e-7), read once a lobe, in 16 taps over the true lobe (rprobe_taps), or in 16
    taps where the view grazes the surface, one read elsewhere, blended between (rprobe_grazing;
    the floor seen edge-on far off)."""
    from iblbake.render import twin as rr

    sc = room(tmp_path, True, "room_twin")
    doc = yaml.safe_load(Path(sc.source).read_text())
    doc["reflection_probes"].append({"shape": "sphere", "position": [-1.2, 1.0, 0.5], "radius": 1.5, "size": 128,
                                     "samples": 4, "bounces": 1, "blend": 0.5})
    for probe in doc["reflection_probes"]:
        probe.update(taps=taps, grazing_taps=grazing)
    doc["materials"]["mirror"]["roughness"] = 0.3
    doc["materials"]["ball"] = {"base_color": [0.6, 0.6, 0.6], "roughness": 0.8}
    doc["objects"].append({"sphere": {"center": [-0.2, 0.4, -0.6], "radius": 0.4}, "material": "ball"})
    doc["output"] = {}
    sc = write(tmp_path, "room_twin2", doc)
    bakes = Bakes(tmp_path / "cache")
    frame = render(sc, runtime=rt, cache=bakes)
    env_sha = bakes.environment(sc.data["environment"])[1].sha256
    distant = next(v[0] for k, v in bakes.held("prefiltered").items() if k[1] == env_sha)
    table = bakes.result("dfg")
    captured = bakes.load("reflection_probes", BakeContext(sc, rt, bakes))[0]
    # the distance chain is the memo's, as the other chains are: a second frame uploads nothing new
    assert captured[0]["depth"] is bakes.load("reflection_probes", BakeContext(sc, rt, bakes))[0][0]["depth"]
    arrays = pack.scene_arrays(sc)
    gb = rr.primary(sc["camera"], arrays)
    want = rr.shade(gb, arrays, sc["effects"], sc["environment"], prefiltered=distant, dfg=table,
                    reflection_probes=captured)[gb["hit"]]
    got = frame.hdr[..., :3].reshape(-1, 3)[gb["hit"]]
    # float32 against float64: a tap whose march (rprobe_hit) grazes the ball's edge meets it in one
    # and misses it in the other (with 16 taps over the visible normals, 1 pixel of 12,288: 0.0024
    # bright, 7% of itself, 4.5e-6 of the frame's brightest; a read without the march, 0.010)
    off = np.abs(got - want).max(1) / want.max()
    assert (off > 2e-6).sum() <= 2 and off.max() < 1e-5, (int((off > 2e-6).sum()), off.max())
    boxed = rr.shade(gb, arrays, sc["effects"], sc["environment"], prefiltered=distant, dfg=table,
                     reflection_probes=[{**c, "depth": None} for c in captured])[gb["hit"]]
    assert np.abs(boxed - want).max() / want.max() > 0.1      # the march met the ball somewhere
    if grazing:             # the frame has grazing views: their taps changed it
        once = rr.shade(gb, arrays, sc["effects"], sc["environment"], prefiltered=distant, dfg=table,
                        reflection_probes=[{**c, "settings": {**c["settings"], "grazing_taps": 0}}
                                           for c in captured])[gb["hit"]]
        assert np.abs(once - want).max() / want.max() > 0.01



@pytest.mark.slow           # make test, not make check
@pytest.mark.parametrize("reading", [{"taps": 16}, {}])
def test_taps_through_an_opening_match_the_twin(tmp_path, rt, monkeypatch, reading):
    """A box open at its top and front (metal_box's shape) under a panorama with a compact lamp
    above the opening, a rough metal ball at the probe (excluded), read in 16 taps, or at the
    defaults (16 taps at grazing views and where the lobe straddles the opening's edge, by a weight
    that takes every value from 0 to 1 on this frame, one read elsewhere): the frame against the
    shade pass's twin with the same chains, where taps see more of the opening than the probe saw
    about them (rprobe_tap_sky's panorama about the tap on that share)."""
    from iblbake.bake import radiance
    from iblbake.core import conventions
    from iblbake.render import twin as rr
    from iblbake.render.twin import reflection_probes as rpt

    dirs = conventions.equirect_texel_dirs(64, 32)
    pano = np.full((32, 64, 3), 0.3, np.float32)
    pano[(dirs @ np.array([0.5, 0.55, 0.67])) > 0.995] = 40.0
    images.write_exr(tmp_path / "lamp.exr", pano)
    walls = [([0, 0, 0], [0, 1, 0]), ([0, 1, -1], [0, 0, 1]), ([-1, 1, 0], [1, 0, 0]), ([1, 1, 0], [-1, 0, 0])]
    objs = [{"plane": {"point": q, "normal": nrm, "size": 2}, "material": "wall"} for q, nrm in walls]
    objs.append({"sphere": {"center": [0, 0.35, 0], "radius": 0.35}, "material": "metal", "name": "ball"})
    sc = write(tmp_path, "open_box", {
        "camera": {"perspective": {"position": [0.6, 1.2, 2.4], "look_at": [0, 0.35, 0], "fov_y": 30},
                   "resolution": [48, 48]},
        "environment": {"path": str(tmp_path / "lamp.exr")},
        "materials": {"metal": {"base_color": [0.95, 0.93, 0.88], "metallic": 1, "roughness": 0.3},
                      "wall": {"base_color": [0.6, 0.6, 0.6], "roughness": 1, "specular": 0}},
        "objects": objs,
        "reflection_probes": [{"position": [0, 0.35, 0], "min": [-1, 0, -1], "max": [1, 2, 1], "exclude": ["ball"],
                               "size": 32, "samples": 4, "bounces": 1, **reading}],
        "effects": {"diffuse": "off", "specular": "prefiltered"}})
    bakes = Bakes(tmp_path / "cache")
    frame = render(sc, runtime=rt, cache=bakes)
    env_sha = bakes.environment(sc.data["environment"])[1].sha256
    distant = next(v[0] for k, v in bakes.held("prefiltered").items() if k[1] == env_sha)
    captured = bakes.load("reflection_probes", BakeContext(sc, rt, bakes))[0]
    arrays = pack.scene_arrays(sc)
    gb = rr.primary(sc["camera"], arrays)
    shares, straddle = [], rpt.straddle

    def recorded(*args):        # the twin's weights on this frame's lobes
        shares.append(straddle(*args))
        return shares[-1]
    monkeypatch.setattr(rpt, "straddle", recorded)
    want = rr.shade(gb, arrays, sc["effects"], sc["environment"], prefiltered=distant, dfg=bakes.result("dfg"),
                    reflection_probes=captured)[gb["hit"]]
    got = frame.hdr[..., :3].reshape(-1, 3)[gb["hit"]]
    if not reading:
        share = np.concatenate(shares)
        assert share.min() == 0 and share.max() == 1 and np.mean((share > 0) & (share < 1)) > 0.02
    # float32 against float64: 2.5e-6 where taps read the lamp beside the opening's edge at the
    # capture's own level (rprobe_tap_sky: a 40-to-0.3 step between texels); the twin itself moves
    # 8e-7 with its normals and views nudged by 6e-8 (one float32 rounding), the kernel rounds at
    # every step; under 2e-6 before, when they read it filtered
    assert np.abs(got - want).max() / want.max() < 1e-5
    # the share the point sees open beyond the probe's is there: directions from the ball's front
    c, q = captured[0], np.array([[0.0, 0.35, 0.36]])
    rng = np.random.default_rng(2)
    ll = rng.normal(size=(2000, 3)) + [0, 0, 1.5]
    ll /= np.linalg.norm(ll, axis=1, keepdims=True)
    x = rpt.hit(c, np.repeat(q, len(ll), 0), ll)
    d = (x - c["settings"]["position"]) / np.linalg.norm(x - c["settings"]["position"], axis=1, keepdims=True)
    seen = 1 - radiance.chain_lookup_twin(c["coverage"], ll, 2.0)[:, 0]
    opened = 1 - radiance.chain_lookup_twin(c["coverage"], d, 2.0)[:, 0]
    assert np.mean(opened > seen + 0.05) > 0.05

def test_reflection_probes_run_only_where_the_split_sum_reads_them(tmp_path, sky):
    probe = {"position": [0, 0, -1], "min": [-2, -2, -2], "max": [2, 2, 2]}
    pl = plan(window(tmp_path, sky, [probe]))
    assert "reflection_probes" in pl.bakes and pl.defines["shade"]["HAS_REFLECTION_PROBES"] == 1
    off = yaml.safe_load(Path(window(tmp_path, sky, [probe]).source).read_text())
    off["effects"]["reflection_probes"] = False
    for name, sc in (("none", window(tmp_path, sky, [], "none")), ("switched off", write(tmp_path, "off", off)),
                     ("importance", write(tmp_path, "imp", {**yaml.safe_load(Path(window(tmp_path, sky, [probe]).source)
                                                                              .read_text()),
                                                           "effects": {"diffuse": "off", "specular": "importance"}}))):
        pl = plan(sc)
        assert "reflection_probes" not in pl.bakes and "HAS_REFLECTION_PROBES" not in pl.defines.get("shade", {}), name
    from iblbake.render.plan import effect_modes
    from iblbake.study import ladder
    sc = window(tmp_path, sky, [probe])
    labels = [r.label for r in ladder.default_ladder(sc, effect_modes(sc), "CPU")]
    assert {"prefiltered + reflection probes", "prefiltered, distant only", "prefiltered + ssr",
            "prefiltered + reflection probes + ssr"} <= set(labels)
    sc = window(tmp_path, sky, [], "plain2")
    labels = [r.label for r in ladder.default_ladder(sc, effect_modes(sc), "CPU")]
    assert not any("reflection" in x or "distant only" in x for x in labels) and "prefiltered + ssr" in labels


@pytest.mark.parametrize("probe, words", [
    ({"position": [0, 0, 0], "min": [-1, -1, -1]}, "missing required key 'max'"),
    ({"position": [0, 0, 0], "min": [1, -1, -1], "max": [-1, 1, 1]}, "is not above min"),
    ({"position": [5, 0, 0], "min": [-1, -1, -1], "max": [1, 1, 1]}, "lies outside the box"),
    ({"position": [0, 0, 0], "shape": "sphere"}, "missing required key 'radius'"),
    ({"position": [0, 0, 0], "shape": "cone", "radius": 1}, "is not one of box | sphere"),
    ({"position": [0, 0, 0], "min": [-1, -1, -1], "max": [1, 1, 1], "grazing_taps": 300}, "grazing_taps"),
])
def test_bad_reflection_probes_are_one_line_errors(tmp_path, sky, probe, words):
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump({"environment": {"path": str(sky)}, "reflection_probes": [probe]}))
    r = run_cli("render", p, "-o", tmp_path / "x.png")
    assert r.returncode == 1 and words in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.mark.slow           # over 3 s on the 2-core CPU: make test, not make check
def test_iblbake_probes_writes_the_captures_for_engines(tmp_path, sky):
    """`iblbake probes` writes each reflection probe's capture beside the irradiance volume with
    what the renderer reads of it (RGB the scene's radiance, A its coverage, sky.RGB the sky seen
    past the scene: before, RGBA alone, an engine could not tell the window's sky from the distant
    panorama's; Z the distance to the scene, 0 where no ray met it), its channels listed in
    probes.json; `iblbake mips` prefilters its RGB into a KTX2
    cube map as it does any panorama."""
    probe = {"position": [0, 0, -1], "min": [-2, -2, -2], "max": [2, 2, 2], "size": 32, "samples": 1}
    sc = window(tmp_path, sky, [probe], "engines")
    out = tmp_path / "vol"
    r = run_cli("probes", sc.source, "-o", out, "--cache", tmp_path / "cache", "-q")
    assert r.returncode == 0, r.stderr
    man = yaml.safe_load((out / "probes.json").read_text())
    assert [p["file"] for p in man["reflection_probes"]] == ["reflection_0.exr"]
    channels = man["reflection_probes"][0]["channels"]
    assert channels == ["R", "G", "B", "A", "sky.R", "sky.G", "sky.B", "Z"]
    cap = images.read_exr(out / "reflection_0.exr", channels)       # by name: OpenImageIO lists Z after A
    assert cap.shape == (32, 64, 8) and not cap[..., :4].any() and not cap[..., 7].any()   # the open sky: no scene
    assert np.array_equal(cap[..., 4:7], images.read_exr(sky)[..., :3])   # but the sky, texel for texel
    r = run_cli("mips", out / "reflection_0.exr", "--layout", "cubemap", "--size", "16", "--ktx2", tmp_path / "r0.ktx2",
                "--cache", tmp_path / "cache", "-q")
    assert r.returncode == 0 and (tmp_path / "r0.ktx2").stat().st_size > 1000, r.stderr


WALL_COLOURS = {"+x": [1.0, 0.1, 0.1], "-x": [0.1, 1.0, 0.1], "+y": [0.1, 0.1, 1.0], "-y": [1.0, 1.0, 0.1],
                "+z": [0.1, 1.0, 1.0], "-z": [1.0, 0.1, 1.0]}


def glowing_room(folder, name, **probe):
    """A closed box [-2, 2] x [0, 3] x [-2, 2] of six black planes each glowing its own colour, a
    black sky, a sphere of radius 0.3 at (0.7, 1.2, 0.4), and a reflection probe there, off the
    room's centre (so that which wall a texel sees depends on where the probe is)."""
    black = Path(folder) / "black.exr"
    if not black.exists():
        images.write_exr(black, np.zeros((8, 16, 3), np.float32))
    walls = {"+x": ([2, 1.5, 0], [-1, 0, 0]), "-x": ([-2, 1.5, 0], [1, 0, 0]), "+y": ([0, 3, 0], [0, -1, 0]),
             "-y": ([0, 0, 0], [0, 1, 0]), "+z": ([0, 1.5, 2], [0, 0, -1]), "-z": ([0, 1.5, -2], [0, 0, 1])}
    mats = {f"w{k}": {"base_color": [0, 0, 0], "emissive": c, "specular": 0} for k, c in WALL_COLOURS.items()}
    objs = [{"plane": {"point": p, "normal": nrm, "size": 4.01 if k[1] != "y" else [4.01, 4.01]}, "material": f"w{k}"}
            for k, (p, nrm) in walls.items()]
    objs.append({"sphere": {"center": [0.7, 1.2, 0.4], "radius": 0.3}, "material": "ball", "name": "ball"})
    mats["ball"] = {"base_color": [0.5, 0.5, 0.5], "metallic": 1, "roughness": 0.3}
    return write(folder, name, {
        "camera": {"perspective": {"position": [0, 1.5, 1.5], "look_at": [0.7, 1.2, 0.4]}, "resolution": [8, 8]},
        "environment": {"path": str(black)}, "materials": mats, "objects": objs,
        "reflection_probes": [{"position": [0.7, 1.2, 0.4], "min": [-2, 0, -2], "max": [2, 3, 2], "size": 16,
                               "samples": 4, "bounces": 1, **probe}],
        "effects": {"diffuse": "off", "specular": "prefiltered"}})


def wall_seen(p, d):
    """Which wall the ray p + t d meets first in the room, and how far from that wall's edges."""
    lo, hi = np.array([-2.0, 0.0, -2.0]), np.array([2.0, 3.0, 2.0])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d > 0, (hi - p) / d, (lo - p) / d)
    axis = t.argmin(1)
    tt = t[np.arange(len(d)), axis]
    q = p + tt[:, None] * d
    margin = np.min(np.where(np.eye(3, dtype=bool)[axis], np.inf, np.minimum(q - lo, hi - q)), 1)
    names = np.array([["-x", "+x"], ["-y", "+y"], ["-z", "+z"]])[axis, (d[np.arange(len(d)), axis] > 0).astype(int)]
    return names, margin


@pytest.mark.slow       # make test; make check keeps under 3 minutes
@pytest.mark.parametrize("how", ["exclude", "reflection_captures"])
def test_a_capture_shows_each_wall_where_it_is(tmp_path, rt, how):
    """The probe sits inside the small metal sphere; excluded from the capture (by the probe's
    exclude list, or the object's reflection_captures: false) the sphere lets the capture's first
    rays through: every texel whose rays all meet one wall, away from its edges, holds that wall's
    glow exactly (to float32) and covers its texel. A mirrored or turned capture puts the colours
    on the wrong texels, which this test sees (the walls all differ); so does parallax from the
    probe's off-centre position. Its distance channel (Z) is the wall's distance along the texel's
    centre within 4% (the mean over its four rays; measured 1.2% at 16 rows)."""
    from iblbake.core import conventions
    from iblbake.render.reflection_probes import proxy_distance
    if how == "exclude":
        sc = glowing_room(tmp_path, how, exclude=["ball"])
    else:
        sc = glowing_room(tmp_path, how)
        sc.data["objects"][-1]["reflection_captures"] = False
    warned = []
    bakes = Bakes(tmp_path / "cache")
    render(sc, runtime=rt, cache=bakes, warn=warned.append)
    (image, _cached), = captures(bakes)
    assert not [w for w in warned if "inside" in w]
    size = 16
    v, u = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(2 * size) + 0.5) / (2 * size), indexing="ij")
    d = conventions.dir_from_equirect_uv(u, v).reshape(-1, 3)
    names, margin = wall_seen(np.array([0.7, 1.2, 0.4]), d)
    clear = margin > 0.5                        # the texel's rays meet one wall (a texel spans ~0.4 there)
    got = image.reshape(-1, 8)
    assert clear.sum() > 200 and (got[:, 3] == 1).all() and not got[:, 4:7].any()      # no sky in a closed room
    want = np.array([WALL_COLOURS[n] for n in names])
    assert np.abs(got[clear, :3] - want[clear]).max() < 1e-6
    box = proxy_distance(sc.data["reflection_probes"][0], d)      # the room's walls are the probe's box
    assert np.abs(got[clear, 7] / box[clear] - 1).max() < 0.04


@pytest.mark.slow           # over 3 s on the 2-core CPU: make test, not make check
def test_a_probe_inside_an_object_says_so(tmp_path, rt):
    """The same probe without the exclude list captures the sphere's inside all around: render
    says in one line that its position lies inside the named object and how to fix it."""
    warned = []
    render(glowing_room(tmp_path, "inside"), runtime=rt, cache_root=tmp_path / "cache", warn=warned.append)
    said = [w for w in warned if "lies inside" in w]
    assert len(said) == 1 and "'ball' (objects.6)" in said[0] and "exclude" in said[0] and "\n" not in said[0]


@pytest.mark.slow           # over 3 s on the 2-core CPU: make test, not make check
def test_a_capture_is_the_same_however_its_launches_split(tmp_path, rt, monkeypatch):
    """The launch policy (device/launch.py) splits a capture into whole texels per launch; random
    streams are numbered by ray, not launch, so a capture of paths of three bounces split into 128
    launches equals the one in a single launch, bit for bit."""
    from iblbake.device import launch

    scene = glowing_room(tmp_path, "split", position=[-0.5, 1.0, -0.6], bounces=3)
    got = []
    for items in (1 << 16, 64):
        monkeypatch.setattr(launch, "per_launch", lambda rt, items=items: items)
        bakes = Bakes(tmp_path / f"cache{items}")
        render(scene, runtime=rt, cache=bakes)
        got.append(captures(bakes)[0][0])
    assert got[0].shape == (16, 32, 8) and got[0][..., :3].max() > 0.1
    assert np.array_equal(got[0], got[1])


def window_room(folder, panorama, rotation):
    """A closed room [-2, 2] x [0, 3] x [-2, 2] of zero-thickness quads (an OBJ, double-sided), lit
    through a window (z in [-0.9, 0.9], y in [1, 2.2]) in its -x wall; a rough gold sphere (0.35) and
    a white one on the floor, a reflection probe at the gold sphere's centre excluding it, the
    camera in front of it (its -x half, which faces the window, on the left)."""
    quads = [[(-2, 0, -2), (2, 0, -2), (2, 0, 2), (-2, 0, 2)], [(-2, 3, -2), (-2, 3, 2), (2, 3, 2), (2, 3, -2)],
             [(2, 0, -2), (2, 3, -2), (2, 3, 2), (2, 0, 2)], [(-2, 0, 2), (2, 0, 2), (2, 3, 2), (-2, 3, 2)],
             [(-2, 0, -2), (-2, 3, -2), (2, 3, -2), (2, 0, -2)],
             [(-2, 0, -2), (-2, 0, 2), (-2, 1, 2), (-2, 1, -2)], [(-2, 2.2, -2), (-2, 2.2, 2), (-2, 3, 2), (-2, 3, -2)],
             [(-2, 1, -2), (-2, 1, -0.9), (-2, 2.2, -0.9), (-2, 2.2, -2)],
             [(-2, 1, 0.9), (-2, 1, 2), (-2, 2.2, 2), (-2, 2.2, 0.9)]]
    obj = Path(folder) / "room.obj"
    obj.write_text("".join(f"v {x} {y} {z}\n" for q in quads for x, y, z in q)
                   + "".join(f"f {4 * k + 1} {4 * k + 2} {4 * k + 3} {4 * k + 4}\n" for k in range(len(quads))))
    return {"camera": {"perspective": {"position": [0.2, 1.3, 1.8], "look_at": [-0.4, 0.5, -0.6], "fov_y": 35},
                       "resolution": [64, 48]},
            "environment": {"path": str(panorama), "rotation_y": rotation, "background": "hide"},
            "materials": {"gold": {"base_color": [1.0, 0.78, 0.34], "metallic": 1, "roughness": 0.35},
                          "white": {"base_color": [0.8, 0.8, 0.8], "roughness": 0.6},
                          "plaster": {"base_color": [0.8, 0.8, 0.8], "specular": 0}},
            "objects": [{"mesh": {"path": str(obj)}, "material": "plaster", "name": "room"},
                        {"sphere": {"center": [-0.4, 0.5, -0.6], "radius": 0.5}, "material": "gold", "name": "gold"},
                        {"sphere": {"center": [0.9, 0.4, 0.3], "radius": 0.4}, "material": "white", "name": "white"}],
            "probes": {},
            "reflection_probes": [{"position": [-0.4, 0.5, -0.6], "min": [-2, 0, -2], "max": [2, 3, 2],
                                   "exclude": ["gold"], "size": 64, "samples": 64}],
            "effects": {"diffuse": "off", "specular": "prefiltered"}}


REFERENCE = ["effects.specular=reference", "effects.reference.max_samples=512", "effects.reference.target_noise=0"]


def halves_error(scene, reference, rt, bakes, sphere: int, split) -> dict:
    """Each half of sphere number `sphere` (split(points): the first half), whole pixels of it
    only: the error of `scene`'s specular term's mean colour with the reflection probe (the
    channels' absolute differences summed, over the reference's sum, as tests/test_corpus.py's
    gold sphere measures it) against `reference`'s converged one."""
    from scipy.ndimage import binary_erosion

    from iblbake.render import twin as rr

    w, h = scene["camera"]["resolution"]
    ref = render(reference, runtime=rt, cache=bakes).hdr[..., :3]
    got = render(scene, runtime=rt, cache=bakes).hdr[..., :3]
    gb = rr.primary(scene["camera"], pack.scene_arrays(scene))
    on = gb["hit"] & (gb["kind"] == 1) & (gb["index"] == sphere)
    out = {}
    for name, side in (("first", split(gb["pos"])), ("second", ~split(gb["pos"]))):
        m = binary_erosion((on & side).reshape(h, w), np.ones((3, 3), bool))
        a, b = got[m].mean(0), ref[m].mean(0)
        out[name] = float(np.abs(a - b).sum() / b.sum())
    return out


def square_room(folder, panorama):
    """An independent interior (not one the reading was tuned on): a closed room [-2.5, 2.5] x
    [0, 3] x [-2.5, 2.5] of zero-thickness quads wound inwards, a window (y in [0.8, 2.2], z in
    [-1.2, 1.2]) in its +x wall, a rough gold sphere (0.3) by it, a reflection probe at its centre
    excluding it, read in 64 taps; the camera across the room."""
    lo, hi = (-2.5, 0.0, -2.5), (2.5, 3.0, 2.5)
    quads = []
    for axis in range(3):
        other = [i for i in range(3) if i != axis]
        for side in (0, 1):
            rect = [((lo[other[0]], hi[other[0]]), (lo[other[1]], hi[other[1]]))]
            if (axis, side) == (0, 1):          # the window: four pieces of wall around it
                (a0, a1), (b0, b1) = rect[0]
                rect = [((a0, 0.8), (b0, b1)), ((2.2, a1), (b0, b1)), ((0.8, 2.2), (b0, -1.2)),
                        ((0.8, 2.2), (1.2, b1))]
            for (a0, a1), (b0, b1) in rect:
                q = []
                for a, b in ((a0, b0), (a1, b0), (a1, b1), (a0, b1)):
                    v = [0.0] * 3
                    v[axis], v[other[0]], v[other[1]] = (lo, hi)[side][axis], a, b
                    q.append(v)
                quads.append(q if side == 1 else q[::-1])
    obj = Path(folder) / "square.obj"
    obj.write_text("".join(f"v {x} {y} {z}\n" for q in quads for x, y, z in q)
                   + "".join(f"f {4 * k + 1} {4 * k + 2} {4 * k + 3} {4 * k + 4}\n" for k in range(len(quads))))
    return {"camera": {"perspective": {"position": [-0.5, 1.5, 1.5], "look_at": [1.7, 0.5, 0.2], "fov_y": 50},
                       "resolution": [64, 48]},
            "environment": {"path": str(panorama), "intensity": 2, "background": "hide"},
            "materials": {"gold": {"base_color": [1.0, 0.78, 0.34], "metallic": 1, "roughness": 0.3},
                          "plaster": {"base_color": [0.75, 0.75, 0.72], "specular": 0}},
            "objects": [{"mesh": {"path": str(obj)}, "material": "plaster", "name": "room"},
                        {"sphere": {"center": [1.7, 0.5, 0.2], "radius": 0.5}, "material": "gold", "name": "gold"}],
            "probes": {},
            "reflection_probes": [{"position": [1.7, 0.5, 0.2], "min": list(lo), "max": list(hi),
                                   "exclude": ["gold"], "size": 64, "samples": 64, "taps": 64}],
            "effects": {"diffuse": "off", "specular": "prefiltered"}}


def sides_error(scene, reference, rt, bakes, sphere: int, centre) -> dict:
    """Each half of sphere number `sphere` by the side it faces ('+x', '-y', ...: metrics.halves,
    whole pixels, 10 or more), as halves_error measures it."""
    from scipy.ndimage import binary_erosion

    from iblbake.core import metrics
    from iblbake.render import twin as rr

    w, h = scene["camera"]["resolution"]
    ref = render(reference, runtime=rt, cache=bakes).hdr[..., :3]
    got = render(scene, runtime=rt, cache=bakes).hdr[..., :3]
    gb = rr.primary(scene["camera"], pack.scene_arrays(scene))
    on = binary_erosion((gb["hit"] & (gb["kind"] == 1) & (gb["index"] == sphere)).reshape(h, w), np.ones((3, 3), bool))
    normals = (gb["pos"] - np.asarray(centre)).reshape(h, w, 3)
    return {side: float(np.abs(got[m].mean(0) - ref[m].mean(0)).sum() / ref[m].mean(0).sum())
            for side, m in metrics.halves(normals, on, 10).items()}


@pytest.mark.slow
def test_a_frame_reads_its_own_probe_settings_where_another_shares_the_capture(tmp_path, rt, panoramas):
    """Two frames of one room through one store, the probe's taps (or its blend) changed between
    them: their captures' chains are the same content, and before the second frame read the
    first's probe settings from the device memo (the same picture); now each its own, as a fresh
    store renders it."""
    doc = square_room(tmp_path, panoramas["studio"])
    doc["camera"]["resolution"] = [16, 12]
    doc["objects"][0]["material"] = "gold"          # every pixel reads the probe
    doc["reflection_probes"][0].update(size=16, samples=4, taps=0)
    shared = Bakes(tmp_path / "shared")
    first = render(load_scene(tmp_path, "a", doc), runtime=rt, cache=shared).hdr
    doc["reflection_probes"][0]["taps"] = 16
    second = render(load_scene(tmp_path, "b", doc), runtime=rt, cache=shared).hdr
    fresh = render(load_scene(tmp_path, "c", doc), runtime=rt, cache=Bakes(tmp_path / "fresh")).hdr
    assert np.abs(second - first).max() > 0.01 and np.array_equal(second, fresh)


def test_a_reading_option_rereads_the_capture_and_never_retraces_it(tmp_path, rt, panoramas):
    """A new user's trial: `taps` (a reading option) was in the capture's key, so changing it traced
    the capture again. Two frames of one room differing in their reading alone (taps 0 -> 16,
    grazing_taps, blend, the box): the second traces nothing, in the same store (its memo) or a
    new one over the same cache (its entry: one capture on disk), and is what a fresh cache renders
    of it, the frames apart as the taps and box say; a capture setting (samples) still traces."""
    doc = square_room(tmp_path, panoramas["studio"])
    doc["camera"]["resolution"] = [16, 12]
    doc["objects"][0]["material"] = "gold"          # every pixel reads the probe
    doc["reflection_probes"][0].update(size=16, samples=4, taps=0)

    def frame(name, bakes):
        f = render(load_scene(tmp_path, name, doc), runtime=rt, cache=bakes)
        row = next(b for b in f.report["bakes"] if b["name"] == "reflection_probes")
        return f.hdr, row["rays_traced"]
    shared = Bakes(tmp_path / "shared")
    first, traced = frame("a", shared)
    assert traced == 2 * 16 ** 2 * 4
    doc["reflection_probes"][0].update(taps=16, grazing_taps=4, blend=0.2, max=[2.5, 2.8, 2.5])
    second, again = frame("b", shared)
    later, from_disk = frame("c", Bakes(tmp_path / "shared"))
    fresh, _ = frame("d", Bakes(tmp_path / "fresh"))
    assert again == 0 and from_disk == 0 and len(list((tmp_path / "shared").glob("reflection-*"))) == 1
    assert np.abs(second - first).max() > 0.01 and np.array_equal(second, fresh) and np.array_equal(later, fresh)
    doc["reflection_probes"][0]["samples"] = 2
    assert frame("e", shared)[1] == 2 * 16 ** 2 * 2


@pytest.mark.slow           # over a minute on the 2-core CPU: make test, not make check
def test_a_probe_at_a_sphere_by_the_window_of_an_independent_room_holds_every_side(tmp_path, rt, panoramas):
    """The square room (square_room) under the studio: every side of the gold sphere within 10%
    of the reference at 512 samples a pixel with 64 taps (measured: 0.9-4.4%; 0.4-3.1% with 16;
    one read a lobe, the split sum's lobe about r taking in the studio's key lights below the
    surface and beside the window: 61-74% off on three sides)."""
    sc = load_scene(tmp_path, "square", square_room(tmp_path, panoramas["studio"]))
    err = sides_error(sc, load.load(sc.source, REFERENCE), rt, Bakes(tmp_path / "cache"), 0, [1.7, 0.5, 0.2])
    assert len(err) >= 5 and max(err.values()) < 0.10, err


@pytest.mark.slow           # over a minute on the 2-core CPU: make test, not make check
@pytest.mark.parametrize("panorama, rotation, bound", [("city", 0, 0.10), ("studio", 180, 0.30)])
def test_a_probe_at_a_sphere_in_a_window_room_sees_the_sky_through_the_window(tmp_path, rt, panoramas, panorama,
                                                                               rotation, bound):
    """The issue's window room (zero-thickness quads, a window in one wall) with a rough gold sphere
    at the reflection probe: the sky through the window is the capture's own (its escaping rays'),
    read along the reflected ray, not the distant chain's lobe over the whole panorama, nor a sky
    pinned on the probe's box. The half of the sphere facing the window, against the reference at
    512 samples a pixel: 3.9% off under city (the distant chain filling the capture's uncovered
    share, before: 23.2%), 14.4% under the studio turned 180 degrees (its key lights outside the
    window; before: 218%); the other half 0.3% and 1.1%."""
    sc = load_scene(tmp_path, "room", window_room(tmp_path, panoramas[panorama], rotation))
    err = halves_error(sc, load.load(sc.source, REFERENCE), rt, Bakes(tmp_path / "cache"), 0,
                       lambda p: p[:, 0] < -0.4)
    assert err["first"] < bound and err["second"] < 0.03, err


@pytest.mark.slow           # over a minute on the 2-core CPU: make test, not make check
def test_a_probe_at_a_resting_sphere_sees_the_floor_it_lights(tmp_path, rt, panoramas):
    """The issue's rough gold sphere resting on a floor (examples/corpus/resting.yaml, roughness
    0.35, city), a reflection probe at its centre excluding it: its lower half mirrors the floor
    close by, which the capture sees from a metre off; read at the level the lobe's footprint on
    the floor spans from the probe (Lagarde and Zanuttini's distance-based roughness), the lower
    half is 2.0% off against the reference at 512 samples a pixel (the capture read at the lobe's
    own level, before: 11.2%, where the reference at bounces: 2 lands); the upper half 1.6%."""
    path = Path(__file__).resolve().parents[1] / "examples" / "corpus" / "resting.yaml"
    sets = [f"environment.path={panoramas['city']}", "camera.resolution=[64,64]", "environment.background=hide",
            "materials.gold.roughness=0.35", "effects.diffuse=off"]
    err = halves_error(load.load(path, sets), load.load(path, sets + REFERENCE), rt, Bakes(tmp_path / "cache"), 0,
                       lambda p: p[:, 1] < 1.0)
    assert err["first"] < 0.05 and err["second"] < 0.05, err


@pytest.mark.slow
def test_a_room_whose_specular_mirrors_the_distant_sky_says_so(tmp_path, rt, panoramas):
    """Inside a room (98% of 256 directions from the camera meet its walls; the window the rest)
    a specular term that reads the distant panorama alone mirrors the sky, not the room: the frame
    says so, naming the share and the remedy. Not with the reflection probe read, nor in the open
    (the resting sphere's floor: 5%), nor where no material has a specular lobe."""
    from iblbake.render import enclosure

    doc = window_room(tmp_path, panoramas["city"], 0)
    doc["camera"]["resolution"] = [8, 6]
    warned = []
    render(load_scene(tmp_path, "bare", {**doc, "reflection_probes": []}), runtime=rt, cache=Bakes(tmp_path / "c"),
           warn=warned.append)
    said = [w for w in warned if "reflects the distant panorama" in w]
    assert len(said) == 1 and "98% of the directions" in said[0] and "reflection_probes:" in said[0], warned

    def note(sc):
        return enclosure.warnings(sc, plan(sc).effects, pack.scene_arrays(sc))

    probed = load_scene(tmp_path, "probed", doc)
    assert note(probed) == []
    off = note(load.load(probed.source, ["effects.reflection_probes=false"]))
    assert len(off) == 1 and "its reflection probes are not read here" in off[0] and "add a" not in off[0], off
    assert note(load.load(probed.source, ["effects.specular=reference"])) == []
    matte = {**doc, "reflection_probes": [], "materials": {k: {**m, "metallic": 0, "specular": 0}
                                                            for k, m in doc["materials"].items()}}
    assert note(load_scene(tmp_path, "matte", matte)) == []
    resting = Path(__file__).resolve().parents[1] / "examples" / "corpus" / "resting.yaml"
    assert note(load.load(resting, ["effects.reflection_probes=false"])) == []


def test_the_lobe_is_read_in_taps_above_the_surface_each_through_what_the_point_sees():
    """A rough floor (n = +y, roughness 0.6) seen at a grazing angle under a key light below its
    horizon (1000 where y < -0.3, 1 elsewhere), a capture that saw no scene, only that panorama:
    the split sum's lobe about r reached below the surface and took the key light in (115 times the
    sky's 1 before); 64 taps over the true lobe's visible normals stop at the surface (1.92 over 256
    turns of the set: each tap's filter, its share of the lobe, kept within a twentieth of NoL in
    alpha; 2.19 at a tenth, which the lobe's normal distribution's taps held at 1.89, having fewer
    near the horizon; 1.91 with 16 or 32 taps, on this chain of five levels). A point that sees the
    sky through a window (coverage 1 but for x > 0.7 from the probe) along some of its taps and a
    black wall along the others gets the window's sky along the open taps only: their weighted
    share, 0.605 with 256 taps (0.619 with 16; before: 1.0, the capture's whole sky along r)."""
    from iblbake.bake.prefilter import prefilter_bruteforce
    from iblbake.core import conventions
    from iblbake.render.twin import reflection_probes as rpt

    dirs = conventions.equirect_texel_dirs(16, 8)
    key = np.repeat(np.where(dirs[..., 1:2] < -0.3, 1000.0, 1.0), 3, -1)
    chain = [prefilter_bruteforce(key, dirs, k / 4) for k in range(5)]
    box = {"shape": "box", "position": [0, 0, 0], "min": [-2, -2, -2], "max": [2, 2, 2], "blend": 0.1,
           "parallax": True, "taps": 64}
    zero = [np.zeros((8, 16, 3))] * 5
    n, v = np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, 0.15, -1.0]]) / np.hypot(0.15, 1.0)
    r = 2 * (n * v).sum(1, keepdims=True) * n - v
    p = np.array([[0.0, -0.5, 0.0]])
    split_sum = rpt.radiance.chain_lookup_twin(chain, r, 4 * 0.6)[0, 0]
    got, _ = turned([{"settings": box, "levels": zero, "coverage": zero, "sky": chain}], p, r, 4 * 0.6,
                    (chain, 0.0, 1.0), n, v)
    assert split_sum > 100 and abs(got - 1.0) < 1.0, (split_sum, got)

    wall = [np.repeat(1.0 - (dirs[..., 0:1] > 0.7), 3, -1)] * 5
    n = v = np.array([[1.0, 0.0, 0.0]])
    p = np.array([[0.0, 0.0, -0.6]])
    ones = [np.ones((8, 16, 3))] * 5
    window = [1.0 - c for c in wall]            # the sky the capture saw: 1 through the window
    box["taps"] = 16
    got, _ = turned([{"settings": box, "levels": zero, "coverage": wall, "sky": window}], p, n, 4 * 0.6,
                    (ones, 0.0, 1.0), n, v)
    assert got == pytest.approx(0.605, abs=0.05), got


def test_an_opening_the_point_sees_is_filled_with_the_sky_through_it_not_the_distant_lobe():
    """A probe at the origin of a box room [-2, 2]^3 whose capture sees the sky (radiance 1) through
    a window of the +x wall (the texels whose direction has x > 0.7; every level the same image);
    the distant chain's lobe about r holds a key light (50) that the wall hides. A point 0.6 off the
    probe sees more of the window about r than the probe does (open 1.0 against 0.63): the share
    only it sees is the window's sky, so its reflection stays under the sky's 1 (before: the
    distant chain's 50 filled it, 10x too bright: quad_room's gold sphere under studio, x1.25 on
    its window half). A point whose opening shifts by more than twice the lobe's width (a probe
    across the room, a narrow lobe) keeps the distant chain there: the probe's view says nothing
    of the sky it sees."""
    from iblbake.bake import radiance
    from iblbake.core import conventions
    from iblbake.render.twin import reflection_probes as rpt

    j, i = np.meshgrid(np.arange(8), np.arange(16), indexing="ij")
    window = (conventions.dir_from_equirect_uv((i + 0.5) / 16, (j + 0.5) / 8)[..., 0] > 0.7)[..., None]
    cov, sky = np.repeat(1.0 - window, 3, -1), np.repeat(1.0 * window, 3, -1)
    c = {"settings": {"shape": "box", "position": [0, 0, 0], "min": [-2, -2, -2], "max": [2, 2, 2], "blend": 0.1,
                      "parallax": True}, "levels": [np.zeros_like(cov)] * 5, "coverage": [cov] * 5, "sky": [sky] * 5}
    r = np.array([[1.0, 0.0, 0.9]]) / np.hypot(1.0, 0.9)
    for pz, rough, fill_radiance in ((-0.6, 0.6, 1.0), (-1.0, 0.2, 50.0)):
        p = np.array([[0.0, 0.0, pz]])
        x = rpt.exit_point(c["settings"], p, r)
        seen = 1 - radiance.chain_lookup_twin(c["coverage"], r, 4 * rough)[0, 0]
        opened = 1 - radiance.chain_lookup_twin(c["coverage"], x / np.linalg.norm(x), 4 * rough)[0, 0]
        off = np.clip((np.linalg.norm(p) / np.linalg.norm(x) - rpt.NEAR) / (rpt.FAR - rpt.NEAR), 0, 1)
        got = rpt.blend([c], p, r, 4 * rough, np.full((1, 3), 50.0), None, None)[0, 0]
        assert opened - seen > 0.3 and seen > 0.5 and off > 0.5, (opened, seen, off)
        assert got == pytest.approx(seen + off * (opened - seen) * fill_radiance, rel=1e-9), (pz, got)


@pytest.mark.slow           # over a minute on the 2-core CPU: make test, not make check
@pytest.mark.parametrize("panorama, rotation", [("studio", 90), ("city", 200)])
def test_taps_hold_a_resting_sphere_in_a_room_they_were_not_tuned_on(tmp_path, rt, panoramas, panorama, rotation):
    """The square room (square_room) changed into one the taps were not measured on while they
    were built: a smaller gold sphere (0.35, roughness 0.25) resting on the floor in a corner away
    from the window, the probe at its centre excluding it, the panorama turned, the camera at the
    window. Every side within 10% of the reference at 512 samples a pixel with 64 taps."""
    doc = square_room(tmp_path, panoramas[panorama])
    centre = [-1.4, 0.35, -1.3]
    doc["environment"]["rotation_y"] = rotation
    doc["materials"]["gold"]["roughness"] = 0.25
    doc["objects"][1]["sphere"] = {"center": centre, "radius": 0.35}
    doc["reflection_probes"][0]["position"] = centre
    doc["camera"]["perspective"] = {"position": [1.8, 1.4, 0.4], "look_at": centre, "fov_y": 30}
    sc = load_scene(tmp_path, "corner", doc)
    err = sides_error(sc, load.load(sc.source, REFERENCE), rt, Bakes(tmp_path / "cache"), 0, centre)
    assert len(err) >= 4 and max(err.values()) < 0.10, err


@pytest.mark.slow           # over a minute on the 2-core CPU: make test, not make check
def test_the_default_reading_holds_a_rough_sphere_facing_a_sunlit_window_of_a_room_not_tuned_on(tmp_path, rt,
                                                                                                  panoramas):
    """The square room (square_room) under city, a rough gold sphere (0.4, radius 0.4) a metre from
    its window at a probe at its defaults (`grazing_taps: 64`; size 128, 256 samples), the camera
    across the room: every side within 12% of the reference at 512 samples a pixel (measured
    1.9-10.4%; 1.9-11.0% with 32 taps from the normal distribution, 2.7-10.1% with 16). The grazing
    count was raised from 16 for a trial's window room under city, a like sphere facing its sunlit
    window: x1.17 on that half with 16 taps, within 6% with 32; to 64 over the visible normals for
    another's under forest, 15% with 32 (docs/conventions.md "Grazing")."""
    doc = square_room(tmp_path, panoramas["city"])
    centre = [1.2, 1.0, -0.5]
    doc["materials"]["gold"]["roughness"] = 0.4
    doc["objects"][1]["sphere"] = {"center": centre, "radius": 0.4}
    probe = doc["reflection_probes"][0]
    del probe["taps"]
    probe.update(position=centre, size=128, samples=256)
    doc["camera"]["perspective"] = {"position": [-1.5, 1.6, 1.2], "look_at": centre, "fov_y": 40}
    sc = load_scene(tmp_path, "facing", doc)
    assert sc["reflection_probes"][0]["grazing_taps"] == 64
    err = sides_error(sc, load.load(sc.source, REFERENCE), rt, Bakes(tmp_path / "cache"), 0, centre)
    assert len(err) >= 5 and max(err.values()) < 0.12, err


def key_light_sky(degrees, value, levels, w=64, h=32):
    """(key, panorama, its chain, a black chain): a panorama of 1 with a key light of `value` (a disk
    `degrees` wide about key) at w x h, prefiltered by brute force at `levels` roughnesses."""
    from iblbake.bake.prefilter import prefilter_bruteforce
    from iblbake.core import conventions

    dirs = conventions.equirect_texel_dirs(w, h)
    key = np.array([0.0, 0.6, 0.8])
    img = np.ones((h, w, 3))
    img[dirs @ key > np.cos(np.radians(degrees))] = value
    chain = [prefilter_bruteforce(img, dirs, k / (levels - 1), max_sub=1) for k in range(levels)]
    return key, img, chain, [np.zeros((h, w, 3))] * levels


def lobe_truth(img, n, v, alpha):
    """The exact integral of the GGX lobe (normal n, view v; no Fresnel) over the panorama's
    texels, normalised by the lobe's own (red channel): what a probe's reading should give."""
    from iblbake.core import brdf, conventions

    h, w = img.shape[:2]
    flat = conventions.equirect_texel_dirs(w, h).reshape(-1, 3)
    omega = conventions.equirect_solid_angles(w, h).reshape(-1)
    half = flat + v
    half /= np.linalg.norm(half, axis=1, keepdims=True)
    nol = np.clip(flat @ n, 0.0, 1.0)
    f = brdf.d_ggx(half @ n, alpha) * brdf.v_smith_ggx_correlated(float(v @ n), nol, alpha) * nol * omega
    return (f * img.reshape(-1, 3)[:, 0]).sum() / f.sum()


@pytest.mark.slow
def test_taps_do_not_alias_on_a_compact_key_light():
    """A capture that saw no scene, only a panorama of 1 with a key light of 500 (a 10-degree disk),
    a surface (roughness 0.5) facing that light, seen from 30 degrees off its normal as the view
    turns about it in steps of 10 degrees: 64 taps against the exact integral of the same lobe over
    the panorama's texels within 20% at every turn (measured -13.6% to +4.7%). Taps read at a fixed
    share of the lobe's level (before) met the light or missed it as the turn moved the taps across
    it: -32% to +19%."""
    from iblbake.core import conventions
    from iblbake.render.twin import reflection_probes as rpt

    levels, rough = 5, 0.5
    key, img, chain, zero = key_light_sky(10, 500.0, levels)
    box = {"shape": "box", "position": [0, 0, 0], "min": [-2, -2, -2], "max": [2, 2, 2], "blend": 0.1,
           "parallax": True, "taps": 64}
    n = key[None]
    t, b = conventions.tangent_frame(n)
    errors = []
    for phi in np.radians(np.arange(0, 360, 10)):
        v = np.cos(np.radians(30)) * n + np.sin(np.radians(30)) * (np.cos(phi) * t + np.sin(phi) * b)
        r = 2 * (n * v).sum(1, keepdims=True) * n - v
        got = rpt.blend([{"settings": box, "levels": zero, "coverage": zero, "sky": chain}], np.zeros((1, 3)), r,
                        rough * (levels - 1), np.zeros((1, 3)), (chain, 0.0, 1.0), (n, v))[0, 0]
        errors.append(got / lobe_truth(img, key, v[0], rough ** 2) - 1)
    assert max(np.abs(errors)) < 0.20, errors


def test_the_default_reading_holds_a_lobe_seen_edge_on(tmp_path, sky):
    """A capture that saw no scene, only a panorama of 1 with a key light of 20 (a 30-degree disk),
    read by a probe at its defaults (load's: `grazing_taps`) on a rough surface (0.35) seen edge-on
    (NoV 0.21), the views about the normal averaged (a silhouette's pixels), the normal turned from
    the light to away from it: within 12% of the exact integral of the true lobe on every turn
    (measured -5% to +8%). The split sum's one read along the dominant direction, the old default,
    is 34% off where the normal looks away from the light (its lobe about r reaches below the
    horizon into the light): the split sum's own error at grazing, the distant panorama alone."""
    from iblbake.core import conventions
    from iblbake.core.bases.common import lobe_axis
    from iblbake.render.twin import reflection_probes as rpt

    levels, rough = 5, 0.35
    key, img, chain, zero = key_light_sky(30, 20.0, levels)
    defaults = window(tmp_path, sky, [{"position": [0, 0, -1], "min": [-2, -2, -2], "max": [2, 2, 2]}])
    box = {**defaults["reflection_probes"][0], "position": [0, 0, 0]}
    alpha = rough ** 2
    nov = np.cos(np.radians(78))

    def ring(tilt, settings):
        """The reading and the truth summed over 24 views at NoV about a normal `tilt` off +y."""
        n = np.array([[np.sin(np.radians(tilt)), np.cos(np.radians(tilt)), 0.0]])
        t, b = conventions.tangent_frame(n)
        phi = np.radians(np.arange(0, 360, 15))[:, None]
        v = nov * n + np.sqrt(1 - nov * nov) * (np.cos(phi) * t + np.sin(phi) * b)
        nn = np.repeat(n, len(v), 0)
        r = lobe_axis(nn, v, np.full(len(v), alpha))          # the split sum's dominant direction
        got = rpt.blend([{"settings": settings, "levels": zero, "coverage": zero, "sky": chain}], np.zeros_like(v), r,
                        rough * (levels - 1), np.zeros_like(v), (chain, 0.0, 1.0), (nn, v))[:, 0]
        return got.sum() / sum(lobe_truth(img, n[0], vk, alpha) for vk in v) - 1

    tilts = (0, 45, 90, 135, 180)
    errors = [ring(tilt, box) for tilt in tilts]
    one = [ring(tilt, {**box, "taps": 0, "grazing_taps": 0}) for tilt in tilts]
    assert max(np.abs(errors)) < 0.12 and max(np.abs(one)) > 0.25, (errors, one)


def test_taps_read_the_lit_floor_beside_an_excluded_cube_without_its_black_footprint():
    """A probe at the centre of a cube it excludes (metal_box's): its capture sees the floor 0.35
    below through the cube, black under it (directions steeper than 45 degrees down: the cube's
    footprint) and lit (1) beside it. The cube's -x face (roughness 0.3) reflects the floor
    beside it: 64 taps read each where its ray leaves the box, at the tap's own level (0.94; the
    taps near the cube's base meet the footprint's filtered edge); floored at the capture's level
    2 (before) the footprint bled into it (0.84: metal_box under city, the -x face x0.88 against
    the converged reference, x0.93 now)."""
    from iblbake.bake.prefilter import prefilter_bruteforce
    from iblbake.core import conventions
    from iblbake.render.twin import reflection_probes as rpt

    dirs = conventions.equirect_texel_dirs(32, 16)
    floor = np.repeat(((dirs[..., 1:2] < 0) & (dirs[..., 1:2] > -np.sqrt(0.5))) * 1.0, 3, -1)
    chain = [prefilter_bruteforce(floor, dirs, k / 4) for k in range(5)]
    cover = [np.repeat((dirs[..., 1:2] < 0) * 1.0, 3, -1)] * 5
    box = {"shape": "box", "position": [0, 0, 0], "min": [-1, -0.35, -1], "max": [1, 1.65, 1], "blend": 0.1,
           "parallax": True, "taps": 64}
    n = np.array([[-1.0, 0.0, 0.0]])
    v = np.array([[-0.6, 0.6, 0.0]]) / np.hypot(0.6, 0.6)       # the camera above: r points down, outwards
    r = 2 * (n * v).sum(1, keepdims=True) * n - v
    p = np.array([[-0.35, -0.2, 0.0]])
    sky = [np.zeros((16, 32, 3))] * 5
    got = rpt.blend([{"settings": box, "levels": chain, "coverage": cover, "sky": sky}], p, r, 4 * 0.3,
                    np.zeros((1, 3)), (sky, 0.0, 1.0), (n, v))[0]
    assert np.all(np.abs(got - 1.0) < 0.1), got



def lobe_samples(n, v, alpha, m=65536):
    """(directions, weights) of m Hammersley samples of the GGX lobe about normal n for view v
    (each (1, 3)): each weight the BRDF over its pdf without Fresnel (V 4 NoL VoH / NoH, 0 below
    the surface), so that (weights L(directions)).sum() / weights.sum() is the lobe's integral."""
    from iblbake.core import brdf, conventions, sampling

    nn, vv = np.repeat(n, m, 0), np.repeat(v, m, 0)
    t, b = conventions.tangent_frame(nn)
    hl = sampling.sample_ggx_half(sampling.hammersley(m), alpha)
    hv = t * hl[:, :1] + b * hl[:, 1:2] + nn * hl[:, 2:]
    voh = (vv * hv).sum(1)
    ll = 2 * voh[:, None] * hv - vv
    nol = (nn * ll).sum(1)
    wt = np.where((nol > 0) & (voh > 0), brdf.v_smith_ggx_correlated(np.full(m, float((n * v).sum())), nol, alpha)
                  * 4 * nol * voh / np.maximum(hl[:, 2], 1e-7), 0.0)
    return ll, wt


def texel_red(img, ll):
    """The red channel of the equirect image's texel each direction falls in (nearest)."""
    from iblbake.core import conventions

    h, w = img.shape[:2]
    lu, lv = conventions.equirect_uv_from_dir(ll)
    return img[np.minimum((lv * h).astype(int), h - 1), np.minimum((lu * w).astype(int), w - 1), 0]


def first_levels(img, dirs):
    """A 5-level chain of img whose levels 0-2 are it and its prefilters at roughness 0.25 and 0.5
    (brute force; what a lobe of roughness up to 0.5 and its taps read), the rest level 2's."""
    from iblbake.bake.prefilter import prefilter_bruteforce

    out = [img] + [prefilter_bruteforce(img, dirs, r, max_sub=1) for r in (0.25, 0.5)]
    return out + [out[-1]] * 2


def turned(captured, p, r, lod, env, n, v, turns=256):
    """What a region of `turns` pixels at one point reads of captured (blend): each pixel's taps
    turned about n by its G-buffer sample's own angle (0 .. turns - 1, rprobe_tap_turn), their mean
    (and their spread: one pixel's read)."""
    from iblbake.render.twin import reflection_probes as rpt

    got = rpt.blend(captured, np.repeat(p, turns, 0), np.repeat(r, turns, 0), lod, np.zeros((turns, 3)), env,
                    (np.repeat(n, turns, 0), np.repeat(v, turns, 0), np.arange(turns)))[:, 0]
    return got.mean(), got.std()


def test_taps_fill_an_opening_only_the_point_sees_with_the_panorama_about_the_tap():
    """A probe at the centre of a box [-1, 1]^3 of black walls open on its +z side (32 x 64
    texels), the panorama 0.1 but one texel of 50 (a compact lamp) 40 degrees from +z towards +x,
    inside the opening's edge as the probe sees it (45 degrees). A point at (0, 0, 0.6), nearer the
    opening, roughness 0.3, its mirror direction 50 degrees from +z (past the probe's edge): its
    taps see more of the opening than the probe saw about them. 64 taps read 1.30x the lobe's own
    integral through the opening as the point sees it (65,536 directions, exact) over 256 turns of
    the set (1.32x with 32 taps, 1.36x with 16; one pixel's spread 4%, 12%, 36%; the lobe's normal
    distribution's one set of 64 read 1.21x, 1.29x in 256 taps: the filtered taps' own bias); the
    probe's sky over its open share alone (before) spread the lamp it saw in a sliver of the
    opening over all the point sees of it: 2.20x (metal_box's cube under studio, its face mirroring the box's open
    corner 1.2x in red and blue against the converged reference, 11.4%; 3.0% now)."""
    from iblbake.core import conventions
    from iblbake.render.twin import reflection_probes as rpt

    h, w = 32, 64
    dirs = conventions.equirect_texel_dirs(w, h)
    box = {"shape": "box", "position": [0, 0, 0], "min": [-1, -1, -1], "max": [1, 1, 1], "blend": 0.1,
           "parallax": True, "taps": 64}
    opened = np.repeat(rpt.exit_point(box, np.zeros((h * w, 3)), dirs.reshape(-1, 3)).reshape(h, w, 3)[..., 2:]
                       > 1 - 1e-9, 3, -1) * 1.0
    pano = np.full((h, w, 3), 0.1)
    u, v = conventions.equirect_uv_from_dir(np.array([[np.sin(np.radians(40)), 0.0, np.cos(np.radians(40))]]))
    pano[int(v[0] * h), int(u[0] * w)] = 50.0

    distant = first_levels(pano, dirs)
    c = {"settings": box, "levels": [np.zeros_like(pano)] * 5, "coverage": first_levels(1 - opened, dirs),
         "sky": first_levels(pano * opened, dirs)}
    p = np.array([[0.0, 0.0, 0.6]])
    n = np.array([[np.sin(np.radians(25)), 0.0, np.cos(np.radians(25))]])
    v = np.array([[0.0, 0.0, 1.0]])
    r = 2 * (n * v).sum(1, keepdims=True) * n - v
    got, _ = turned([c], p, r, 4 * 0.3, (distant, 0.0, 1.0), n, v)
    ll, wt = lobe_samples(n, v, 0.09)
    through = rpt.exit_point(box, np.repeat(p, len(ll), 0), ll)[:, 2] > 1 - 1e-9
    truth = (wt * through * texel_red(pano, ll)).sum() / wt.sum()
    assert 0.9 < got / truth < 1.4, (got, truth)


def test_taps_at_grazing_views_do_not_weigh_one_direction_over_the_lobe():
    """A floor (n = +y) at the bottom of a dark box [-1, 1]^3 lit by a skylight overhead (|x|, |z| <
    0.4 of the +y face, the sky 1), a point on it seen at grazing views (NoV 0.06, 0.15, 0.3;
    roughness 0.4) in 32 taps. The lobe leans to the horizon, and little of it meets the skylight
    (0.9-1.4% of the sky). Taps drawn from the lobe's normal distribution weighed V 4 NoL VoH / NoH
    each, 9 or more on those near the normal, whose directions meet the skylight: one set read
    14.3x, 14.0x and 4.8x (a new user's rough gold sphere under city, one silhouette pixel 5x and
    its half 13% off, the specular frame 45%). Over the visible normals (Heitz 2018) each weighs
    G2 / G1, about 1: over 256 turns of the set 1.01x, 0.97x, 0.92x, one pixel's spread 1.05-1.47x
    the truth (a tap is a 32nd of the lobe; the skylight about a hundredth)."""
    from iblbake.core import conventions
    from iblbake.render.twin import reflection_probes as rpt

    h, w = 32, 64
    dirs = conventions.equirect_texel_dirs(w, h)
    box = {"shape": "box", "position": [0, 0, 0], "min": [-1, -1, -1], "max": [1, 1, 1], "blend": 0.1,
           "parallax": True, "taps": 32}

    def skylight(q, ll):
        x = rpt.exit_point(box, q, ll)
        return (x[:, 1] > 1 - 1e-9) & (np.abs(x[:, 0]) < 0.4) & (np.abs(x[:, 2]) < 0.4)
    opened = np.repeat(skylight(np.zeros((h * w, 3)), dirs.reshape(-1, 3)).reshape(h, w, 1), 3, -1) * 1.0
    sky = np.ones((h, w, 3))
    c = {"settings": box, "levels": [np.zeros_like(sky)] * 5, "coverage": first_levels(1 - opened, dirs),
         "sky": first_levels(opened, dirs)}
    p, n = np.array([[0.0, -0.9, 0.0]]), np.array([[0.0, 1.0, 0.0]])
    for nov in (0.06, 0.15, 0.3):
        v = np.array([[np.sqrt(1 - nov * nov), nov, 0.0]])
        r = 2 * (n * v).sum(1, keepdims=True) * n - v
        ll, wt = lobe_samples(n, v, 0.16)
        truth = (wt * skylight(np.repeat(p, len(ll), 0), ll)).sum() / wt.sum()
        got, spread = turned([c], p, r, 4 * 0.4, (first_levels(sky, dirs), 0.0, 1.0), n, v)
        assert abs(got / truth - 1) < 0.12, (nov, got, truth)
        assert spread / truth < 2.0, (nov, spread, truth)


def lamp_inside_a_window_edge():
    """A probe at the centre of a box [-1, 1]^3 sees the sky (0.1) through a window of the +z wall
    (|x|, |y| < 0.5) and a compact lamp (50, one texel of 32 x 64) just inside the window's +x edge;
    a point 0.4 off it along +x, normal and view along (0.25, 0, 1) (roughness 0.5, the lobe
    straddling the edge), sees the window but the lamp behind the wall. (capture without settings,
    box, p, n = v, the panorama's chain, the true lobe's integral: 65536 directions, the window
    traced from the point)."""
    from iblbake.core import conventions
    from iblbake.render.twin import reflection_probes as rpt

    h, w = 32, 64
    dirs = conventions.equirect_texel_dirs(w, h)
    box = {"shape": "box", "position": [0, 0, 0], "min": [-1, -1, -1], "max": [1, 1, 1], "blend": 0.1,
           "parallax": True}

    def window_of(q, ll):
        x = rpt.exit_point(box, q, ll)
        return (x[:, 2] > 1 - 1e-9) & (np.abs(x[:, 0]) < 0.5) & (np.abs(x[:, 1]) < 0.5)
    opened = np.repeat(window_of(np.zeros((h * w, 3)), dirs.reshape(-1, 3)).reshape(h, w, 1), 3, -1) * 1.0
    pano = np.full((h, w, 3), 0.1)
    u, v = conventions.equirect_uv_from_dir(np.array([[0.42, 0.0, 1.0]]) / np.hypot(0.42, 1.0))
    pano[int(v[0] * h), int(u[0] * w)] = 50.0
    lamp = dirs[int(v[0] * h), int(u[0] * w)][None]
    p = np.array([[0.4, 0.0, 0.0]])
    assert window_of(np.zeros((1, 3)), lamp)[0] and not window_of(p, lamp)[0]

    c = {"levels": [np.zeros_like(pano)] * 5, "coverage": first_levels(1 - opened, dirs),
         "sky": first_levels(pano * opened, dirs)}
    n = np.array([[0.25, 0.0, 1.0]]) / np.hypot(0.25, 1.0)
    ll, wt = lobe_samples(n, n, 0.25)
    truth = (wt * window_of(np.repeat(p, len(ll), 0), ll) * texel_red(pano, ll)).sum() / wt.sum()
    return c, box, p, n, first_levels(pano, dirs), truth


def test_taps_keep_a_lamp_the_probe_saw_inside_a_window_edge_out_of_what_the_point_sees():
    """The mirror case (lamp_inside_a_window_edge): the taps hold the true lobe's integral: 16 taps
    1.09x and 64 1.10x over 256 turns of the set (the capture's own level along each tap whose
    footprint the edge crosses; one pixel's spread 24% and 4%); before, the capture's sky filtered
    at the tap's roughness per unit of its open share spread the lamp over the part the point sees
    open: 1.55x and 1.44x in one set (a new user's window room under studio, the gold sphere's +x
    half x1.49 with 64 taps, x1.10 after)."""
    c, box, p, n, pano_chain, truth = lamp_inside_a_window_edge()
    for taps in (16, 64):
        c["settings"] = {**box, "taps": taps}
        got, _ = turned([c], p, n, 4 * 0.5, (pano_chain, 0.0, 1.0), n, n)
        assert abs(got / truth - 1) < 0.15, (taps, got, truth)


def test_the_default_reading_takes_a_lobe_straddling_a_window_edge_in_taps():
    """The same lobe read at the probe's defaults (taps 0, grazing_taps 16), seen head-on (NoV 1: no
    grazing taps): the probe saw part of the lobe open and the point is off it, so the reading is
    the 16 taps' (1.09x the true lobe over 256 turns of the set). One read (before) spread the lamp the probe saw inside the
    edge over all the point sees open: 14x (docs/conventions.md "What the reading misses"). The
    share in taps is a weight, not a threshold: from the probe to the point it rises from 0 with no
    step over 0.15 of an 80th of the way (a step at rprobe_read's `off` > 0: 1)."""
    from iblbake.render.twin import reflection_probes as rpt

    c, box, p, n, pano_chain, truth = lamp_inside_a_window_edge()
    c["settings"] = {**box, "taps": 0, "grazing_taps": 16}
    got, _ = turned([c], p, n, 4 * 0.5, (pano_chain, 0.0, 1.0), n, n)
    assert abs(got / truth - 1) < 0.15, (got, truth)
    share = rpt.straddle(c, np.linspace(0, 1, 81)[:, None] * p, np.repeat(n, 81, 0), np.full(81, 2.0))
    assert share[0] == 0 and share[-1] == 1 and np.abs(np.diff(share)).max() < 0.15, share


def box_probe_distances(st: dict, h: int, w: int, sphere=None):
    """The distance from a probe at st's position to its box (or to `sphere`, (centre, radius),
    where that is met first) at each texel centre of an h x w capture."""
    from iblbake.core import conventions
    from iblbake.render.reflection_probes import proxy_distance

    d = conventions.equirect_texel_dirs(w, h).reshape(-1, 3)
    dist = proxy_distance(st, d)
    if sphere is not None:
        o = np.asarray(st["position"], np.float64) - sphere[0]
        b = d @ o
        disc = b * b - (o @ o - sphere[1] ** 2)
        near = -b - np.sqrt(np.maximum(disc, 0.0))
        dist = np.where((disc > 0) & (near > 0), np.minimum(near, dist), dist)
    return dist.reshape(h, w)


def test_the_march_keeps_the_box_projection_in_a_closed_box():
    """A probe off the centre of a closed box whose distance channel is the box's (each texel 0.4%
    off at random, as a capture's texel means are: 0.06% at the 99th percentile of window_room's
    walls): 20000 rays from random points in the box meet the captured surface exactly where they
    leave the box (the closed form: the march's distance is stored over the box's, 1 on the box
    whatever the direction; read as the distance itself, 14% of the rays stopped up to 0.72 short
    of the wall at the box's edges, at 32 x 64). A probe that sees nothing in front of its proxy
    skips the march (the same point, at no cost)."""
    from iblbake.render.reflection_probes import depth_levels
    from iblbake.render.twin import reflection_probes as rpt

    st = {"shape": "box", "position": [0.3, 0.2, -0.1], "min": [-2, 0, -2], "max": [2, 3, 2], "blend": 0.0,
          "parallax": True}
    rng = np.random.default_rng(1)
    dist = box_probe_distances(st, 32, 64) * (1 + 0.004 * rng.uniform(-1, 1, (32, 64)))
    c = {"settings": st, "depth": depth_levels(dist, st, [(32, 64)])}
    p = rng.uniform([-1.9, 0.1, -1.9], [1.9, 2.9, 1.9], (20000, 3))
    r = rng.normal(size=(20000, 3))
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    x = rpt.exit_point(st, p, r)
    assert np.array_equal(rpt.march(c, p, r, x), x)
    assert not rpt.marches(c)       # so the reads skip it (rp_info's fourth w 0)


def test_a_reflection_meets_an_object_off_the_box_where_it_stands():
    """A probe at the centre of a box room [-2, 2]^3 whose capture (64 x 128) sees a ball (radiance
    1, radius 0.3 at (-0.6, 0, -0.6)) against black walls. A mirror point at (1.2, 0, -0.6) looking
    at the ball's centre (r = -x) sees it: the march meets the ball's front (-0.3, 0, -0.6) to a
    texel (0.041 off: that point is 2.3 degrees inside the ball's edge as the probe sees it, a
    texel 2.8), radiance 1.0; the box projection alone pinned the ball on the wall behind it, (-2, 0,
    -0.6), where the probe sees the black wall beside the ball (0.0: window_room's chrome sphere
    mirroring its clay sphere, x1.21 on that half)."""
    from iblbake.core import conventions
    from iblbake.render.reflection_probes import depth_levels
    from iblbake.render.twin import reflection_probes as rpt

    st = {"shape": "box", "position": [0, 0, 0], "min": [-2, -2, -2], "max": [2, 2, 2], "blend": 0.1,
          "parallax": True}
    ball = (np.array([-0.6, 0.0, -0.6]), 0.3)
    dist = box_probe_distances(st, 64, 128, ball)
    seen = np.repeat((dist < box_probe_distances(st, 64, 128))[..., None] * 1.0, 3, -1)
    ones, zero = [np.ones_like(seen)] * 5, [np.zeros_like(seen)] * 5
    c = {"settings": st, "levels": [seen] * 5, "coverage": ones, "sky": zero,
         "depth": depth_levels(dist, st, [(64, 128)] * 5)}
    p, r = np.array([[1.2, 0.0, -0.6]]), np.array([[-1.0, 0.0, 0.0]])
    assert rpt.hit(c, p, r)[0] == pytest.approx([-0.3, 0.0, -0.6], abs=0.08)
    got = rpt.blend([c], p, r, 0.0, np.zeros((1, 3)), None, None)[0]
    boxed = rpt.blend([{**c, "depth": None}], p, r, 0.0, np.zeros((1, 3)), None, None)[0]
    assert np.all(np.abs(got - 1.0) < 0.02) and np.all(boxed < 0.02), (got, boxed)


def test_an_influence_wholly_outside_the_scene_is_said():
    """A new user's probe box at 19..21 beside a room (bounds about -2..3) bakes, and the chrome
    sphere it was meant for read the distant sky (8x off): said now, naming the key and both
    boxes; a box that meets the bounds (at a face) or a sphere over them is not."""
    from iblbake.render import reflection_probes as rp

    bounds = (np.array([-2.0, 0, -2]), np.array([2.0, 3, 2]))
    away = {"reflection_probes": [{"position": [20, 20, 20], "min": [19, 19, 19], "max": [21, 21, 21]}], "objects": []}
    said = rp.warnings(0, {}, away, bounds)
    assert len(said) == 1 and said[0].startswith("reflection_probes.0: its influence [19.0, 19.0, 19.0]..[21.0, "
                                                 "21.0, 21.0] lies wholly outside the scene's bounds"), said
    touching = {"reflection_probes": [{"position": [2.5, 1, 0], "min": [2, 0, -1], "max": [3, 2, 1]}], "objects": []}
    assert rp.warnings(0, {}, touching, bounds) == []
    sphere = {"reflection_probes": [{"position": [2.5, 1, 0], "shape": "sphere", "radius": 0.6}], "objects": []}
    assert rp.warnings(0, {}, sphere, bounds) == []
    sphere["reflection_probes"][0]["radius"] = 0.4                    # 2.1..2.9 along x: beyond 2
    assert len(rp.warnings(0, {}, sphere, bounds)) == 1
    assert rp.warnings(0, {}, away, None) == []


def two_spheres(folder, name, probes, keep=(0, 1)):
    """A closed 4 x 3 x 4 room lit by a bright square on its -x wall; a gold sphere and a chrome one,
    each with a probe at its centre excluding it (both influences the whole room: they overlap
    everywhere), and a grey metal sphere no probe excludes; `keep` the probes whose influence is the
    room, the others' a sphere of 5 cm inside their own sphere that nothing seen reads (each probe
    keeps its number: its capture's random streams)."""
    walls = [([0, 0, 0], [0, 1, 0]), ([0, 3, 0], [0, -1, 0]), ([-2, 1.5, 0], [1, 0, 0]), ([2, 1.5, 0], [-1, 0, 0]),
             ([0, 1.5, -2], [0, 0, 1]), ([0, 1.5, 2], [0, 0, -1])]
    objs = [{"plane": {"point": p, "normal": nrm, "size": 4}, "material": "wall"} for p, nrm in walls]
    objs.append({"plane": {"point": [-1.98, 1.5, 0], "normal": [1, 0, 0], "size": 1}, "material": "lamp"})
    objs += [{"name": "gold", "sphere": {"center": [-0.6, 0.5, 0], "radius": 0.5}, "material": "gold"},
             {"name": "chrome", "sphere": {"center": [0.7, 0.4, -0.3], "radius": 0.4}, "material": "chrome"},
             {"name": "third", "sphere": {"center": [0.3, 0.3, 0.9], "radius": 0.3}, "material": "grey"}]
    black = Path(folder) / "black.exr"
    if not black.exists():
        images.write_exr(black, np.zeros((8, 16, 3), np.float32))
    every = [{"position": [-0.6, 0.5, 0], "exclude": ["gold"]}, {"position": [0.7, 0.4, -0.3], "exclude": ["chrome"]}]
    return write(folder, name, {
        "camera": {"perspective": {"position": [0, 1.6, 1.9], "look_at": [0, 0.4, 0], "fov_y": 70},
                   "resolution": [40, 30]},
        "environment": {"path": str(black)},
        "materials": {"wall": {"base_color": [0.6, 0.5, 0.4], "roughness": 1, "specular": 0},
                      "lamp": {"base_color": [0, 0, 0], "emissive": [30, 30, 30], "specular": 0},
                      "gold": {"base_color": [1.0, 0.78, 0.34], "metallic": 1, "roughness": 0.3},
                      "chrome": {"base_color": [0.55, 0.56, 0.55], "metallic": 1, "roughness": 0.05},
                      "grey": {"base_color": [0.8, 0.8, 0.8], "metallic": 1, "roughness": 0.2}},
        "objects": objs,
        "reflection_probes": [{**every[k], "size": 32, "samples": 2, "bounces": 1, **probes,
                               **({"min": [-2, 0, -2], "max": [2, 3, 2]} if k in keep else
                                  {"shape": "sphere", "radius": 0.05, "blend": 0})} for k in (0, 1)],
        "effects": {"diffuse": "off", "specular": "prefiltered"}})


@pytest.mark.parametrize("probes", [{}, {"taps": 8}])
def test_an_object_a_probe_excludes_reads_that_probe_alone(tmp_path, rt, probes):
    """Two probes whose influences overlap everywhere, each at a sphere excluding it: each sphere
    reads its own probe alone (its frame equals that with the other probe removed, to float
    rounding), where the blend read half of the other's capture, in which it stands (a new user's
    window room: gold x1.47 on a half); the third sphere, excluded by none, still blends both. The
    frame against the shade pass's twin on its G-buffer, over the lamp's 30 (measured 3.5e-6 one read,
    3.2e-6 in taps: the chrome's sharp lobe on the lamp's edge)."""
    from iblbake.render import twin as rr
    from iblbake.render.lightmaps.read import hit_objects

    bakes = Bakes(tmp_path / "cache")
    sc = two_spheres(tmp_path, "both", probes)
    frame = render(sc, runtime=rt, cache=bakes).hdr[..., :3].reshape(-1, 3)
    alone = [render(two_spheres(tmp_path, f"only{k}", probes, (k,)), runtime=rt, cache=bakes).hdr[..., :3]
             .reshape(-1, 3) for k in (0, 1)]
    arrays = pack.scene_arrays(sc)
    gb = rr.primary(sc["camera"], arrays)
    obj = hit_objects(gb, arrays)
    gold, chrome, third = (obj == 7), (obj == 8), (obj == 9)
    assert gold.sum() > 50 and chrome.sum() > 30 and third.sum() > 20
    for own, mine in ((gold, alone[0]), (chrome, alone[1])):
        assert np.abs(frame[own] - mine[own]).max() / mine[own].max() < 1e-5
    for other in alone:                              # the third sphere reads both probes, 50/50
        assert np.abs(frame[third] - other[third]).max() / frame[third].max() > 0.02
    env_sha = bakes.environment(sc.data["environment"])[1].sha256
    distant = next(v[0] for k, v in bakes.held("prefiltered").items() if k[1] == env_sha)
    captured = bakes.load("reflection_probes", BakeContext(sc, rt, bakes))[0]
    assert [c["excluded"] for c in captured] == [[7], [8]]
    hit = gb["hit"]
    want = rr.shade(gb, arrays, sc["effects"], sc["environment"], prefiltered=distant, dfg=bakes.result("dfg"),
                    reflection_probes=captured)[hit]
    assert np.abs(frame[hit] - want).max() / want.max() < 1e-5
    blended = rr.shade(gb, arrays, sc["effects"], sc["environment"], prefiltered=distant, dfg=bakes.result("dfg"),
                       reflection_probes=[{**c, "excluded": []} for c in captured])[hit]
    for own in (gold[hit], chrome[hit]):           # the rule changed what each sphere reads
        assert np.abs(blended[own] - want[own]).max() / want[own].max() > 0.02


def test_an_objects_own_probes_are_the_first_32():
    """rp_excl keeps the bits of probes 0..31 (kernels/reflection_probes.h RPROBE_OWN_MAX); a scene
    with more probes that excludes objects is told the rule uses the first 32; a point whose own
    probes do not hold it blends every probe."""
    from iblbake.render import reflection_probes as rp
    from iblbake.render.twin import reflection_probes as rpt

    captured = [{"excluded": [1]}] * 31 + [{"excluded": [0, 1]}, {"excluded": [0]}]
    masks = rpt.own_masks(captured, 3)
    assert masks.tolist() == [1 << 31, (1 << 32) - 1, 0]
    room = {"shape": "box", "min": [-1, -1, -1], "max": [1, 1, 1], "blend": 0, "position": [0, 0, 0]}
    away = {**room, "min": [4, 4, 4], "max": [5, 5, 5], "position": [4.5, 4.5, 4.5]}
    p = np.zeros((2, 3))
    got = rpt.own([{"settings": away}, {"settings": room}], p, np.array([1, 2], np.uint32))
    assert got.tolist() == [0, 2]
    data = {"reflection_probes": [{"position": [0, 0, 0], "exclude_ids": [0]}] * 33, "objects": []}
    said = [w for k in range(33) for w in rp.warnings(k, {}, data)]
    assert len(said) == 1 and "among the first 32" in said[0], said
    data["reflection_probes"] = [{"position": [0, 0, 0], "exclude_ids": []}] * 33
    assert [w for k in range(33) for w in rp.warnings(k, {}, data)] == []
