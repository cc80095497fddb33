"""Each directional basis's kernel header (kernels/basis_*.h through kernels/bases.h) against its
float64 twin (iblbake/core/bases/), and a render with every basis as `effects.diffuse` against the
shade twin: the kernel compiled only with the scene's basis."""

from __future__ import annotations

import numpy as np
import pytest

from iblbake.core import conventions
from iblbake.core.bases import BASES, DIFFUSE

VARIANTS = [(name, opts) for name in DIFFUSE for opts in BASES[name].variants()]


def sky(w=64, h=32):
    """A coloured sky with a bright lobe (negative least-squares lobes, Geomerics' r near 1)."""
    d = conventions.equirect_texel_dirs(w, h)
    sun = np.exp(60 * (d @ np.array([0.48, 0.6, 0.64]) - 1))
    return np.stack([0.3 + 0.2 * d[..., 1] + 8 * sun, 0.4 + 0.1 * d[..., 0] + 6 * sun, 0.6 + 2 * sun], -1)


@pytest.mark.parametrize("name,opts", VARIANTS, ids=lambda x: str(x))
def test_kernel_matches_twin(rt, name, opts):
    """float32 against float64: measured <= 3.9e-7 of the largest irradiance (SG6; Geomerics' pow
    2.7e-7), Haar's sum of up to 1024 clipped squares 1.5e-6 (256 kept); Haar at 600 normals (its
    float64 twin is a loop over terms)."""
    m = BASES[name]
    c = m.project(sky(), opts)
    rng = np.random.default_rng(1)
    n = rng.normal(size=(600 if name == "haar" else 3000, 3))
    n = np.concatenate([n / np.linalg.norm(n, axis=1, keepdims=True), np.eye(3), -np.eye(3)])
    k = rt.kernel("selftest.cl", "t_basis_irradiance", m.defines(opts))
    out = rt.empty(len(n) * 3 * 4)
    rt.run(k, (len(n),), None, rt.to_device(m.pack(c, opts)),
           rt.to_device(n.astype(np.float32)), out)
    got = rt.read(out, (len(n), 3))
    want = m.irradiance(c, n, opts)
    err = np.abs(got - want).max() / np.abs(want).max()
    assert err < (5e-6 if name == "haar" else 1.5e-6), err


RENDERED = [(n, BASES[n].variants()[-1 if n != "haar" else 2]) for n in DIFFUSE]


@pytest.mark.parametrize("name,opts", RENDERED, ids=lambda x: str(x))
def test_render_matches_shade_twin(tmp_path, name, opts):
    """`effects.diffuse: <basis>` end to end (schema, plan, the cached `basis` bake, the source, the
    shade kernel with only that header) against the shade twin on the float64 projection:
    measured <= 1.1e-6 of the brightest pixel (Haar 64: 1.0e-6); only the scene's basis compiled."""
    from iblbake.render import render
    from iblbake.io import images
    from iblbake.render import twin as rr
    from iblbake.render.plan import plan
    from iblbake.scene import load as scene, pack

    from tests.helpers import scene_file

    env = tmp_path / "sky.exr"
    img = sky().astype(np.float32)
    images.write_exr(env, img)
    fx = {"diffuse": name, "specular": "off", **opts}
    sc = scene.load(scene_file(tmp_path, env, camera={"perspective": {"position": [0, 0, 3], "fov_y": 45},
                                                      "resolution": [24, 24]},
                               materials={"base_color": [0.8, 0.6, 0.4], "roughness": 0.5}, effects=fx))
    defines = plan(sc).defines["shade"]
    assert [k for k in defines if k.startswith("BASIS_")] == [f"BASIS_{name.upper()}"]
    frame = render(sc, cache_root=tmp_path / "cache")
    arrays = pack.scene_arrays(sc)
    gb = rr.primary(sc["camera"], arrays)
    hit = gb["hit"]
    c = BASES[name].project(img.astype(np.float64), opts)
    want = rr.shade(gb, arrays, sc["effects"], sc["environment"], basis_coeffs=c)[hit]
    got = frame.hdr[..., :3].reshape(-1, 3)[hit]
    err = np.abs(got - want).max() / want.max()
    assert hit.sum() > 100 and err < 5e-6, err
    again = render(sc, cache_root=tmp_path / "cache")          # the bake read back from the cache
    assert np.array_equal(again.hdr, frame.hdr)
