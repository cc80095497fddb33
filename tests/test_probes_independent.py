"""Irradiance probes on scenes they were not built with (issue 59): the corpus interiors at a
uniform scale of 0.01 and 100 give the frame they give at scale 1 (no absolute epsilon), and a
room of quads of no thickness exported as glTF binary (.glb), wound the other way and single-sided
in its material as an exporter writes it by default, within 30% of the converged reference on
every region."""

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

import iblbake
from iblbake.io.gltf import glb_bytes
from iblbake.render import render

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "examples" / "corpus"


def corpus_doc(name, panoramas, panorama="studio"):
    """A corpus scene as a mapping, its paths absolute."""
    doc = yaml.safe_load((CORPUS / f"{name}.yaml").read_text())
    doc["environment"]["path"] = str(panoramas[panorama])
    for o in doc["objects"]:
        if "mesh" in o:
            o["mesh"]["path"] = str(CORPUS / o["mesh"]["path"])
    return doc


def scaled(doc, k):
    """The scene scaled uniformly by k about the origin: the camera, spheres, planes, meshes'
    transforms (the probes' box is automatic in the corpus)."""
    d = copy.deepcopy(doc)
    times = lambda v: [k * x for x in v]          # noqa: E731
    cam = d["camera"]["perspective"]
    cam["position"], cam["look_at"] = times(cam["position"]), times(cam["look_at"])
    for o in d["objects"]:
        if "sphere" in o:
            o["sphere"]["center"], o["sphere"]["radius"] = times(o["sphere"].get("center", [0, 0, 0])), k * o["sphere"]["radius"]
        if "mesh" in o:
            m = o["mesh"]
            s = m.get("scale", 1.0)
            m["translate"], m["scale"] = times(m.get("translate", [0, 0, 0])), times(s) if isinstance(s, list) else k * s
    return d


@pytest.mark.slow
@pytest.mark.parametrize("name", ["thin_wall", "l_room"])
def test_a_corpus_interior_gives_the_same_frame_at_any_scale(tmp_path, rt, panoramas, name):
    """Measured at the median's spacing: the probes' frame at scale 0.01 and 100 within 1e-6
    (thin_wall, l_room) and 1.3e-4 (corridor) relative RMSE of the frame at scale 1; at the
    nearer quarter's, within the bound below (thin_wall, l_room). At cells of the nearer quarter of the free
    distance, before the grid kept its probes off axis-aligned surfaces and relocation's ties
    held, thin_wall's layer of probes on its wall (0.9%) and l_room's probes oscillating to other
    places (4%) differed by scale, as float32 hits fell."""
    doc = corpus_doc(name, panoramas)
    doc["camera"]["resolution"] = [48, 36]
    doc["effects"] = {"diffuse": "probes", "specular": "off"}
    frames = [np.asarray(render(iblbake.load_scene(scaled(doc, k)), runtime=rt, cache_root=tmp_path / "cache")
                         .hdr[..., :3], np.float64) for k in (1.0, 0.01, 100.0)]
    for f in frames[1:]:
        assert np.sqrt(((f - frames[0]) ** 2).mean()) < 1e-3 * frames[0].mean()


def obj_to_glb(src: Path, dst: Path) -> str:
    """An OBJ of triangles as a .glb: positions and indices, each face wound the other way, a
    material single-sided (glTF's default) of the OBJ's grey."""
    v, f = [], []
    for ln in src.read_text().splitlines():
        p = ln.split()
        if p and p[0] == "v":
            v.append([float(x) for x in p[1:4]])
        if p and p[0] == "f":
            f.append([int(x.split("/")[0]) - 1 for x in p[1:4]][::-1])
    pos, idx = np.asarray(v, np.float32), np.asarray(f, np.uint32).ravel()
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
           "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1], "metallicFactor": 0}}],
           "buffers": [{"byteLength": pos.nbytes + idx.nbytes}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": pos.nbytes},
                           {"buffer": 0, "byteOffset": pos.nbytes, "byteLength": idx.nbytes}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3",
                          "min": pos.min(0).tolist(), "max": pos.max(0).tolist()},
                         {"bufferView": 1, "componentType": 5125, "count": len(idx), "type": "SCALAR"}]}
    dst.write_bytes(glb_bytes(doc, pos.tobytes() + idx.tobytes()))
    return str(dst)


@pytest.mark.external
@pytest.mark.slow
@pytest.mark.parametrize("panorama", ["studio", "city"])
def test_a_gltf_room_is_within_the_bound_of_the_truth(tmp_path, rt, panoramas, panorama):
    """The L room of the corpus (walls, floor and ceiling quads of no thickness) exported as .glb,
    wound the other way: default probes within 30% of the converged reference on every region
    (measured at 64 px under studio: walls x1.06, floor x1.03, ceiling x0.97, sphere x0.97)."""
    from iblbake.render.bakes import Bakes
    from iblbake.study import accuracy as acc, ladder
    from tests.helpers import MIN_PIXELS, REGION_BOUND, outside

    doc = corpus_doc("l_room", panoramas, panorama)
    for o in doc["objects"]:
        if "mesh" in o:
            src = Path(o["mesh"]["path"])
            o["mesh"]["path"] = obj_to_glb(src, tmp_path / f"{src.stem}.glb")
    (tmp_path / "l_room_glb.yaml").write_text(yaml.safe_dump(doc))
    settings = acc.Settings(max_side=40, repeats=1, target_noise=0.03, max_samples=256, flip=False)
    st = acc.Study(tmp_path / "l_room_glb.yaml", ["effects.specular=off"], settings, runtime=rt,
                   bakes=Bakes(tmp_path / "cache"))
    st.render_reference("diffuse")
    row = st.run_rung(next(r for r in ladder.realtime_ladder(st.scene, st.fx) if r.label == "probes"))
    judged = [e for e in row["region_absolute"].values() if e["pixels"] >= MIN_PIXELS]
    assert len(judged) == 4 and not outside(row["region_absolute"], REGION_BOUND), row["region_absolute"]
