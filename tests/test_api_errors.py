"""The API's promise (issue 44) against a new user's trial: a wrong kind or value of an argument is
an iblbake.InputError of one line naming the argument and what it takes, said before any work
(raw AttributeError, TypeError and ValueError came out, or the call ran on with a bad value);
scene mappings take numpy values; messages name the API's arguments, not the command line's
flags; the documented types and shapes hold."""

import numpy as np
import pytest

import iblbake
from tests.helpers import write_exr


@pytest.fixture(scope="module")
def sky(tmp_path_factory):
    v = (np.arange(16)[:, None, None] + 0.5) / 16
    return write_exr(tmp_path_factory.mktemp("sky") / "sky.exr",
                     np.where(v < 0.5, [0.6, 0.8, 1.0], [0.1, 0.08, 0.05]) * np.ones((16, 32, 1)))


@pytest.fixture(scope="module")
def pano(sky):
    return iblbake.load_panorama(sky)


def scene_of(sky, **sections):
    doc = {"camera": {"perspective": {"position": [0, 0, 3], "fov_y": 40}, "resolution": [8, 8]},
           "environment": {"path": sky},
           "materials": {"m": {"base_color": [0.75, 0.5, 0.25], "roughness": 0.5}},
           "objects": [{"sphere": {"radius": 1}, "material": "m"}],
           "effects": {"diffuse": "sh", "specular": "off"}}
    return {**doc, **sections}


def _in_itself(doc):
    doc = dict(doc)
    doc["materials"] = {"m": {"base_color": [1, 1, 1]}}
    doc["materials"]["m"]["extra"] = doc["materials"]
    return doc


def _scene_in_itself(doc):
    doc = dict(doc)
    doc["materials"] = {"m": {"base_color": [1, 1, 1]}}
    doc["materials"]["m"]["self"] = doc
    return doc


class Stop(Exception):
    """Raised from before_run: the study stops before anything renders."""


def stop(*_args):
    raise Stop


# (argument the message names, the call): each an InputError before any work
BAD = {
    "sh": [
        ("panorama", lambda c: iblbake.sh(c["sky"])),
        ("panorama", lambda c: iblbake.sh(np.ones((4, 8, 3)))),
        ("panorama", lambda c: iblbake.sh(None)),
        ("bands", lambda c: iblbake.sh(c["pano"], bands=3.0)),
        ("bands", lambda c: iblbake.sh(c["pano"], bands=True)),
        ("window", lambda c: iblbake.sh(c["pano"], window="")),
        ("rotate_y", lambda c: iblbake.sh(c["pano"], rotate_y="10")),
        ("intensity", lambda c: iblbake.sh(c["pano"], intensity="2")),
        ("intensity", lambda c: iblbake.sh(c["pano"], intensity=True)),
        ("intensity", lambda c: iblbake.sh(c["pano"], intensity=-1.0)),
        ("intensity 1e+300: scales the panorama's brightest texel", lambda c: iblbake.sh(c["pano"], intensity=1e300)),
        ("error", lambda c: iblbake.sh(c["pano"], error="no")),
        ("error", lambda c: iblbake.sh(c["pano"], error=1)),
        ("device", lambda c: iblbake.sh(c["pano"], backend="opencl", device=5)),
        ("names", lambda c: iblbake.sh(c["pano"], names=["--bands"])),
    ],
    "SH": [
        ("bands=3", lambda c: iblbake.sh(c["pano"], 4, error=False).to_filament()),
        ("bands=3", lambda c: iblbake.sh(c["pano"], 4, error=False).to_threejs()),
        ("bands=3", lambda c: iblbake.sh(c["pano"], 4, error=False).to_gltf()),
        ("bands=3", lambda c: iblbake.sh(c["pano"], 4, error=False).export("filament")),
    ],
    "basis": [
        ("panorama", lambda c: iblbake.basis(c["sky"], "zh3")),
        ("intensity", lambda c: iblbake.basis(c["pano"], "zh3", intensity="1")),
        ("error", lambda c: iblbake.basis(c["pano"], "zh3", error="yes")),
        ("sg_lobes", lambda c: iblbake.basis(c["pano"], "sg", sg_lobes=9.0)),
        ("sg_lobes", lambda c: iblbake.basis(c["pano"], "sg", sg_lobes=True)),
        ("sg_lobes", lambda c: iblbake.basis(c["pano"], "sg", sg_lobes="9")),
        ("basis", lambda c: iblbake.basis(c["pano"], 5)),
    ],
    "Basis": [
        ("normals", lambda c: iblbake.basis(c["pano"], "zh3", error=False).irradiance([1, 0])),
        ("normals", lambda c: iblbake.basis(c["pano"], "zh3", error=False).irradiance("up")),
        ("normals", lambda c: iblbake.basis(c["pano"], "zh3", error=False).irradiance([0, 2, 0])),     # not unit
        ("normals", lambda c: iblbake.basis(c["pano"], "zh3", error=False).irradiance([0, 0, 0])),
        ("views", lambda c: iblbake.basis(c["pano"], "sg", error=False).specular_radiance(
            [[0, 1, 0]], [[0, 1, 0], [1, 0, 0]], 0.5)),
        ("roughness", lambda c: iblbake.basis(c["pano"], "sg", error=False).specular_radiance(
            [[0, 1, 0]], [[0, 1, 0]], "0.5")),
        ("roughness", lambda c: iblbake.basis(c["pano"], "sg", error=False).specular_radiance(
            [[0, 1, 0]], [[0, 1, 0]], 2.0)),
    ],
    "prefilter": [
        ("panorama", lambda c: iblbake.prefilter(c["sky"])),
        ("progress", lambda c: iblbake.prefilter(c["pano"], size=8, levels=2, backend="numpy", progress="x")),
        ("size", lambda c: iblbake.prefilter(c["pano"], size=0, backend="numpy")),
        # issue 60's fuzzing: the texel count of a 2^40 cube map wrapped in int64 and passed the check
        ("size 1099511627776: the cubemap chain needs", lambda c: iblbake.prefilter(
            c["pano"], 2 ** 40, 3, "cubemap", min_size=2 ** 40, backend="numpy")),
        ("size 1000000000000000000000000000000: the equirect chain needs", lambda c: iblbake.prefilter(
            c["pano"], 10 ** 30, backend="numpy")),          # the bisect's len() overflowed
        ("device", lambda c: iblbake.prefilter(c["pano"], device=5)),
        # issue 60: no bound on levels (40 asked 23 GB) nor on samples
        ("levels 33: use 1 to 32", lambda c: iblbake.prefilter(c["pano"], 8, 33, method="fis", samples=4,
                                                             backend="numpy")),
        ("samples", lambda c: iblbake.prefilter(c["pano"], 8, 2, method="fis", samples=2 ** 40, backend="numpy")),
        # the trial: a float count said only the range; an unknown keyword was a raw TypeError
        ("samples 64.0: give a whole number 1 to 1048576", lambda c: iblbake.prefilter(c["pano"], 8, 3, samples=64.0)),
        ("bogus: not an argument of prefilter (its arguments: panorama, size,",
         lambda c: iblbake.prefilter(c["pano"], 8, 3, bogus=1)),
        ("prefilter: missing a required argument: 'panorama'", lambda c: iblbake.prefilter(size=8)),
    ],
    "dfg": [
        ("multiscatter", lambda c: iblbake.dfg(4, samples=4, multiscatter="yes", backend="numpy")),
        ("size", lambda c: iblbake.dfg(4.0, backend="numpy")),
        ("device", lambda c: iblbake.dfg(4, device=5)),
        ("samples 1099511627776: use 1 to 1048576", lambda c: iblbake.dfg(4, samples=2 ** 40, backend="numpy")),
        ("size 16.0: give a whole number 2 to 4096", lambda c: iblbake.dfg(np.float64(16))),
        ("bogus: not an argument of dfg", lambda c: iblbake.dfg(8, bogus=1)),
    ],
    "load_panorama": [
        ("path", lambda c: iblbake.load_panorama(None)),
        ("path", lambda c: iblbake.load_panorama(123)),
        ("max_pixels", lambda c: iblbake.load_panorama(c["sky"], max_pixels="big")),
        ("max_pixels", lambda c: iblbake.load_panorama(c["sky"], max_pixels=-1)),
        ("max_pixels", lambda c: iblbake.load_panorama(c["sky"], max_pixels=0)),
        ("max_pixels", lambda c: iblbake.load_panorama(c["sky"], max_pixels=True)),
        ("names", lambda c: iblbake.load_panorama(c["sky"], names="--flags")),
        # the trial: a NUL read as a missing file, raw in the message ('city\0.exr: no such file')
        (r"path 'city\x00.exr': holds a NUL character", lambda c: iblbake.load_panorama("city\0.exr")),
    ],
    "Panorama.from_pixels": [
        ("pixels", lambda c: iblbake.Panorama.from_pixels(c["sky"])),
        ("pixels", lambda c: iblbake.Panorama.from_pixels([["a", "b"]])),
        ("nonfinite", lambda c: iblbake.Panorama.from_pixels(np.ones((4, 8, 3)), nonfinite="bogus")),
        ("negative", lambda c: iblbake.Panorama.from_pixels(np.ones((4, 8, 3)), negative=None)),
        ("name", lambda c: iblbake.Panorama.from_pixels(np.ones((4, 8, 3)), name=5)),
        ("bogus: not an argument of Panorama.from_pixels (its arguments: pixels,",
         lambda c: iblbake.Panorama.from_pixels(np.ones((4, 8, 3)), bogus=1)),
        # issue 60: an array's repr spanned lines; a complex array lost its imaginary part with a warning
        ("nonfinite array(", lambda c: iblbake.Panorama.from_pixels(np.ones((4, 8, 3)), nonfinite=np.zeros((4, 8, 3)))),
        ("pixels", lambda c: iblbake.Panorama.from_pixels(np.ones((4, 8, 3), complex))),
    ],
    "load_scene": [
        ("scene", lambda c: iblbake.load_scene(123)),
        ("folders: not an argument of load_scene", lambda c: iblbake.load_scene(c["scene"], folders=".")),
        (r"scene 's\x00.yaml': holds a NUL character", lambda c: iblbake.load_scene("s\0.yaml")),
        (r"folder 'a\x00': holds a NUL character", lambda c: iblbake.load_scene(c["scene"], folder="a\0")),
        (r"outputs 'f\x00.png': holds a NUL character", lambda c: iblbake.load_scene(c["scene"], outputs="f\0.png")),
        ("overrides", lambda c: iblbake.load_scene(c["scene"], [5])),
        ("overrides", lambda c: iblbake.load_scene(c["scene"], 5)),
        ("outputs", lambda c: iblbake.load_scene(c["scene"], outputs=5)),
        ("folder", lambda c: iblbake.load_scene(c["scene"], folder=None)),
        ("names", lambda c: iblbake.load_scene(c["scene"], names="--set")),
        # issue 60: raw TypeError (an int key, a generator) and RecursionError (a mapping in itself)
        ("materials: key 5", lambda c: iblbake.load_scene({**c["scene"], "materials": {5: {}}})),
        ("objects: generator", lambda c: iblbake.load_scene({**c["scene"], "objects": (o for o in [])})),
        ("camera.perspective.position: generator", lambda c: iblbake.load_scene(
            {**c["scene"], "camera": {"perspective": {"position": (x for x in (0, 0, 3))}}})),
        ("<scene>: materials.m.extra: contains itself", lambda c: iblbake.load_scene(_in_itself(c["scene"]))),
        # the trial: the scene inside one of its sections named the key below it (materials.m.self.materials)
        ("<scene>: materials.m.self: contains itself", lambda c: iblbake.load_scene(_scene_in_itself(c["scene"]))),
    ],
    "render": [
        ("scene", lambda c: iblbake.render(None)),
        ("cache", lambda c: iblbake.render(c["scene"], cache=123)),
        ("warn", lambda c: iblbake.render(c["scene"], warn="x")),
        ("progress", lambda c: iblbake.render(c["scene"], progress="x")),
        ("device", lambda c: iblbake.render(c["scene"], 5)),
        ("profile: not an argument of render", lambda c: iblbake.render(c["scene"], profile=True)),
    ],
    "Renderer": [
        ("reuse", lambda c: iblbake.Renderer(reuse="no")),
        ("cache", lambda c: iblbake.Renderer(cache=123)),
        ("device", lambda c: iblbake.Renderer(device=0)),
        (r"cache 'c\x00': holds a NUL character", lambda c: iblbake.Renderer(cache="c\0")),
        ("cache_dir: not an argument of Renderer (its arguments: device, cache,", lambda c: iblbake.Renderer(cache_dir=1)),
        ("scenes: not an argument of Renderer.render", lambda c: iblbake.Renderer().render(scenes=c["scene"])),
    ],
    "bake_probes": [
        ("scene", lambda c: iblbake.bake_probes(["scene.yaml"])),
        ("cache", lambda c: iblbake.bake_probes(c["scene"], cache=1)),
        ("warn", lambda c: iblbake.bake_probes(c["scene"], warn="x")),
    ],
    "bake_lightmap": [
        ("scene", lambda c: iblbake.bake_lightmap(["scene.yaml"])),
        ("no `lightmap:` section", lambda c: iblbake.bake_lightmap(c["scene"])),
        ("cache", lambda c: iblbake.bake_lightmap(c["scene"], cache=1)),
        ("progress", lambda c: iblbake.bake_lightmap(c["scene"], progress="x")),
    ],
    "accuracy": [
        ("scene", lambda c: iblbake.accuracy(123)),
        ("repeats", lambda c: iblbake.accuracy(c["scene"], repeats=0)),
        (r"ladder 'l\x00.yaml': holds a NUL character", lambda c: iblbake.accuracy(c["scene"], ladder="l\0.yaml")),
        ("repeats", lambda c: iblbake.accuracy(c["scene"], repeats=-2)),
        ("max_side", lambda c: iblbake.accuracy(c["scene"], max_side=-1)),
        ("max_side", lambda c: iblbake.accuracy(c["scene"], max_side=0)),
        ("max_side", lambda c: iblbake.accuracy(c["scene"], max_side="16")),
        ("max_samples", lambda c: iblbake.accuracy(c["scene"], max_samples=0)),
        ("target_noise", lambda c: iblbake.accuracy(c["scene"], target_noise=-0.1)),
        ("visibility", lambda c: iblbake.accuracy(c["scene"], visibility="no")),
        ("flip", lambda c: iblbake.accuracy(c["scene"], flip=None)),
        ("bounces", lambda c: iblbake.accuracy(c["scene"], bounces=0)),
        ("bounces", lambda c: iblbake.accuracy(c["scene"], bounces="many")),
        ("jobs", lambda c: iblbake.accuracy(c["scene"], jobs=0)),
        ("devices", lambda c: iblbake.accuracy(c["scene"], devices="gpu,cpu")),
        ("ladder", lambda c: iblbake.accuracy(c["scene"], ladder=5)),
        ("overrides", lambda c: iblbake.accuracy(c["scene"], overrides=[5])),
        ("cache", lambda c: iblbake.accuracy(c["scene"], cache=5)),
        ("warn", lambda c: iblbake.accuracy(c["scene"], warn="x")),
        ("progress", lambda c: iblbake.accuracy(c["scene"], progress="x")),
        ("before_run", lambda c: iblbake.accuracy(c["scene"], before_run="x")),
    ],
}


@pytest.mark.parametrize("function,named,call", [pytest.param(f, named, call, id=f"{f}-{i}-{named}")
                                                 for f, cases in BAD.items() for i, (named, call) in enumerate(cases)])
def test_a_bad_argument_is_an_input_error_naming_it(function, named, call, sky, pano, monkeypatch):
    """One line naming the argument: never AttributeError, TypeError, ValueError or IndexError,
    and never the bare base class. A bad argument of accuracy is refused before the reference
    renders (repeats=0 rendered it, then crashed in the study)."""
    from iblbake.study import accuracy as acc
    monkeypatch.setattr(acc.Study, "render_reference", lambda *a: pytest.fail("rendered before refusing"))
    with pytest.raises(iblbake.InputError) as e:
        call({"sky": sky, "pano": pano, "scene": scene_of(sky)})
    message = str(e.value)
    assert named in message and "\n" not in message, message
    assert type(e.value) is not iblbake.Error


def test_a_scene_mapping_takes_numpy_values(sky, tmp_path):
    """numpy scalars and arrays, tuples and paths read as a file's numbers, lists and strings
    ("holds np.int64(32), not a finite number"); a bool, numpy's too, is still not a number."""
    from pathlib import Path
    plain = scene_of(sky, probes={"rays": 16})
    plain["camera"] = {"perspective": {"position": [0.0, 0.0, 3.0], "fov_y": 40}, "resolution": [32, 24]}
    numpy = scene_of(Path(sky), probes={"rays": np.int64(16)})
    numpy["environment"] = {"path": Path(sky)}
    numpy["camera"] = {"perspective": {"position": np.array([0.0, 0, 3]), "fov_y": np.float32(40)},
                       "resolution": [np.int64(32), np.int64(24)]}
    numpy["materials"] = {"m": {"base_color": np.array([0.75, 0.5, 0.25], np.float32), "roughness": np.float64(0.5)}}
    numpy["objects"] = ({"sphere": {"radius": np.int32(1)}, "material": "m"},)
    assert iblbake.load_scene(numpy).data == iblbake.load_scene(plain).data
    for bad in ({"resolution": [np.bool_(True), 24]}, {"resolution": [True, 24]},
                {"perspective": {"fov_y": np.bool_(True)}}):
        with pytest.raises(iblbake.InputError, match="camera"):
            iblbake.load_scene(scene_of(sky, camera=bad))


def test_scene_value_errors_of_the_bakes_are_input_errors(sky, tmp_path):
    """`probes: {counts: 1}` and a cache folder that is a file raised the bare iblbake.Error, not
    the documented InputError."""
    scene = scene_of(sky, objects=[{"sphere": {"radius": 1}, "material": "m"},
                                   {"plane": {"point": [0, -1, 0], "size": 4}, "material": "m"}])
    with pytest.raises(iblbake.InputError, match="probes.counts 1"):
        iblbake.bake_probes({**scene, "probes": {"counts": 1}}, cache=tmp_path / "cache")
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(iblbake.InputError, match="cannot create the cache folder"):
        iblbake.render(scene_of(sky), cache=afile)


def test_overrides_and_outputs_given_as_one_string(sky, tmp_path):
    """A plain string was split into characters ("--set 'm': expected KEY.PATH=VALUE")."""
    import os
    sc = iblbake.load_scene(scene_of(sky), "materials.m.roughness=0.25", outputs=str(tmp_path / "x.png"))
    assert sc.data["materials"]["m"]["roughness"] == 0.25
    assert sc.data["output"]["frame"] == [os.path.abspath(tmp_path / "x.png")]
    assert iblbake.load_scene(scene_of(sky), None).data == iblbake.load_scene(scene_of(sky)).data
    again = iblbake.load_scene(sc, ["materials.m.roughness=0.75"])       # a Scene, validated again
    assert again.data["materials"]["m"]["roughness"] == 0.75 and sc.data["materials"]["m"]["roughness"] == 0.25


def test_messages_name_the_apis_arguments_not_the_command_lines_flags(sky, tmp_path):
    """From Python "raise it with --max-pixels", "give --bands 3", "--set: ...", "--device" named
    flags that do not exist there; the command line passes its flags (its messages are its tests')."""
    nan = write_exr(tmp_path / "nan.exr", np.full((8, 16, 3), np.nan))
    said = []
    for named, call in [
            ("max_pixels", lambda: iblbake.load_panorama(sky, max_pixels=10)),
            ("nonfinite zero", lambda: iblbake.load_panorama(nan)),
            ("give layout for", lambda: iblbake.load_panorama(sky, layout="hcross")),
            ("layout faces", lambda: iblbake.load_panorama(sky, layout="faces")),
            ("bands=3", lambda: iblbake.sh(iblbake.Panorama.from_pixels(np.ones((4, 8, 3))), 4).to_filament()),
            ("overrides 'x'", lambda: iblbake.load_scene(scene_of(sky), "x")),
            ("<scene>: overrides: probes.spacing", lambda: iblbake.load_scene(
                scene_of(sky), "probes={counts: 4, spacing: 0.5}")),
            ("device/IBLBAKE_DEVICE 'no such device'", lambda: iblbake.sh(
                iblbake.Panorama.from_pixels(np.ones((4, 8, 3))), backend="opencl", device="no such device")),
            ("did you mean ladder realtime?", lambda: iblbake.accuracy(scene_of(sky), "realtme", before_run=stop))]:
        with pytest.raises(iblbake.Error) as e:
            call()
        assert named in str(e.value), str(e.value)
        said.append(str(e.value))
    warnings = []
    with pytest.raises(Stop):
        iblbake.accuracy(scene_of(sky), bounces=2, max_samples=16, warn=warnings.append, before_run=stop)
    assert warnings and warnings[0].startswith("bounces 2: no light passes between"), warnings
    assert not [m for m in said + warnings if "--" in m], said + warnings


def test_accuracy_takes_a_mapping_or_a_scene_and_caches_its_reference(sky, tmp_path):
    """accuracy() said "<the dict's repr>: scene file not found" where every other function takes
    a mapping or a Scene; the reference is keyed by the scene's content (a second run reads it
    back), overrides apply (one string is one override), and no scene file is said to be read."""
    ladder = tmp_path / "ladder.yaml"
    ladder.write_text("rungs: [{key: effects.sh_bands, values: [1]}]\n")
    reads = []
    args = dict(max_side=8, repeats=1, max_samples=8, flip=False, cache=tmp_path / "cache")
    first = iblbake.accuracy(scene_of(sky), ladder, before_run=lambda s, r, files: reads.extend(files), **args)
    assert first.summary["scene"] == "<scene>" and [r["label"] for r in first.records][1:] == ["sh_bands=1"]
    assert first.reference["diffuse"]["cached"] == [False, False]
    assert reads and not [w for w, _ in reads if w == "the scene file"], reads
    again = iblbake.accuracy(iblbake.load_scene(scene_of(sky)), ladder, **args)
    assert again.reference["diffuse"]["cached"] == [True, True]
    assert np.array_equal(again.reference["diffuse"]["hdr"], first.reference["diffuse"]["hdr"])
    rough = iblbake.accuracy(scene_of(sky), ladder, overrides="materials.m.base_color=[0.5, 0.5, 0.5]", **args)
    assert rough.study.scene.data["materials"]["m"]["base_color"] == [0.5, 0.5, 0.5]
    assert rough.reference["diffuse"]["cached"] == [False, False]


def test_to_filament_is_nine_rows_as_documented(pano):
    """sh(pano, 2).to_filament() was (4, 3) where the docs say (9, 3): padded with zeros, as
    to_threejs and to_gltf are."""
    from iblbake.bake import sh as shbake
    two = iblbake.sh(pano, 2, error=False)
    for rows in (two.to_filament(), two.to_threejs(), two.to_gltf()):
        assert rows.shape == (9, 3) and not rows[4:].any()
    assert np.array_equal(two.to_filament()[:4], shbake.filament_coefficients(two.document))


def test_probe_volumes_are_float32_as_documented(sky, tmp_path):
    """ProbeVolume's arrays were float64 where the docs (and the volume's files) say float32."""
    scene = scene_of(sky, objects=[{"sphere": {"radius": 1}, "material": "m"},
                                   {"plane": {"point": [0, -1, 0], "size": 4}, "material": "m"}],
                     probes={"counts": [3, 2, 3], "rays": 16})
    vol = iblbake.bake_probes(scene, cache=tmp_path / "cache")
    assert vol.irradiance.dtype == vol.distance.dtype == vol.data.dtype == np.float32
    assert vol.data.shape == (18, 4)
