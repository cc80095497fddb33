"""BRDF terms and GGX sampling: closed forms, chi-square against the pdf, OpenCL against numpy."""

import math

import numpy as np
import pytest

from iblbake.core import brdf
from iblbake.core import sampling


def test_hammersley_and_radical_inverse():
    assert np.allclose(sampling.radical_inverse_vdc([0, 1, 2, 3, 4, 5]), [0, 0.5, 0.25, 0.75, 0.125, 0.625])
    h = sampling.hammersley(1)
    assert h.shape == (1, 2) and np.all(h == 0)
    h = sampling.hammersley(7)  # not a power of two
    assert np.all((h >= 0) & (h < 1)) and len(np.unique(h[:, 1])) == 7


@pytest.mark.parametrize("alpha", [0.05, 0.3, 1.0])
def test_ggx_ndf_normalised(alpha):
    # int D(h) cos(theta_h) dOmega_h = 1 over the hemisphere (Gauss-Legendre in cos theta)
    x, w = np.polynomial.legendre.leggauss(400)
    c = 0.5 * (x + 1)
    val = 2 * math.pi * np.sum(0.5 * w * brdf.d_ggx(c, alpha) * c)
    assert abs(val - 1) < 1e-6


@pytest.mark.parametrize("alpha", [0.1, 0.5, 0.9])
def test_ggx_half_vector_sampling_chi_square(alpha):
    """Histogram of cos(theta_h) of sampled half-vectors against the pdf's own integral per bin
    (Mitsuba's habit: bins with < 5 expected samples pooled)."""
    from scipy import stats
    rng = np.random.default_rng(1)
    n = 200000
    h = sampling.sample_ggx_half(rng.random((n, 2)), alpha)
    assert np.allclose(np.linalg.norm(h, axis=1), 1)
    edges = np.linspace(0, 1, 41)
    observed, _ = np.histogram(h[:, 2], edges)
    x, w = np.polynomial.legendre.leggauss(40)
    expected = []
    for a, b in zip(edges[:-1], edges[1:]):
        c = 0.5 * (b - a) * x + 0.5 * (a + b)
        expected.append(2 * math.pi * np.sum(0.5 * (b - a) * w * sampling.pdf_ggx_half(c, alpha)))
    expected = np.array(expected) * n
    assert abs(expected.sum() - n) < 1e-3 * n
    keep = expected >= 5
    obs = np.append(observed[keep], observed[~keep].sum())
    exp = np.append(expected[keep], expected[~keep].sum())
    if exp[-1] == 0:
        obs, exp = obs[:-1], exp[:-1]
    chi2 = np.sum((obs - exp) ** 2 / exp)
    p = stats.chi2.sf(chi2, len(obs) - 1)
    assert p > 1e-3, (chi2, p)


def test_visibility_is_reciprocal_and_smith_correlated():
    rng = np.random.default_rng(2)
    nov, nol, a = rng.random(1000), rng.random(1000), rng.random(1000)
    v1 = brdf.v_smith_ggx_correlated(nov, nol, a)
    assert np.allclose(v1, brdf.v_smith_ggx_correlated(nol, nov, a))
    # alpha = 0: V = 1 / (4 NoV NoL)
    assert np.allclose(brdf.v_smith_ggx_correlated(0.5, 0.25, 0.0), 1 / (4 * 0.5 * 0.25))
    assert np.all(np.isfinite(brdf.v_smith_ggx_correlated(0.0, 0.0, 0.0)))


def test_schlick():
    assert np.isclose(brdf.f_schlick(1.0, 0.04), 0.04) and np.isclose(brdf.f_schlick(0.0, 0.04), 1.0)
    assert np.isclose(brdf.f_schlick_roughness(0.0, 0.04, 1.0), 0.04)


def test_opencl_brdf_and_sampling_match_numpy(rt):
    src = '''
    #include "brdf.h"
    #include "sampling.h"
    __kernel void t(__global const float *in, __global float *out) {
        int i = get_global_id(0);
        float nov = in[4*i], nol = in[4*i+1], a = in[4*i+2], noh = in[4*i+3];
        out[8*i] = d_ggx(noh, a);
        out[8*i+1] = v_smith_ggx_correlated(nov, nol, a);
        out[8*i+2] = f_schlick(nov, (float3)(0.04f), (float3)(0.7f)).x;
        out[8*i+3] = f_schlick_roughness(nov, (float3)(0.04f), (float3)(0.7f), a).x;
        float3 h = sample_ggx_half(hammersley((uint)i, 1000u), a);
        out[8*i+4] = h.x; out[8*i+5] = h.y; out[8*i+6] = h.z; out[8*i+7] = radical_inverse_vdc((uint)i);
    }'''
    from iblbake.device import programs as icl
    import pyopencl as pcl
    text = src.replace('#include "brdf.h"', icl.kernel_source("brdf.h")).replace(
        '#include "sampling.h"', icl.kernel_source("sampling.h"))
    prg = pcl.Program(rt.ctx, text).build(options=rt.device_options)     # as Runtime.program builds
    rng = np.random.default_rng(3)
    inp = rng.random((1000, 4)).astype(np.float32)
    inp[:, 2] = np.maximum(inp[:, 2], 0.02)
    out = rt.empty(1000 * 8 * 4)
    prg.t(rt.queue, (1000,), None, rt.to_device(inp), out)
    got = rt.read(out, (1000, 8))
    nov, nol, a, noh = inp.T.astype(np.float64)
    assert np.allclose(got[:, 0], brdf.d_ggx(noh, a), rtol=2e-4)
    assert np.allclose(got[:, 1], brdf.v_smith_ggx_correlated(nov, nol, a), rtol=2e-4)
    assert np.allclose(got[:, 2], brdf.f_schlick(nov, 0.04, 0.7), rtol=1e-5)
    assert np.allclose(got[:, 3], brdf.f_schlick_roughness(nov, 0.04, a, 0.7), rtol=1e-5)
    h = np.stack([sampling.sample_ggx_half(sampling.hammersley(1000)[i], a[i]) for i in range(1000)])
    assert np.abs(got[:, 4:7] - h).max() < 2e-5
    assert np.allclose(got[:, 7], sampling.radical_inverse_vdc(np.arange(1000)), atol=1e-7)
