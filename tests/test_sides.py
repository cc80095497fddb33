"""One rule for sides (docs/conventions.md "Sides"): which mesh parts bound a solid (closed,
consistently wound, the camera outside), what an irradiance probe's ray calls a back face (the
inside of a solid, the back of a single-sided surface, never a double-sided open surface), and the
scenes that broke on it: a box of OBJ quads of either winding, probes inside a solid (warned, with
its name), a cell whose probes are all off (the nearest active probes, else the panorama's SH,
counted)."""

import math

import numpy as np

from iblbake.render import render
from iblbake.io import images
from iblbake.render import probes
from iblbake.render.bakes import Bakes
from iblbake.render.twin import probes as twin
from iblbake.scene import geometry, pack
from iblbake.scene.layout import SURFACE_FLAGS
from tests.helpers import load_scene


def cube_triangles(centre=(0, 0, 0), half=0.5, inward=False):
    """A watertight cube as (v0, v1, v2), its corners shared exactly, wound outwards (or inwards)."""
    c, h = np.asarray(centre, float), half
    p = c + h * np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1], [-1, -1, 1], [1, -1, 1], [1, 1, 1],
                          [-1, 1, 1]], float)
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (3, 7, 6, 2), (0, 4, 7, 3), (1, 2, 6, 5)]
    f = np.array([t for a, b, c_, d in quads for t in ((a, b, c_), (a, c_, d))])
    if inward:
        f = f[:, ::-1]
    return p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]


def test_closed_components_and_their_winding():
    """A watertight cube wound outwards bounds a solid (+1), inwards too (-1: the rule follows its
    volume); without a face, or with a face twice (an edge of three faces), it is open (0); two
    cubes are two components; triangles given as a soup (every corner its own vertex) weld where
    bit-identical."""
    v0, v1, v2 = cube_triangles()
    comp, solid = geometry.closed_components(v0, v1, v2)
    assert set(comp) == {0} and set(solid) == {1}
    assert set(geometry.closed_components(*cube_triangles(inward=True))[1]) == {-1}
    assert set(geometry.closed_components(v0[:-1], v1[:-1], v2[:-1])[1]) == {0}
    assert set(geometry.closed_components(np.r_[v0, v0[:1]], np.r_[v1, v1[:1]], np.r_[v2, v2[:1]])[1]) == {0}
    w0, w1, w2 = cube_triangles((3, 0, 0), inward=True)
    comp, solid = geometry.closed_components(np.r_[v0, w0], np.r_[v1, w1], np.r_[v2, w2])
    assert len(set(comp)) == 2 and sorted(set(zip(comp, solid))) == [(0, 1), (1, -1)]
    # a quad of two triangles: open, whatever its winding
    q = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], float)
    assert set(geometry.closed_components(q[[0, 0]], q[[1, 2]], q[[2, 3]])[1]) == {0}


def test_a_point_inside_a_closed_part():
    v0, v1, v2 = cube_triangles()
    comp, solid = geometry.closed_components(v0, v1, v2)
    assert geometry.inside_closed([0.1, 0.2, -0.3], v0, v1, v2, comp, solid) == {0}
    assert geometry.inside_closed([0.0, 0.0, 2.0], v0, v1, v2, comp, solid) == set()
    assert geometry.inside_closed([0.5, 0.0, 0.0], v0[:-2], v1[:-2], v2[:-2], *geometry.closed_components(
        v0[:-2], v1[:-2], v2[:-2])) == set()                      # an open part encloses nothing


def write_cube(folder, name, inward=False, centre=(0, 0, 0), half=0.5):
    v0, v1, v2 = cube_triangles(centre, half, inward)
    corners = np.stack([v0, v1, v2], 1).reshape(-1, 3)
    pts, idx = np.unique(corners, axis=0, return_inverse=True)
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in pts]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in idx.reshape(-1, 3)]
    path = folder / f"{name}.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def flags_of(arrays):
    return arrays.tris[:, 2, 3].view(np.int32), arrays.spheres[:, 1, 2].view(np.int32)


def test_which_surfaces_bound_a_solid(tmp_path, lobed_sky):
    """A closed double-sided mesh and a sphere bound solids (flipped where the mesh is wound
    inwards); the same with the camera inside them, or `solid: false`, bound none (a room, a
    dome); a closed single-sided mesh bounds one by its winding (never flipped: it is there from
    its front alone); `solid: true` makes an open mesh one."""
    S, F, ONE = SURFACE_FLAGS["solid"], SURFACE_FLAGS["solid_flipped"], SURFACE_FLAGS["single_sided"]
    cube, inv = write_cube(tmp_path, "cube"), write_cube(tmp_path, "inv", inward=True)

    def arrays(camera=(0, 0, 5), **obj):
        doc = {"camera": {"perspective": {"position": list(camera), "look_at": [0, 0, -10]}, "resolution": [8, 8]},
               "environment": {"path": str(lobed_sky)},
               "materials": {"m": {}, "one": {"double_sided": False}},
               "objects": [{"mesh": {"path": str(obj.pop("path", cube))}, "material": obj.pop("material", "m"),
                            **obj}, {"sphere": {"center": [3, 0, 0], "radius": 1}, "material": "m"}]}
        return pack.scene_arrays(load_scene(tmp_path, "s", doc))

    tri, sph = flags_of(arrays())
    assert set(tri) == {S} and set(sph) == {S}
    assert set(flags_of(arrays(path=inv))[0]) == {S | F}
    tri, sph = flags_of(arrays(camera=(0.1, 0.1, 0.2)))            # the camera inside the cube: a room
    assert set(tri) == {0} and set(sph) == {S}
    assert set(flags_of(arrays(camera=(3, 0, 0.5)))[1]) == {0}     # inside the sphere: a dome
    assert set(flags_of(arrays(solid=False))[0]) == {0}
    assert set(flags_of(arrays(material="one"))[0]) == {ONE | S}        # by its winding: never flipped
    assert set(flags_of(arrays(material="one", path=inv))[0]) == {ONE | S}
    quad = tmp_path / "quad.obj"
    quad.write_text("v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 1 2 3\nf 1 3 4\n")
    assert set(flags_of(arrays(path=quad))[0]) == {0}
    assert set(flags_of(arrays(path=quad, solid=True))[0]) == {S}


def open_box(folder, sky, inward: bool, diffuse="probes"):
    """The issue's open box: a white Lambert sphere, a floor, a back, a red left and a green right
    wall, each an OBJ quad wound out of the box (or into it), every surface double-sided."""
    walls = {"floor": [(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)],
             "back": [(-1, 0, -1), (-1, 2, -1), (1, 2, -1), (1, 0, -1)],
             "left": [(-1, 0, -1), (-1, 0, 1), (-1, 2, 1), (-1, 2, -1)],
             "right": [(1, 0, -1), (1, 2, -1), (1, 2, 1), (1, 0, 1)]}
    objs = [{"sphere": {"center": [0, 0.4, 0], "radius": 0.4}, "material": "white", "name": "sphere"}]
    for name, q in walls.items():
        q = q[::-1] if inward else q
        path = folder / f"{name}_{'in' if inward else 'out'}.obj"
        path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in q) + "f 1 2 3\nf 1 3 4\n")
        objs.append({"mesh": {"path": str(path)}, "material": {"left": "red", "right": "green"}.get(name, "white"),
                     "name": name})
    return load_scene(folder, f"box_{inward}_{diffuse}", {
        "camera": {"perspective": {"position": [0, 1.5, 3.8], "look_at": [0, 0.7, 0], "fov_y": 42},
                   "resolution": [32, 32]},
        "environment": {"path": str(sky)},
        "materials": {"white": {"base_color": [0.8, 0.8, 0.8], "specular": 0},
                      "red": {"base_color": [0.8, 0.1, 0.1], "specular": 0},
                      "green": {"base_color": [0.1, 0.8, 0.1], "specular": 0}},
        # one pass of rays (target_noise 0): the windings' volumes compared ray for ray (adaptive rounds
        # follow each winding's Monte Carlo noise, and their distance moments with them)
        "objects": objs, "probes": {"rays": 256, "target_noise": 0},
        "effects": {"diffuse": diffuse, "specular": "off", "reference": {"max_samples": 256, "target_noise": 0}}})


def baked(bakes):
    return bakes.result("probes")


def test_a_box_of_quads_lights_its_sphere_whichever_way_they_are_wound(tmp_path, rt, lobed_sky):
    """The open box of OBJ quads: wound out of the box, every probe inside it met the quads' back
    faces and was switched off as inside geometry, and the sphere rendered black (before the rule,
    252 of 448 probes off). Now both windings give the same volume (the same states and distances;
    irradiance as Monte Carlo agrees), no probe is inside a wall, no warning is said, and the sphere's
    diffuse light from the probes is within 10% of the converged reference's on average (measured
    5%; SH, blind to the box, 60%)."""
    vols, frames, warned = [], [], []     # out of the box, into it
    for inward in (False, True):
        bakes = Bakes(tmp_path / "cache")
        frames.append(render(open_box(tmp_path, lobed_sky, inward), runtime=rt, cache=bakes,
                                    warn=warned.append))
        vols.append(baked(bakes))
    a, b = vols
    assert np.array_equal(a["data"][:, 3], b["data"][:, 3])
    # the rays meet the same points (distances to float32 rounding); the paths beyond, whose hits the
    # watertight test computes from corners in the other order, scatter differently: the two
    # volumes agree as Monte Carlo does, over every probe to 1% (measured 0.1%)
    assert np.abs(a["distance"] - b["distance"]).max() <= 1e-5 * a["distance"].max()
    assert abs(a["irradiance"].mean() / b["irradiance"].mean() - 1) < 0.01
    for v in vols:                                 # inside geometry: only the sphere's own probes
        assert set(v["report"]["inside_objects"]) <= {"0"}, v["report"]
    assert not [w for w in warned if "inside geometry" in w]
    ref = render(open_box(tmp_path, lobed_sky, False, "reference"), runtime=rt,
                        cache_root=tmp_path / "cache")
    sh = render(open_box(tmp_path, lobed_sky, False, "sh"), runtime=rt, cache_root=tmp_path / "cache")
    from iblbake.render import twin as rr
    sc = open_box(tmp_path, lobed_sky, False, "reference")
    gb = rr.primary(sc["camera"], pack.scene_arrays(sc))
    sphere = ((gb["kind"] == 1) & gb["hit"]).reshape(32, 32)
    want = ref.hdr[..., :3][sphere].mean(0)
    for f, bound in ((frames[0], 0.10), (frames[1], 0.10)):
        got = f.hdr[..., :3][sphere].mean(0)
        assert np.abs(got - want).sum() / want.sum() < bound
    assert np.abs(sh.hdr[..., :3][sphere].mean(0) - want).sum() / want.sum() > 0.3


def test_probes_inside_a_solid_are_said_with_its_name(tmp_path, rt, lobed_sky):
    """A closed cube filling most of the probes' box: its probes are inside geometry, the bake's
    report counts them by object and render says so in one line naming the object; the same cube
    as a room the camera stands in is no solid, and nothing is said, from the same cache (the
    camera's side of the cube is in the bake's key: a new user's stale volume, 216 probes off)."""
    cube = write_cube(tmp_path, "big", half=1.0)
    doc = {"camera": {"perspective": {"position": [0, 0.5, 4], "look_at": [0, 0, 0]}, "resolution": [8, 8]},
           "environment": {"path": str(lobed_sky)},
           "materials": {"m": {"specular": 0}},
           "objects": [{"mesh": {"path": str(cube)}, "material": "m", "name": "crate"}],
           "probes": {"min": [-0.9, -0.9, -0.9], "max": [1.5, 1.5, 1.5], "counts": [4, 4, 4], "rays": 64},
           "effects": {"diffuse": "probes", "specular": "off"}}
    warned = []
    bakes = Bakes(tmp_path / "cache")
    render(load_scene(tmp_path, "crate", doc), runtime=rt, cache=bakes, warn=warned.append)
    rep = baked(bakes)["report"]
    assert rep["inside_geometry"] >= 27 and rep["inside_objects"] == {"0": rep["inside_geometry"]}
    said = [w for w in warned if "inside geometry" in w]
    assert len(said) == 1 and "'crate' (objects.0)" in said[0] and "\n" not in said[0]
    warned.clear()
    room = {**doc, "camera": {"perspective": {"position": [0.3, 0.2, 0.5], "look_at": [0, 0, -1]},
                              "resolution": [8, 8]}}
    bakes = Bakes(tmp_path / "cache")
    render(load_scene(tmp_path, "room", room), runtime=rt, cache=bakes, warn=warned.append)
    assert baked(bakes)["report"]["inside_geometry"] == 0 and not [w for w in warned if "inside geometry" in w]
    # (the room's walls at +-1 lie on the volume's fading edge (min -0.9): that is said, apart)
    assert [w for w in warned if "outside the probe volume" in w]


def test_a_closed_room_is_dark_and_its_outside_probes_are_off(tmp_path, rt, lobed_sky):
    """A watertight cube of zero-thickness walls with the camera and a sphere inside it: no light
    enters, the reference is black. The automatic grid overhangs the room by half a cell; those
    probes see the sky and, before this rule, lit the room along every wall (a new user's trial:
    mean 0.035, max 2.15 at 8 probes; 0.44 at 3). Probes outside a closed part that encloses the
    camera are off (counted in the report), and the room is black at every grid size."""
    cube = write_cube(tmp_path, "room", half=1.0)
    doc = {"camera": {"perspective": {"position": [0.4, 0.2, 0.4], "look_at": [-0.5, -0.3, -0.5], "fov_y": 80},
                      "resolution": [16, 12]},
           "environment": {"path": str(lobed_sky), "background": "hide"},
           "materials": {"m": {"specular": 0}},
           "objects": [{"mesh": {"path": str(cube)}, "material": "m", "name": "room"},
                       {"sphere": {"center": [-0.4, -0.6, -0.4], "radius": 0.3}, "material": "m"}],
           "probes": {"rays": 64}, "effects": {"diffuse": "probes", "specular": "off"}}
    for counts in (8, 3):
        bakes = Bakes(tmp_path / "cache")
        sc = load_scene(tmp_path, f"room{counts}", {**doc, "probes": {"rays": 64, "counts": counts}})
        frame = render(sc, runtime=rt, cache=bakes)
        vol = baked(bakes)
        pos = vol["grid"].positions() + vol["data"][:, :3]
        outside = (np.abs(pos) >= 1.0).any(1)
        assert outside.any() and vol["report"]["outside_camera_room"] == int(outside.sum())
        assert (vol["data"][outside, 3] == probes.INACTIVE).all()
        assert frame.hdr[..., :3].max() == 0.0, counts
    sh = render(load_scene(tmp_path, "room_sh", {**doc, "effects": {"diffuse": "sh", "specular": "off"}}),
                       runtime=rt, cache=Bakes(tmp_path / "cache"))
    assert sh.hdr[..., :3].mean() > 0.1               # SH, blind to the walls, lights the room


def test_a_cell_of_inactive_probes_falls_back(rt):
    """The eight probes of a cell all off: the nearest active ones of the 4 x 4 x 4 around it
    stand in (a constant field: exactly its value; RTXGI returns 0 there), in the kernel and its
    twin alike; no active probe near: the source says none (the shade pass then reads the SH)."""
    from tests.probe_helpers import kernel_irradiance, settings, synthetic
    counts = (4, 4, 4)
    grid = probes.Grid((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), counts)
    cell = np.array([[x, y, z] for x in (1, 2) for y in (1, 2) for z in (1, 2)])
    states = np.zeros(64)
    states[twin.probe_index(cell, counts)] = probes.INACTIVE
    vol = probes.sampled(synthetic(counts, grid.spacing, grid.origin, value=lambda p: np.array([0.5, 1.0, 2.0]),
                                   states=states), settings(visibility=False))
    p = np.array([[1.5, 1.5, 1.5], [1.2, 1.8, 1.4]])
    n = np.array([[0, 1.0, 0], [1.0, 0, 0]])
    got, src = twin.irradiance_and_source(vol, p, n, n, visibility=False, classification=True)
    assert (src == twin.SOURCE_NEAREST).all() and np.abs(got - [0.5, 1.0, 2.0]).max() < 1e-12
    k = kernel_irradiance(rt, vol, p, n, n, False, True)
    assert np.abs(k - [0.5, 1.0, 2.0]).max() < 1e-6
    vol["data"][:, 3] = probes.INACTIVE
    got, src = twin.irradiance_and_source(vol, p, n, n, visibility=False, classification=True)
    assert (src == twin.SOURCE_NONE).all() and not got.any()


def test_the_shade_pass_counts_the_samples_that_fell_back(tmp_path, rt, lobed_sky):
    """A volume whose probes are all off: the sphere is lit by the panorama's SH, exactly as
    `diffuse: sh` lights it (not black, as RTXGI's 0 made it), and the report counts every sample."""
    from tests.probe_helpers import Given, sphere_scene
    sc = sphere_scene(tmp_path, lobed_sky, "probes")
    bakes = Bakes(tmp_path / "cache")
    render(sc, runtime=rt, cache=bakes)
    vol = baked(bakes)
    vol = {**vol, "data": np.concatenate([vol["data"][:, :3], np.ones((len(vol["data"]), 1))], 1)}
    f = render(sc, runtime=rt, cache=Given(tmp_path / "cache", vol))
    with_sh = render(sphere_scene(tmp_path, lobed_sky, "sh"), runtime=rt, cache_root=tmp_path / "cache")
    hit = f.hdr[..., 3] > 0
    shade = next(p for p in f.report["passes"] if p["name"] == "shade")
    assert shade["probe_fallback_sky"] == int(hit.sum()) and shade["probe_fallback_nearest"] == 0
    assert np.abs(f.hdr[hit] - with_sh.hdr[hit]).max() <= 1e-5 * with_sh.hdr[hit].max()


def test_probe_rays_pass_single_sided_backs_and_meet_solids_insides(tmp_path, rt, lobed_sky):
    """A probe 0.5 behind a single-sided quad facing away: its ray passes through (as the camera's,
    the paths' and the captures' do: the light behind it reaches the probe); the same quad
    double-sided is a front face; a probe inside a closed single-sided cube meets its inside, a
    back face (the probe is inside geometry)."""
    from iblbake.render.units import Job
    quad = tmp_path / "q.obj"
    quad.write_text("v -2 -2 0\nv 2 -2 0\nv 2 2 0\nv -2 2 0\nf 1 2 3\nf 1 3 4\n")      # faces +z
    cube = write_cube(tmp_path, "c", centre=(0, 0, -3), half=0.5)

    def trace(path, sided, origin):
        sc = load_scene(tmp_path, f"q{sided}{path.stem}", {
            "camera": {"perspective": {"position": [0, 0, 3], "look_at": [0, 0, 0]}, "resolution": [8, 8]},
            "environment": {"path": str(lobed_sky)},
            "materials": {"m": {"double_sided": sided}},
            "objects": [{"mesh": {"path": str(path)}, "material": "m"}],
            "effects": {"diffuse": "probes", "specular": "off"}})
        tracer = probes.Tracer(Job(sc, rt, Bakes(tmp_path / "c")), {"bounces": 1, "seed": 1})
        return tracer.trace(np.array([origin]), np.array([[0, 0, 1.0], [0, 0, -1.0]]), True)

    _rad, t, obj = trace(quad, False, [0, 0, -0.5])
    assert obj[0, 0] == -1 and np.isinf(t[0, 0])                    # through the single-sided back
    _rad, t, obj = trace(quad, True, [0, 0, -0.5])
    assert obj[0, 0] == 0 and math.isclose(t[0, 0], 0.5, rel_tol=1e-5)
    _rad, t, obj = trace(cube, False, [0, 0, -3])
    assert (obj[0] == 0).all() and (t[0] < 0).all() and np.allclose(-t[0], 0.5, rtol=1e-5)


def test_negative_texels_do_not_spoil_a_bake(tmp_path, rt):
    """A panorama whose lower half holds tiny negative texels (kept as stored: environment.negative
    keep; every one of Blender's panoramas has some): probes and a capture under a floor see only
    its underside, lit by them. Their irradiance and radiance stay >= 0 and read back (a negative
    value failed the volume's and the capture's checks: found on the city panorama)."""
    sky = tmp_path / "neg.exr"
    img = np.full((16, 32, 3), 0.5, np.float32)
    img[8:] = -1e-3
    images.write_exr(sky, img)
    sc = load_scene(tmp_path, "neg", {
        "camera": {"perspective": {"position": [0, 0.5, 3], "look_at": [0, 0, 0]}, "resolution": [8, 8]},
        "environment": {"path": str(sky)},
        "materials": {"d": {"specular": 0}, "m": {"metallic": 1, "roughness": 0.1}},
        "objects": [{"plane": {"point": [0, 0, 0], "size": 40}, "material": "d"},
                    {"sphere": {"center": [0, 0.5, 0], "radius": 0.5}, "material": "m"}],
        "probes": {"min": [-1, -0.6, -1], "max": [1, -0.2, 1], "counts": [2, 2, 2], "rays": 64,
                   "relocation": False, "classification": False},
        "reflection_probes": [{"position": [0, -0.5, 0], "min": [-2, -1, -2], "max": [2, 1, 2], "size": 8,
                               "samples": 4}],
        "effects": {"diffuse": "probes", "specular": "prefiltered"}})
    for _ in range(2):                            # baked, then read back from the cache
        bakes = Bakes(tmp_path / "cache")
        render(sc, runtime=rt, cache=bakes)
        assert (baked(bakes)["irradiance"] >= 0).all()
        (capture, _cached, _report), = list(bakes.held("reflection").values())
        assert (capture >= 0).all() and capture[..., 3].max() == 1


def test_a_junction_step_past_a_bright_layer_keeps_its_floor(rt):
    """The junction step goes on linearly from the live layer to the point, by the reads one cell
    apart; past a layer 21x brighter (a sun patch's) its line went below 0 and the point read black
    (a new user's L-shaped room: its inner corner's floor, RGB 0 where the truth was x0.8 of the
    read). It keeps STEP_FLOOR of the read, in the kernel and the twin alike. Probes at x = 0 and
    y = 0 off (two walls), those at x = 2 or y = 2 and beyond 21x the rest."""
    from tests.probe_helpers import kernel_irradiance, settings, synthetic
    counts = (4, 4, 4)
    grid = probes.Grid((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), counts)
    pos = grid.positions()
    states = np.where((pos[:, 0] < 0.5) | (pos[:, 1] < 0.5), probes.INACTIVE, 0.0)
    vol = probes.sampled(synthetic(counts, grid.spacing, grid.origin, states=states,
                                   value=lambda p: np.array([1.0, 1.0, 1.0]) * (21.0 if max(p[0], p[1]) > 1.5 else 1.0)),
                         settings(visibility=False))
    p = np.array([[0.3, 0.3, 1.5], [0.6, 0.2, 1.2]])
    n = np.array([[0, 0, 1.0], [0, 0, 1.0]])
    e, _ = twin.blend_and_source(vol, p, n, n, visibility=False, classification=True)
    got, src = twin.irradiance_and_source(vol, p, n, n, visibility=False, classification=True)
    assert (src == twin.SOURCE_CELL).all() and np.allclose(e, 1.0)
    assert (got > 0).all() and np.allclose(got, twin.STEP_FLOOR * e, rtol=1e-9), got    # below 0: the floor
    k = kernel_irradiance(rt, vol, p, n, n, False, True)
    assert np.abs(k - got).max() < 1e-5, (k, got)
