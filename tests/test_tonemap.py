"""Tone mapping: OpenCL against the numpy twin, closed forms, monotonicity, hostile inputs."""

import numpy as np
import pytest

from iblbake.core import tonemap
from iblbake.scene.layout import TONEMAP_IDS as OPS
from tests.helpers import HOSTILE, run_cl


def test_closed_forms():
    assert np.isclose(tonemap.reinhard(1.0), 0.5)
    assert np.isclose(tonemap.aces(np.array(1.0)), (2.51 + 0.03) / (2.43 + 0.59 + 0.14))
    assert np.isclose(tonemap.hable(np.array(11.2)), 1.0)
    assert np.isclose(tonemap.srgb_encode(np.array(0.5)), 0.7353569830524495)
    # PBR Neutral is the identity below the compression start, minus the Fresnel offset
    c = np.array([0.5, 0.3, 0.2])
    assert np.allclose(tonemap.pbr_neutral(c), c - 0.04)
    assert np.allclose(tonemap.tonemap(np.array([[0.25, 0.25, 0.25]]), "linear", transfer="gamma", gamma=2.0), 0.5)
    assert np.allclose(tonemap.tonemap(np.array([[0.25] * 3]), "linear", exposure_ev=2, transfer="gamma"), 1.0)


@pytest.mark.parametrize("op", list(OPS))
@pytest.mark.parametrize("srgb", [True, False])
def test_opencl_matches_numpy(rt, op, srgb):
    rng = np.random.default_rng(0)
    hdr = np.concatenate([rng.random((2000, 3)) * 4, np.exp(rng.normal(0, 3, (2000, 3)))]).astype(np.float32)
    disp, u8 = run_cl(rt, hdr, op, ev=0.5, srgb=srgb)
    ref = tonemap.tonemap(hdr, op, 0.5, "srgb" if srgb else "gamma", 2.2)
    assert np.abs(disp - ref).max() < 1e-5
    assert np.abs(u8.astype(int) - tonemap.to_u8(ref).astype(int)).max() <= 1


@pytest.mark.parametrize("op", list(OPS))
def test_hostile_inputs_stay_finite_in_range(rt, op):
    hdr = np.stack(list(np.meshgrid(HOSTILE, HOSTILE, indexing="ij")) + [np.full((len(HOSTILE),) * 2, 0.3)], -1)
    hdr = hdr.reshape(-1, 3).astype(np.float32)
    ref = tonemap.tonemap(hdr, op)
    disp, _ = run_cl(rt, hdr, op)
    for a in (ref, disp):
        assert np.all(np.isfinite(a)) and a.min() >= 0 and a.max() <= 1
    assert np.abs(disp - ref).max() < 1e-5


@pytest.mark.parametrize("op", list(OPS))
def test_monotonic_in_luminance(op):
    x = np.geomspace(1e-6, 1e6, 4000)
    y = tonemap.tonemap(np.stack([x, x, x], -1), op)[:, 0]
    assert np.all(np.diff(y) >= -1e-12)
    # and for a coloured ramp, the luminance of the output never decreases
    c = np.stack([x, 0.5 * x, 0.2 * x], -1)
    out = tonemap.tonemap(c, op, transfer="gamma", gamma=1.0)
    lum = out @ np.array([0.2126, 0.7152, 0.0722])
    assert np.all(np.diff(lum) >= -1e-9)
