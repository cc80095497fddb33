"""Textured materials (glTF 2.0's metallic-roughness model): glTF files written by trimesh's
exporter (and edited where it has no option: TEXCOORD_1, KHR_texture_transform, samplers) and
scene materials with maps, rendered and checked against closed forms and hand-computed pixels:
- constant textures equal the factor-only material, the sRGB decode equals IEC 61966-2-1;
- a flat normal map changes nothing, a tilted one moves the highlight where reflection puts it;
- a checkerboard plane at grazing angles: no aliasing (high-frequency energy and the mean), and
  the mip level equals the footprint formula;
- KHR_texture_transform, the wrap modes and TEXCOORD_1 against hand-computed texels;
- alpha MASK cut-outs: the background shows through, coverage equals the mask's area;
- tangents: a mirrored UV layout keeps the normal map's directions (w = -1);
- the kernels against their numpy twin with every map; an untextured scene compiles no texture code;
- bad input: a missing image, a too-large texture, a textured material without UVs, BLEND."""

import base64
import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from iblbake.io import images
from iblbake.io.color import srgb_decode
from iblbake.render import frame as render
from iblbake.render import twin as rr
from iblbake.scene import load as scene
from iblbake.scene import pack

from tests.helpers import (QUAD_F, QUAD_UV, QUAD_V, mend_cache_entry, quad_glb, run_cli,
                           scene_file as write_scene_file, write_exr)

def png(path, rgba, bits=8):
    """A PNG through OpenImageIO (8 or 16 bits per channel)."""
    import OpenImageIO as oiio
    a = np.asarray(rgba)
    h, w, c = a.shape
    spec = oiio.ImageSpec(w, h, c, oiio.UINT8 if bits == 8 else oiio.UINT16)
    o = oiio.ImageOutput.create(str(path))
    px = np.ascontiguousarray(a.astype(np.uint8 if bits == 8 else np.uint16))
    assert o.open(str(path), spec) and o.write_image(px), o.geterror()
    o.close()
    return str(path)


def flat_env(folder, value=(0.5, 0.5, 0.5), spot=None, size=256):
    """A constant panorama (size x size/2), with an optional bright disk (direction, radius in
    degrees, value)."""
    from iblbake.core import conventions
    d = conventions.equirect_texel_dirs(size, size // 2)
    img = np.broadcast_to(np.asarray(value, np.float32), d.shape).copy()
    if spot is not None:
        a = np.asarray(spot[0], float) / np.linalg.norm(spot[0])
        img[(d @ a) > math.cos(math.radians(spot[1]))] = spot[2]
    return write_exr(Path(folder) / "env.exr", img)


def scene_file(folder, materials, objects, *, camera=None, effects=None, env=None, background="hide", res=(64, 64)):
    camera = dict(camera or {"orthographic": {"position": [0, 0, 3], "look_at": [0, 0, 0], "width": 2}})
    camera.setdefault("resolution", list(res))
    return write_scene_file(folder, env or flat_env(folder), materials=materials, objects=objects, camera=camera,
                            environment={"background": background}, effects={"tonemap": "linear", **(effects or {})})


def render_scene(path, cache, aovs=(), **load_kw):
    sc = scene.load(path, **load_kw)
    for a in aovs:
        sc.data["output"][a] = str(Path(path).parent / f"{a}.exr")
    return sc, render.render(sc, cache_root=cache)


EMISSIVE_ONLY = {"diffuse": "off", "specular": "off"}


# --- values --------------------------------------------------------------------------------------

@pytest.mark.slow
def test_constant_texture_equals_the_factor(tmp_path):
    """A constant base colour map (8-bit sRGB) times a factor equals the material whose factor is
    their product, through SH diffuse and prefiltered specular: 1e-6 of the peak (measured 1.3e-7;
    float32 texels hold the decoded value exactly)."""
    tex = png(tmp_path / "c.png", np.broadcast_to([200, 120, 40, 255], (8, 8, 4)))
    lin = srgb_decode(np.array([200, 120, 40]) / 255.0)
    factor = [0.9, 0.5, 1.0]
    mesh = quad_glb(tmp_path / "q.glb")
    objs = [{"mesh": {"path": mesh}, "material": "m"}]
    fx = {"diffuse": "sh", "specular": "prefiltered"}
    env = flat_env(tmp_path, (0.3, 0.6, 0.9), spot=([0.3, 0.4, 1.0], 10, 20.0))
    a = scene_file(tmp_path, {"m": {"base_color": factor, "roughness": 0.4, "base_color_map": {"path": tex}}}, objs,
                   effects=fx, env=env)
    _, fa = render_scene(a, tmp_path / "cache")
    b = scene_file(tmp_path, {"m": {"base_color": (np.float32(lin) * np.float32(factor)).tolist(), "roughness": 0.4}},
                   objs, effects=fx, env=env)
    _, fb = render_scene(b, tmp_path / "cache")
    rel = np.abs(fa.hdr[..., :3] - fb.hdr[..., :3]) / np.abs(fb.hdr[..., :3]).max()
    assert fa.hdr[..., 3].min() == 1 and rel.max() < 1e-6, rel.max()


def test_cached_textures_follow_their_material_wherever_it_stands(tmp_path):
    """The textures' cache entry is keyed by the maps' content, not by the index of the material
    that holds them: a plain material put before the textured one (another scene, the same maps)
    reuses the entry and gets the same frame as a fresh cache (it failed with a KeyError, and could
    have given a map to the wrong material)."""
    tex = png(tmp_path / "c.png", np.broadcast_to([200, 40, 30, 255], (8, 8, 4)))
    mesh = quad_glb(tmp_path / "q.glb")
    quad = {"mesh": {"path": mesh}, "material": "t"}
    ball = {"sphere": {"center": [0.6, 0.6, 0.5], "radius": 0.3}, "material": "p"}
    textured = {"base_color": [1, 1, 1], "roughness": 0.6, "base_color_map": {"path": tex}}
    plain = {"base_color": [0.2, 0.8, 0.3], "roughness": 0.6}
    fx = {"diffuse": "sh", "specular": "prefiltered"}
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    first = scene_file(tmp_path / "a", {"t": textured}, [quad], effects=fx, res=(32, 32))
    then = scene_file(tmp_path / "b", {"p": plain, "t": textured}, [ball, quad], effects=fx, res=(32, 32))
    _, fa = render_scene(first, tmp_path / "cache")
    _, fb = render_scene(then, tmp_path / "cache")
    _, fresh = render_scene(then, tmp_path / "fresh")
    assert np.array_equal(fb.hdr, fresh.hdr)
    corner = fb.hdr[4, 4, :3]                    # the quad alone: the map's red, as in the first scene
    assert corner[0] > 3 * corner[1] and np.array_equal(corner, fa.hdr[4, 4, :3]), corner
    assert [b["cached"] for b in fb.report["bakes"] if b["name"] == "textures"] == [True]


@pytest.mark.parametrize("mend", ["slot out of range", "slots missing", "level past the texels", "texels of ints"])
def test_a_cached_textures_entry_that_does_not_read_back_is_baked_again(tmp_path, mend):
    """A textures entry whose files match its manifest but not what the kernels will index (another
    version's, or a hand's): said in one warning naming it, baked again, and the frame is the
    fresh cache's (before, a slot out of range was read as a texture)."""
    tex = png(tmp_path / "c.png", np.broadcast_to([200, 40, 30, 255], (8, 8, 4)))
    p = scene_file(tmp_path, {"t": {"base_color": [1, 1, 1], "base_color_map": {"path": tex}}},
                   [{"mesh": {"path": quad_glb(tmp_path / "q.glb")}, "material": "t"}], res=(16, 16))
    _, want = render_scene(p, tmp_path / "cache")
    entry = next(e for e in (tmp_path / "cache").iterdir() if e.name.startswith("textures-"))
    if mend == "slot out of range":
        mend_cache_entry(entry, lambda m: m.update(slots=[7]))
    elif mend == "slots missing":
        mend_cache_entry(entry, lambda m: m.pop("slots"))
    elif mend == "level past the texels":
        levels = np.load(entry / "tex_levels.npy")
        levels[:, 2] += 1000
        mend_cache_entry(entry, tex_levels=levels)
    else:
        mend_cache_entry(entry, texels=np.load(entry / "texels.npy").astype(np.int32))
    said = []
    got = render.render(scene.load(p), cache_root=tmp_path / "cache", warn=said.append)
    again = [w for w in said if "baking it again" in w]
    assert len(again) == 1 and entry.name in again[0], said
    assert np.array_equal(got.hdr, want.hdr)


def test_srgb_decode_is_the_formula(tmp_path):
    """Every 8-bit code of a base colour map, read back as the albedo AOV (nearest texel,
    magnified): IEC 61966-2-1's decode to 1e-6 (measured 1.6e-7, float32)."""
    codes = np.arange(256).reshape(16, 16)
    tex = png(tmp_path / "ramp.png", np.stack([codes, codes[::-1], codes.T, np.full_like(codes, 255)], -1))
    mesh = quad_glb(tmp_path / "q.glb")
    p = scene_file(tmp_path, {"m": {"base_color": [1, 1, 1], "base_color_map": {"path": tex, "filter": "nearest"}}},
                   [{"mesh": {"path": mesh}, "material": "m"}], effects=EMISSIVE_ONLY, res=(64, 64))
    _, fr = render_scene(p, tmp_path / "cache", aovs=("albedo",))
    got = fr.aovs["albedo"][2::4, 2::4, :3]                          # one pixel inside each texel
    c = np.arange(256).reshape(16, 16) / 255.0
    x = np.stack([c, c[::-1], c.T], -1)
    want = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    assert np.abs(got - want).max() < 1e-6


@pytest.mark.slow
def test_flat_normal_map_changes_nothing(tmp_path):
    """A flat normal map changes nothing: at scale 0 (exactly (0, 0, 1)) the frame of a glossy metal
    quad under a lit sky in perspective equals the frame without the map to 1e-6 of its peak
    (measured: equal); a
    16-bit (32768, 32768, 65535) map, which decodes to x = y = 1/65535, tilts the normal AOV by
    that and no more (2.2e-5 rad; the frame then moves by the sky's gradient times the tilt)."""
    flat = png(tmp_path / "flat.png", np.broadcast_to([32768, 32768, 65535], (4, 4, 3)), bits=16)
    mesh = quad_glb(tmp_path / "q.glb")
    cam = {"perspective": {"position": [0.3, 0.5, 2.5], "look_at": [0, 0, 0], "fov_y": 50}}
    env = flat_env(tmp_path, (0.3, 0.6, 0.9), spot=([0.2, 0.3, 1.0], 15, 10.0))
    mat = {"base_color": [0.9, 0.8, 0.7], "metallic": 1, "roughness": 0.3}
    frames, normals, cover = [], [], None
    for extra in ({}, {"normal_map": {"path": flat, "scale": 0.0}}, {"normal_map": {"path": flat}}):
        p = scene_file(tmp_path, {"m": {**mat, **extra}}, [{"mesh": {"path": mesh}, "material": "m"}], camera=cam,
                       env=env, effects={"diffuse": "sh", "specular": "prefiltered"})
        _, fr = render_scene(p, tmp_path / "cache", aovs=("normal",))
        frames.append(fr.hdr[..., :3])
        normals.append(fr.aovs["normal"][..., :3].astype(np.float64))
        cover = fr.hdr[..., 3] == 1
    assert np.abs(frames[0] - frames[1]).max() / frames[0].max() < 1e-6
    tilt = np.linalg.norm(np.cross(normals[0], normals[2]), axis=-1)[cover]      # sin of the angle
    assert cover.sum() > 1000 and np.abs(tilt - math.sqrt(2) / 65535).max() < 3e-6, (tilt.min(), tilt.max())


def highlight_pixel(spot, normal, cam_pos, fov_y, res):
    """Where a perspective camera sees the mirror reflection of direction `spot` on the plane z = 0
    of normal `normal`: the ray to it is reflect(spot)."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    s = np.asarray(spot, float) / np.linalg.norm(spot)
    d = -(s - 2 * (s @ n) * n)                                       # from the camera to the point
    c = np.asarray(cam_pos, float)
    p = c + d * (-c[2] / d[2])
    fwd = -c / np.linalg.norm(c)
    right = np.cross(fwd, [0, 1, 0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    v = p - c
    hh = math.tan(math.radians(fov_y) / 2)
    x, y = (v @ right) / (v @ fwd) / (hh * res[0] / res[1]), (v @ up) / (v @ fwd) / hh
    return (x + 1) / 2 * res[0], (1 - y) / 2 * res[1]


@pytest.mark.slow
def test_tilted_normal_map_moves_the_highlight(tmp_path):
    """A constant normal map tilted 20 degrees towards +u (the quad's +x): the mirror-like highlight of
    a small bright disk moves to where reflection about the tilted normal puts it, within half a
    pixel (measured 0.05 px; 0.13 px without the map, where the plain normal puts it)."""
    res = (160, 160)
    cam_pos, fov = [0.0, 0.0, 3.0], 50
    spot = [0.35, 0.25, 1.0]
    env = flat_env(tmp_path, (0.02, 0.02, 0.02), spot=(spot, 1.5, 2000.0), size=2048)
    mesh = quad_glb(tmp_path / "q.glb", vertices=QUAD_V * 2)
    cam = {"perspective": {"position": cam_pos, "look_at": [0, 0, 0], "fov_y": fov}}
    a = math.radians(20)
    code = np.round((np.array([math.sin(a), 0.0, math.cos(a)]) + 1) / 2 * 65535)
    tilted = png(tmp_path / "tilt.png", np.broadcast_to(code, (4, 4, 3)), bits=16)
    n_tilt = code / 65535 * 2 - 1
    for tex, normal in ((None, [0, 0, 1]), (tilted, n_tilt / np.linalg.norm(n_tilt))):
        mat = {"base_color": [1, 1, 1], "metallic": 1, "roughness": 0.02}
        if tex:
            mat["normal_map"] = {"path": tex}
        p = scene_file(tmp_path, {"m": mat}, [{"mesh": {"path": mesh}, "material": "m"}], camera=cam, env=env,
                       effects={"diffuse": "off", "specular": "prefiltered",
                                "prefilter": {"dominant_direction": False}}, res=res)
        _, fr = render_scene(p, tmp_path / "cache")
        y = fr.hdr[..., :3].sum(-1)
        w = np.where(y > 0.5 * y.max(), y, 0)
        jj, ii = np.indices(y.shape)
        got = ((w * (ii + 0.5)).sum() / w.sum(), (w * (jj + 0.5)).sum() / w.sum())
        want = highlight_pixel(spot, normal, cam_pos, fov, res)
        assert math.dist(got, want) < 0.5, (got, want, normal)


def test_mirrored_uvs_keep_the_normal_maps_directions(tmp_path):
    """Two quads side by side, the right one's UVs mirrored in u (trimesh writes no tangents: they
    are generated, w = -1 there). A normal map tilted up the image (+y, green) tilts both quads'
    normals to +y; one tilted along +u tilts the left quad to +x and the mirrored one to -x. Read
    back as the normal AOV."""
    v = np.concatenate([QUAD_V * [0.5, 1, 1] - [0.5, 0, 0], QUAD_V * [0.5, 1, 1] + [0.5, 0, 0]])
    f = np.concatenate([QUAD_F, QUAD_F + 4])
    uv = np.concatenate([QUAD_UV, QUAD_UV * [-1, 1] + [1, 0]])
    s = math.sin(math.radians(30))
    for tn, left_dir, right_dir in (((0.0, s), (0, 1), (0, 1)), ((s, 0.0), (1, 0), (-1, 0))):
        code = np.round((np.array([tn[0], tn[1], math.sqrt(1 - s * s)]) + 1) / 2 * 255)
        mesh = quad_glb(tmp_path / "q.glb", vertices=v, faces=f, uv=uv,
                        normal=np.broadcast_to(code, (4, 4, 3)).astype(np.uint8))
        p = scene_file(tmp_path, {}, [{"mesh": {"path": mesh}}], effects=EMISSIVE_ONLY, res=(64, 32),
                       camera={"orthographic": {"position": [0, 0, 3], "look_at": [0, 0, 0], "width": 2}})
        _, fr = render_scene(p, tmp_path / "cache", aovs=("normal",))
        nrm = fr.aovs["normal"][..., :3]
        for half, want in ((nrm[:, :32], left_dir), (nrm[:, 32:], right_dir)):
            m = half.reshape(-1, 3).mean(0)
            # an 8-bit 128 decodes to 1/255 (glTF's 2c - 1): "zero" is 0.004
            assert np.sign(m[0]) == np.sign(want[0]) if want[0] else abs(m[0]) < 0.005, (tn, m)
            assert np.sign(m[1]) == np.sign(want[1]) if want[1] else abs(m[1]) < 0.005, (tn, m)
            assert abs(math.hypot(m[0], m[1]) - s) < 0.01 and m[2] > 0.8, (tn, m)


# --- filtering ---------------------------------------------------------------------------------

def grazing_checker(tmp_path, min_filter, res=(192, 96)):
    """A 400 x 400 ground (a glTF quad, UVs one per unit, repeating) of an emissive checkerboard
    of half-unit squares (256 texels a unit), seen from 0.5 above it towards the horizon: rows near
    the horizon see it 10 to 400 units away, minified 30x to 1000x."""
    i, j = np.indices((256, 256))
    c = (((i // 128) + (j // 128)) % 2) * 255
    ground = np.array([[-200, 0, 200], [200, 0, 200], [200, 0, -200], [-200, 0, -200]], float)
    uv = (ground[:, [0, 2]] + 200) * [1, 1]

    def sampler(doc):
        doc["samplers"] = [{"magFilter": 9729, "minFilter": min_filter}]
        doc["textures"][0]["sampler"] = 0
    mesh = quad_glb(tmp_path / "ground.glb", emissive=np.stack([c, c, c], -1).astype(np.uint8), vertices=ground,
                    uv=uv, emissiveFactor=[1, 1, 1], baseColorFactor=[0, 0, 0, 1], doubleSided=True, edit=sampler)
    p = scene_file(tmp_path, {}, [{"mesh": {"path": mesh}}], effects=EMISSIVE_ONLY, res=res,
                   camera={"perspective": {"position": [0.3, 0.5, 0], "look_at": [0.3, 0.35, -3], "fov_y": 40}})
    return render_scene(p, tmp_path / "cache", aovs=("depth",))[1]


def high_frequency_energy(img):
    """The image's variance (mean removed) at spatial frequencies above half the Nyquist band
    (|f| > 0.25 cycles per pixel along x or y), per pixel."""
    a = img - img.mean()
    f = np.abs(np.fft.fft2(a)) ** 2 / a.size ** 2
    fy, fx = np.meshgrid(np.fft.fftfreq(a.shape[0]), np.fft.fftfreq(a.shape[1]), indexing="ij")
    return float(f[(np.abs(fx) > 0.25) | (np.abs(fy) > 0.25)].sum())


def test_grazing_checkerboard_does_not_alias(tmp_path):
    """Trilinear filtering from the ray cone's footprint: in the rows whose every pixel sees the
    ground 10 units away or more, the frame is the checkerboard's mean, 0.5, within 1%, and its
    energy above half the Nyquist band is under 1e-4 of the checkerboard's variance (0.25)
    (measured: the mean exactly, no such energy: the footprint reaches a level of one grey texel).
    The same ground without mipmaps (minFilter LINEAR) aliases: 0.16 lands there (65% of it)."""
    fr = grazing_checker(tmp_path, 9987)
    rows = np.flatnonzero((fr.hdr[..., 3].min(axis=1) == 1) & (fr.aovs["depth"].min(axis=1) > 10))
    y = fr.hdr[rows, :, 0].astype(np.float64)
    assert len(rows) >= 5 and abs(y.mean() - 0.5) < 0.005, (len(rows), y.mean())
    assert high_frequency_energy(y) < 1e-4 * 0.25, high_frequency_energy(y)
    aliased = grazing_checker(tmp_path, 9729).hdr[rows, :, 0].astype(np.float64)
    assert high_frequency_energy(aliased) > 0.25 * 0.25, high_frequency_energy(aliased)


def test_mip_level_is_the_footprint(tmp_path):
    """A 1-texel checker (level 0 alternates 0 and 1, every coarser level is 0.5) read with
    NEAREST_MIPMAP_LINEAR: a texel of 1 shows 1 - lod / 2, so lod is read back from the pixels. A
    quad 2 units wide seen orthographically at tilt theta, each of 96 pixels 2/96 wide: the
    footprint is (2/96) / cos(theta) world units of 128/2 texels each, lod = log2(128 / 96 /
    cos(theta)); at 0, 30 and 45 degrees (levels 0.42, 0.62, 0.91): within 1e-4 (measured 1.2e-7)."""
    i, j = np.indices((128, 128))
    c = ((i + j) % 2) * 255
    def sampler(doc):
        doc["samplers"] = [{"magFilter": 9728, "minFilter": 9986}]
        doc["textures"][0]["sampler"] = 0
    mesh = quad_glb(tmp_path / "q.glb", emissive=np.stack([c, c, c], -1).astype(np.uint8), emissiveFactor=[1, 1, 1],
                    baseColorFactor=[0, 0, 0, 1], edit=sampler)
    for theta in (0.0, 30.0, 45.0):
        p = scene_file(tmp_path, {}, [{"mesh": {"path": mesh, "rotate": [0, theta, 0]}}], effects=EMISSIVE_ONLY,
                       res=(96, 96))
        _, fr = render_scene(p, tmp_path / "cache")
        y = fr.hdr[..., 0]
        ones = y[y > 0.5]
        lod = 2 * (1 - ones)
        want = math.log2(128 / 96 / math.cos(math.radians(theta)))
        assert len(ones) > 100 and np.abs(lod - want).max() < 1e-4, (theta, np.median(lod), want)


# --- coordinates ---------------------------------------------------------------------------------

@pytest.mark.slow         # over 5 s: make test runs it, make check is the fast loop
def test_texture_transform_wrap_and_texcoord1_hand_computed(tmp_path):
    """An 8 x 8 texture of distinct texels, magnified with nearest filtering, on the quad (pixel
    (i, j) at uv ((i + 0.5) / 64, (j + 0.5) / 64)): each pixel equals the texel a hand-computed
    uv' = T R S uv (KHR_texture_transform: offset, rotation, scale), through each wrap mode, and
    through TEXCOORD_1 (uv1 = uv / 2 + 0.25, selected by the extension's texCoord)."""
    rng = np.random.default_rng(5)
    codes = rng.integers(0, 256, (8, 8, 3))
    lin = srgb_decode(codes / 255.0)
    uv1 = QUAD_UV / 2 + 0.25
    px = (np.arange(64) + 0.5) / 64
    uu, vv = np.meshgrid(px, px)

    def expect(u, v, wrap):
        def w(x):
            k = np.floor(x * 8).astype(int)
            if wrap == 10497:
                return np.mod(k, 8)
            if wrap == 33071:
                return np.clip(k, 0, 7)
            k = np.mod(k, 16)
            return np.where(k < 8, k, 15 - k)
        return lin[w(v), w(u)]

    for wrap in (10497, 33071, 33648):
        for offset, rot, scale, texcoord in (([0.25, -0.5], 0.0, [2.0, 3.0], 0), ([0.1, 0.2], 0.7, [1.5, 0.5], 0),
                                             ([0.0, 0.0], 0.0, [1.0, 1.0], 1), ([0.3, 0.0], 1.2, [2.5, 2.5], 1)):
            def edit(doc, offset=offset, rot=rot, scale=scale, texcoord=texcoord, wrap=wrap):
                doc["samplers"] = [{"magFilter": 9728, "minFilter": 9728, "wrapS": wrap, "wrapT": wrap}]
                doc["textures"][0]["sampler"] = 0
                info = doc["materials"][0]["emissiveTexture"]
                info["extensions"] = {"KHR_texture_transform": {"offset": offset, "rotation": rot, "scale": scale,
                                                                "texCoord": texcoord}}
                doc["extensionsUsed"] = ["KHR_texture_transform"]
            mesh = quad_glb(tmp_path / "q.glb", emissive=codes.astype(np.uint8), emissiveFactor=[1, 1, 1],
                            baseColorFactor=[0, 0, 0, 1], uv1=uv1, edit=edit)
            p = scene_file(tmp_path, {}, [{"mesh": {"path": mesh}}], effects=EMISSIVE_ONLY, res=(64, 64))
            _, fr = render_scene(p, tmp_path / "cache")
            u, v = (uu / 2 + 0.25, vv / 2 + 0.25) if texcoord else (uu, vv)
            c, s_ = math.cos(rot), math.sin(rot)
            tu = c * scale[0] * u - s_ * scale[1] * v + offset[0]
            tv = s_ * scale[0] * u + c * scale[1] * v + offset[1]
            want = expect(tu, tv, wrap)
            # a texel edge through a pixel centre may round either way in float32
            edge = (np.abs(tu * 8 - np.round(tu * 8)) < 1e-4) | (np.abs(tv * 8 - np.round(tv * 8)) < 1e-4)
            bad = (np.abs(fr.hdr[..., :3] - want).max(-1) > 1e-6) & ~edge
            assert not bad.any(), (wrap, offset, rot, scale, texcoord, int(bad.sum()))


@pytest.mark.slow
def test_alpha_mask_cuts_out(tmp_path):
    """A base colour map whose alpha is a disk of radius 0.35 (of the texture's width), MASK with
    cutoff 0.5 (trimesh writes alphaMode and alphaCutoff): outside it the background colour shows
    exactly, and the quad's coverage is the disk's area, pi 0.35^2, within 0.5% (measured 0.2%: the
    frame's pixels sample the disk's edge)."""
    n = 512
    j, i = np.indices((n, n))
    r = np.hypot((i + 0.5) / n - 0.5, (j + 0.5) / n - 0.5)
    rgba = np.stack([np.full((n, n), 200), np.full((n, n), 80), np.full((n, n), 40), (r < 0.35) * 255], -1)
    mesh = quad_glb(tmp_path / "q.glb", base=rgba.astype(np.uint8), alphaMode="MASK", alphaCutoff=0.5,
                    metallicFactor=0.0, roughnessFactor=0.6)
    p = scene_file(tmp_path, {}, [{"mesh": {"path": mesh}}], background=[0.25, 0.5, 0.75], res=(200, 200))
    _, fr = render_scene(p, tmp_path / "cache")
    cover = fr.hdr[..., 3]
    assert abs(cover.mean() - math.pi * 0.35 ** 2) < 0.005 * math.pi * 0.35 ** 2, cover.mean()
    out = cover == 0
    assert np.abs(fr.hdr[..., :3][out] - [0.25, 0.5, 0.75]).max() < 1e-6


# --- the kernels, their twin, gating ----------------------------------------------------------------

def five_map_scene(tmp_path, res=(96, 64)):
    """A glTF quad and a scene-material sphere and plane with all five maps, in perspective."""
    rng = np.random.default_rng(9)
    smooth = lambda k: np.kron(rng.integers(40, 255, (8, 8, k)), np.ones((16, 16, 1)))
    nrm = np.stack([rng.integers(90, 166, (16, 16)), rng.integers(90, 166, (16, 16)), np.full((16, 16), 230)], -1)
    nrm = np.kron(nrm, np.ones((8, 8, 1)))
    files = {k: png(tmp_path / f"{k}.png", a) for k, a in
             (("base", np.concatenate([smooth(3), np.full((128, 128, 1), 255)], -1)), ("mr", smooth(3)),
              ("normal", nrm), ("occ", smooth(3)), ("emis", smooth(3) // 4))}
    from PIL import Image
    ims = {k: np.asarray(Image.open(v)) for k, v in files.items()}
    mesh = quad_glb(tmp_path / "q.glb", base=ims["base"], mr=ims["mr"], normal=ims["normal"], occlusion=ims["occ"],
                    emissive=ims["emis"], emissiveFactor=[0.5, 0.5, 0.5], metallicFactor=0.8, roughnessFactor=0.9)
    maps = {"base_color_map": {"path": files["base"], "uv_scale": [2, 2]}, "metallic_roughness_map": {"path": files["mr"]},
            "normal_map": {"path": files["normal"], "scale": 0.7}, "occlusion_map": {"path": files["occ"], "strength": 0.8},
            "emissive_map": {"path": files["emis"], "wrap": "mirror", "uv_rotation": 30}}
    mats = {"s": {"base_color": [0.9, 0.9, 0.9], "metallic": 0.5, "roughness": 0.7, "emissive": [0.2, 0.1, 0.1], **maps}}
    objs = [{"mesh": {"path": mesh, "translate": [0.9, 0, 0], "rotate": [0, -30, 0], "scale": 0.8}},
            {"sphere": {"center": [-0.8, 0, 0], "radius": 0.6}, "material": "s"},
            {"plane": {"point": [0, -0.7, 0], "size": [5, 3]}, "material": "s"}]
    env = flat_env(tmp_path, (0.3, 0.5, 0.8), spot=([0.4, 0.6, 0.8], 20, 8.0))
    cam = {"perspective": {"position": [0, 0.6, 3.2], "look_at": [0, -0.1, 0], "fov_y": 45}, "spp": 2}
    return scene_file(tmp_path, mats, objs, camera=cam, env=env, res=res,
                      effects={"diffuse": "sh", "specular": "prefiltered"})


@pytest.mark.slow
def test_textured_kernels_match_their_twin(tmp_path):
    """Every map kind on a glTF quad (the file's material), a sphere and a finite plane (a scene
    material with a transform and mirrored wrap): the kernel's albedo and normal AOVs and its
    SH-diffuse + split-sum frame against the float64 twin (twin.primary, gbuffer_coords,
    resolve_materials, shade): albedo median 4e-8, 98% within 1.4e-6; frame median 2.5e-7, 98%
    within 4.5e-6 relative (measured; bounds 4x)."""
    from iblbake.bake.dfg import dfg_twin
    from iblbake.core import sh

    sc, fr = render_scene(five_map_scene(tmp_path), tmp_path / "cache", aovs=("albedo", "normal"))
    arrays = pack.scene_arrays(sc)
    tex = rr.textures(sc, arrays)
    gb = rr.primary(sc["camera"], arrays, tex)
    rr.gbuffer_coords(gb, arrays, sc["camera"])
    rr.resolve_materials(gb, arrays, tex)
    w, h = sc["camera"]["resolution"]
    full = (fr.hdr[..., 3] == 1) & gb["hit"].reshape(h, w, 2).all(2)
    base, _m, _e, _r, nrm, _o = gb["resolved"]
    alb = np.zeros((len(gb["hit"]), 3))
    alb[gb["hit"]] = base
    got = fr.aovs["albedo"][..., :3][full]
    want = alb.reshape(h, w, 2, 3).mean(2)[full]
    err = np.abs(got - want)
    assert np.median(err) < 2e-7 and np.quantile(err, 0.98) < 6e-6, (np.median(err), np.quantile(err, 0.98))
    image = images.read_panorama(sc["environment"]["path"])[0]
    rep = {b["name"]: b for b in fr.report["bakes"]}
    entry = Path(rep["prefiltered"]["entry"])
    man = json.loads((entry / "manifest.json").read_text())
    pre = [images.read_exr(entry / f["name"])[..., :3].astype(np.float64) for f in man["files"]]
    dfg = images.read_exr(Path(rep["dfg"]["entry"]) / "dfg.exr")[..., :2].astype(np.float64)
    ref = rr.shade(gb, arrays, sc["effects"], sc["environment"], sh_coeffs=sh.project(image, 3) * sh.ahat(3)[:, None],
                   prefiltered=pre, dfg=dfg).reshape(h, w, 2, 3).mean(2)
    rel = np.abs(fr.hdr[..., :3][full] - ref[full]) / np.maximum(np.abs(ref[full]), 1e-3)
    assert np.median(rel) < 1e-6 and np.quantile(rel, 0.98) < 2e-5, (np.median(rel), np.quantile(rel, 0.98))
    assert full.sum() > 2000


@pytest.mark.slow
def test_untextured_scene_compiles_no_texture_code(tmp_path):
    mesh = quad_glb(tmp_path / "q.glb")
    p = scene_file(tmp_path, {"m": {"base_color": [0.5, 0.5, 0.5]}}, [{"mesh": {"path": mesh}, "material": "m"}])
    sc, fr = render_scene(p, tmp_path / "cache")
    defines = {k for d in fr.report["effects"]["defines"].values() for k in d}
    built = {k for b in fr.report["kernel_builds"] for k in b["defines"]}
    textured = {"HAS_TEXTURES", "HAS_ALPHA_MASK", "HAS_SINGLE_SIDED"} | {f"HAS_{k}_MAP" for k in
                                                                         ("BASE_COLOR", "METALLIC_ROUGHNESS", "NORMAL",
                                                                          "OCCLUSION", "EMISSIVE")}
    assert not (defines | built) & textured and "material" not in fr.report["effects"]["passes"]
    assert not any(b["name"] == "textures" for b in fr.report["bakes"])
    # the file's own (textured, single-sided) material: only the defines it needs
    mesh = quad_glb(tmp_path / "t.glb", base=np.full((4, 4, 3), 128, np.uint8))
    p = scene_file(tmp_path, {}, [{"mesh": {"path": mesh}}])
    _, fr = render_scene(p, tmp_path / "cache")
    defines = {k for d in fr.report["effects"]["defines"].values() for k in d}
    assert defines & textured == {"HAS_TEXTURES", "HAS_BASE_COLOR_MAP", "HAS_SINGLE_SIDED"}


@pytest.mark.external
def test_real_textured_model(tmp_path):
    """assimp-testmodels' BoxTextured (the Khronos sample: a GLB with an embedded PNG), its own
    material: the albedo AOV is the texture, the kernel's equal to the twin's within 2e-6 (measured
    4e-7 at most)."""
    model = Path(__file__).parent / "data" / "assimp" / "glTF2" / "BoxTextured-glTF-Binary" / "BoxTextured.glb"
    if not model.is_file():
        pytest.fail(f"{model} missing: run `make testmodels`")
    cam = {"perspective": {"position": [1.2, 1.0, 1.6], "look_at": [0, 0, 0], "fov_y": 45}}
    p = scene_file(tmp_path, {}, [{"mesh": {"path": str(model)}}], camera=cam, res=(64, 64))
    sc, fr = render_scene(p, tmp_path / "cache", aovs=("albedo",))
    arrays = pack.scene_arrays(sc)
    tex = rr.textures(sc, arrays)
    gb = rr.primary(sc["camera"], arrays, tex)
    rr.gbuffer_coords(gb, arrays, sc["camera"])
    rr.resolve_materials(gb, arrays, tex)
    alb = np.zeros((len(gb["hit"]), 3))
    alb[gb["hit"]] = gb["resolved"][0]
    both = (fr.hdr[..., 3] == 1) & gb["hit"].reshape(64, 64)
    got = fr.aovs["albedo"][..., :3]
    assert both.sum() > 800 and got[both].std(axis=0).min() > 0.05        # the texture, not a constant
    assert np.abs(got[both] - alb.reshape(64, 64, 3)[both]).max() < 2e-6


# --- bad input -------------------------------------------------------------------------------------

def test_missing_image_names_file_material_and_uri(tmp_path):
    mesh = quad_glb(tmp_path / "q.glb", base=np.full((4, 4, 3), 100, np.uint8))
    gltf_path = tmp_path / "ext.gltf"
    data = Path(mesh).read_bytes()
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + n])
    binary = data[20 + n + 8:]
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
    doc["images"] = [{"uri": "textures/wood%20grain.png"}]
    doc["materials"][0]["name"] = "Oak"
    gltf_path.write_text(json.dumps(doc))
    p = scene_file(tmp_path, {}, [{"mesh": {"path": str(gltf_path)}}])
    r = run_cli("render", p, "-o", tmp_path / "x.png")
    err = r.stderr.strip()
    assert r.returncode == 1 and len(err.splitlines()) == 1 and "Traceback" not in err
    assert "ext.gltf" in err and "Oak" in err and "textures/wood%20grain.png" in err, err
    assert not (tmp_path / "x.png").exists()


def test_texture_limits_and_formats(tmp_path):
    """A texture over --max-texture-pixels is refused from its header; a non-power-of-two and a
    16-bit PNG load with their values (nearest, magnified: 1e-6)."""
    big = png(tmp_path / "big.png", np.zeros((300, 500, 3)))
    mesh = quad_glb(tmp_path / "q.glb")
    p = scene_file(tmp_path, {"m": {"base_color_map": {"path": big}}}, [{"mesh": {"path": mesh}, "material": "m"}])
    r = run_cli("render", p, "-o", tmp_path / "x.png", "--max-texture-pixels", "100000")
    assert r.returncode == 1 and "500x300" in r.stderr and "--max-texture-pixels" in r.stderr and "IBLBAKE_MAX_TEXTURE_PIXELS" in r.stderr, r.stderr
    codes = np.random.default_rng(2).integers(0, 65536, (5, 7, 3))
    odd = png(tmp_path / "odd16.png", codes, bits=16)
    wide = quad_glb(tmp_path / "wide.glb", vertices=QUAD_V * [1, 5 / 7, 1])
    p = scene_file(tmp_path, {"m": {"base_color": [0, 0, 0], "emissive": [1, 1, 1],
                                    "emissive_map": {"path": odd, "filter": "nearest"}}},
                   [{"mesh": {"path": wide}, "material": "m"}], effects=EMISSIVE_ONLY, res=(70, 50))
    _, fr = render_scene(p, tmp_path / "cache")
    centre = fr.hdr[5::10, 5::10, :3]
    assert np.abs(centre - srgb_decode(codes / 65535.0)).max() < 1e-6


@pytest.mark.slow         # over 5 s: make test runs it, make check is the fast loop
def test_textured_material_without_uvs_and_blend(tmp_path):
    import trimesh
    box = tmp_path / "box.stl"
    trimesh.creation.box().export(box)
    tex = png(tmp_path / "t.png", np.full((4, 4, 3), 90))
    p = scene_file(tmp_path, {"Wood": {"base_color_map": {"path": tex}}}, [{"mesh": {"path": str(box)}, "material": "Wood"}])
    r = run_cli("render", p, "-o", tmp_path / "x.png")
    assert r.returncode == 1 and "'Wood'" in r.stderr and "TEXCOORD_0" in r.stderr and "box.stl" in r.stderr, r.stderr
    mesh = quad_glb(tmp_path / "b.glb", base=np.full((4, 4, 4), 90, np.uint8), alphaMode="BLEND")
    p = scene_file(tmp_path, {}, [{"mesh": {"path": mesh}}])
    r = run_cli("render", p, "-o", tmp_path / "x.png")
    assert r.returncode == 1 and "BLEND" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
