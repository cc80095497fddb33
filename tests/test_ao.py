"""Ray-traced ambient occlusion (effects.ao: raytraced): 1 on an open plane, 1 - (R/h)^2 under a
floating sphere (the cosine-weighted share of the sky it hides), the kernel against the numpy
twin, and gating."""

import numpy as np
import pytest
import yaml

from iblbake.render import Bakes, Reuse, render
from iblbake.io import images
from iblbake.render import twin as rr
from iblbake.scene import load as scene
from iblbake.scene import pack

from tests.helpers import prefiltered_bakes


@pytest.fixture(scope="module")
def white(tmp_path_factory):
    p = tmp_path_factory.mktemp("white-ao") / "white.exr"
    images.write_exr(p, np.ones((32, 64, 3), np.float32))
    return p


def side_view(folder, env, sphere=None, effects=None, res=33):
    """A camera low over the plane looking at the origin: the centre pixel sees the point under
    the sphere (its line of sight passes below the sphere)."""
    doc = {"camera": {"perspective": {"position": [0, 0.2, 8], "look_at": [0, 0, 0], "fov_y": 20},
                      "resolution": [res, res]},
           "environment": {"path": str(env), "background": "hide"},
           "materials": {"floor": {"base_color": [0.7, 0.7, 0.7], "roughness": 1}},
           "objects": [{"plane": {"point": [0, 0, 0], "size": 100}, "material": "floor"}]
           + ([{"sphere": sphere, "material": "floor"}] if sphere else []),
           "effects": {"diffuse": "sh", "specular": "off", "ao": "raytraced", "ao_radius": 50, "ao_samples": 4096,
                       **(effects or {})}}
    p = folder / "scene.yaml"
    p.write_text(yaml.safe_dump(doc))
    return scene.load(p)


def test_open_plane_is_unoccluded(tmp_path, white):
    sc = side_view(tmp_path, white, effects={"ao_samples": 64})
    with_ao = render(sc, cache_root=tmp_path / "cache").hdr
    sc.data["effects"]["ao"] = "off"
    without = render(sc, cache_root=tmp_path / "cache").hdr
    hit = without[..., 3] == 1
    assert hit.sum() > 300 and np.array_equal(with_ao[hit], without[hit])


@pytest.mark.parametrize("h_over_r", [2.0, 4.0])
def test_ao_under_a_floating_sphere(tmp_path, white, h_over_r):
    """At the point beneath a sphere of radius R centred at height h, the sphere hides the cone
    of half angle asin(R/h) around the normal: cosine-weighted share (R/h)^2, AO = 1 - (R/h)^2
    (1e-3; measured within 1e-5 at 4096 rays: the issue asked for 1%)."""
    R = 0.5
    sc = side_view(tmp_path, white, sphere={"center": [0, h_over_r * R, 0], "radius": R})
    c = 16
    with_ball = render(sc, cache_root=tmp_path / "cache").hdr[c, c, :3]
    sc.data["objects"] = sc.data["objects"][:1]
    open_ = render(sc, cache_root=tmp_path / "cache").hdr[c, c, :3]
    ao = float((with_ball / open_).mean())
    print(f"h = {h_over_r} R: AO {ao:.7f} against {1 - 1 / h_over_r ** 2:.7f}")
    assert ao == pytest.approx(1 - 1 / h_over_r ** 2, rel=1e-3)


@pytest.mark.slow
def test_ao_matches_numpy(tmp_path, white):
    import trimesh
    mesh = tmp_path / "ico.ply"
    trimesh.creation.icosphere(subdivisions=2, radius=0.4).export(mesh)
    doc = {"camera": {"perspective": {"position": [0, 1.5, 3], "look_at": [0, 0, 0], "fov_y": 50},
                      "resolution": [48, 36]},
           "environment": {"path": str(white), "background": "hide"},
           "materials": {"a": {"base_color": [0.9, 0.6, 0.3], "roughness": 0.5},
                         "b": {"base_color": [0.8, 0.8, 0.8], "metallic": 1, "roughness": 0.3}},
           "objects": [{"sphere": {"center": [-0.6, 0.2, 0], "radius": 0.5}, "material": "b"},
                       {"mesh": {"path": str(mesh), "translate": [0.6, 0.1, 0]}, "material": "a"},
                       {"plane": {"point": [0, -0.3, 0], "size": 4}, "material": "a"}],
           "effects": {"diffuse": "sh", "specular": "prefiltered", "ao": "raytraced", "ao_radius": 1.0,
                       "ao_samples": 64, "prefilter": {"method": "fis", "samples": 64}}}
    p = tmp_path / "scene.yaml"
    p.write_text(yaml.safe_dump(doc))
    sc = scene.load(p)
    frame = render(sc, cache_root=tmp_path / "cache")
    arrays = pack.scene_arrays(sc)
    gb = rr.primary(sc["camera"], arrays)
    from iblbake.core import sh
    image = images.read_panorama(sc["environment"]["path"])[0]
    ao = rr.ambient_occlusion(gb, arrays, sc["effects"])
    assert ao[gb["hit"]].min() < 0.9 and ao[gb["hit"]].max() == 1.0     # both open and occluded samples
    want = rr.shade(gb, arrays, sc["effects"], sc["environment"], sh_coeffs=sh.project(image, 3) * sh.ahat(3)[:, None],
                    ao=ao, **prefiltered_bakes(frame))
    same = gb["hit"] & (frame.hdr[..., 3].reshape(-1) == 1)
    got = frame.hdr[..., :3].reshape(-1, 3)[same]
    rel = np.abs(got - want[same]) / np.maximum(np.abs(want[same]), 1e-3)
    print("AO shading against the twin: median", np.median(rel), "98%", np.quantile(rel, 0.98))
    # measured: median 8e-8, 98th percentile 2e-7
    assert np.median(rel) < 1e-6 and np.quantile(rel, 0.98) < 2e-6


def test_ao_gating(tmp_path, white):
    sc = side_view(tmp_path, white, effects={"ao": "off"})
    fr = render(sc, cache_root=tmp_path / "cache")
    assert "ao" not in fr.report["effects"]["passes"] and "HAS_AO" not in fr.report["effects"]["defines"]["shade"]
    sc = side_view(tmp_path, white, effects={"diffuse": "reference", "ao_samples": 4,
                                             "reference": {"max_samples": 4, "target_noise": 0}})
    fr = render(sc, cache_root=tmp_path / "cache")
    assert "ao" not in fr.report["effects"]["passes"]          # the reference traces true visibility


def test_a_series_switching_ao_on_reuses_safely(tmp_path, white):
    """Frames of one series (a sheet's cells: one runtime, Reuse) switching AO and AOVs on grow
    those buffers instead of writing past them: the second frame equals its own fresh render."""
    from iblbake.device.runtime import Runtime
    rt, bakes, reuse = Runtime(), Bakes(tmp_path / "cache"), Reuse()
    sc_off = side_view(tmp_path, white, effects={"ao": "off"}, res=48)
    render(sc_off, runtime=rt, cache=bakes, reuse=reuse)
    sc_on = side_view(tmp_path, white, sphere={"center": [0, 1.0, 0], "radius": 0.5},
                      effects={"ao_samples": 32}, res=48)
    sc_on.data["output"]["albedo"] = str(tmp_path / "a.exr")
    series = render(sc_on, runtime=rt, cache=bakes, reuse=reuse)
    fresh = render(sc_on, cache_root=tmp_path / "cache")
    assert np.array_equal(series.hdr, fresh.hdr) and np.array_equal(series.aovs["albedo"], fresh.aovs["albedo"])
