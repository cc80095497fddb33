"""The equirect/cube/octahedral mappings, solid angles and frames: numpy against closed forms,
and kernels/common.h against numpy."""

import numpy as np
import pytest

from iblbake.core import conventions as cv
from tests.helpers import selftest_kernel


def random_dirs(n, seed=0):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_equirect_known_directions():
    u, v = cv.equirect_uv_from_dir(np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0], [0, -1, 0], [-1, 0, 0]], float))
    assert np.allclose(u[[0, 1, 4]], [0.5, 0.25, 0.75])
    assert np.allclose(v, [0.5, 0.5, 0.0, 1.0, 0.5])
    # -z is the seam: u wraps to 0, never 1
    u, _ = cv.equirect_uv_from_dir(np.array([[-0.0, 0, -1.0], [0.0, 0, -1.0]]))
    assert np.all((u >= 0) & (u < 1))


def test_equirect_round_trip():
    d = random_dirs(10000)
    u, v = cv.equirect_uv_from_dir(d)
    assert np.abs(cv.dir_from_equirect_uv(u, v) - d).max() < 1e-12
    w, h = 64, 32
    t = cv.equirect_texel_dirs(w, h)
    u, v = cv.equirect_uv_from_dir(t)
    assert np.allclose(u * w - 0.5, np.arange(w)[None, :], atol=1e-9)
    assert np.allclose(v * h - 0.5, np.arange(h)[:, None], atol=1e-9)


@pytest.mark.parametrize("w,h", [(1, 1), (2, 1), (3, 2), (7, 3), (1024, 512), (4096, 2048)])
def test_solid_angles_sum_to_4pi(w, h):
    assert abs(cv.equirect_solid_angles(w, h).sum() - 4 * np.pi) < 1e-12 * max(1, w * h)


def test_cube_and_octahedral():
    assert abs(6 * cv.cube_texel_solid_angles(16).sum() - 4 * np.pi) < 1e-12
    d = cv.cube_texel_dirs(8)
    # face centres and orientation (OpenGL convention): +X face, top row looks up (+y)
    assert np.allclose(cv.dir_from_cube(0, 0.5, 0.5), [1, 0, 0])
    assert cv.dir_from_cube(0, 0.5, 0.0)[1] > 0.7
    assert np.allclose(cv.dir_from_cube(4, 1.0, 0.5), np.array([1, 0, 1]) / np.sqrt(2))
    assert np.allclose(np.linalg.norm(d, axis=-1), 1)
    r = random_dirs(5000, 3)
    u, v = cv.octahedral_uv_from_dir(r)
    assert np.abs(cv.dir_from_octahedral(u, v) - r).max() < 1e-12
    assert np.allclose(cv.dir_from_octahedral(0.5, 0.5), [0, 1, 0])


def test_tangent_frame_orthonormal_everywhere():
    n = np.concatenate([random_dirs(1000), np.eye(3), -np.eye(3), [[0, 0, -1 + 1e-9]]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t, b = cv.tangent_frame(n)
    for a in (t, b):
        assert np.all(np.isfinite(a))
        assert np.allclose(np.linalg.norm(a, axis=1), 1, atol=1e-9)
    assert np.abs(np.sum(t * b, 1)).max() < 1e-9
    assert np.abs(np.cross(t, b) - n).max() < 1e-9


def test_bilinear_wraps_u_and_clamps_v():
    img = np.arange(4 * 2 * 1, dtype=float).reshape(2, 4, 1)
    # exactly at texel centres
    assert cv.bilinear_equirect(img, 0.125, 0.25)[0] == 0
    # halfway across the seam: mean of first and last column
    assert np.isclose(cv.bilinear_equirect(img, 0.0, 0.25)[0], 0.5 * (img[0, 0, 0] + img[0, 3, 0]))
    # beyond the last row centre: clamped
    assert np.isclose(cv.bilinear_equirect(img, 0.125, 1.0)[0], img[1, 0, 0])


# ---- kernels/common.h against numpy ------------------------------------------------------


def test_kernels_flush_subnormal_floats(rt):
    """Every program runs with subnormals flushed (programs.DENORMS; docs/conventions.md amendment
    15), as operands (an integer's bits in a record's w lane read as a float: DAZ) and as results
    (FTZ); normal floats are untouched. Without the flush this CPU took a microcode assist for each
    such operand: the reference 1.2-3.7x slower (docs/benchmarks.md "Subnormal floats")."""
    a = np.array([1e-20, 1e-30, 2.0, np.array(5, np.int32).view(np.float32), 1.5e-38], np.float32)
    b = np.array([1e-20, 1.0, 3.0, 1.0, 0.5], np.float32)
    got = selftest_kernel(rt, "t_product", len(a), [a, b], 1)[:, 0]
    assert got.tolist() == [0.0, np.float32(1e-30), 6.0, 0.0, 0.0]
    assert (a * b)[[0, 3, 4]].min() > 0                     # numpy keeps them: the kernel flushed


def test_opencl_equirect_matches_numpy(rt):
    d = np.concatenate([random_dirs(4096), np.eye(3), -np.eye(3)])
    uv = selftest_kernel(rt, "t_equirect_uv", len(d), [d], 2)
    u, v = cv.equirect_uv_from_dir(d)
    du = np.abs(uv[:, 0] - u)
    du = np.minimum(du, 1 - du)  # the seam: 0 and 1 are the same column
    assert du.max() < 2e-6 and np.abs(uv[:, 1] - v).max() < 2e-6
    uvs = np.random.default_rng(1).random((4096, 2))
    dd = selftest_kernel(rt, "t_dir_from_equirect", len(uvs), [uvs], 3)
    assert np.abs(dd - cv.dir_from_equirect_uv(uvs[:, 0], uvs[:, 1])).max() < 2e-6


def test_opencl_solid_angles_and_bilinear_match_numpy(rt):
    w, h = 1024, 512
    prg = rt.program("selftest.cl", {"SH_BANDS": 3})
    out = rt.empty(h * 4)
    rt.run(prg.t_row_solid_angle, (h,), None, np.int32(w), np.int32(h), out)
    got = rt.read(out, (h,))
    ref = cv.equirect_row_solid_angles(w, h)
    assert np.abs(got / ref - 1).max() < 1e-5
    img = np.random.default_rng(2).random((8, 16, 3)).astype(np.float32)      # RGB, 3 floats a texel
    uv = np.concatenate([np.random.default_rng(3).random((2000, 2)), [[0, 0], [1, 1], [0.999999, 0.0]]])
    res = selftest_kernel(rt, "t_bilinear", len(uv), [img, np.int32(16), np.int32(8), uv], 3)
    assert np.abs(res - cv.bilinear_equirect(img, uv[:, 0], uv[:, 1])).max() < 1e-5


def test_opencl_cube_octahedral_frames_match_numpy(rt):
    rng = np.random.default_rng(4)
    st = np.stack([np.repeat(np.arange(6), 200), rng.random(1200), rng.random(1200)], 1)
    got = selftest_kernel(rt, "t_cube", len(st), [st], 3)
    assert np.abs(got - cv.dir_from_cube(st[:, 0].astype(int), st[:, 1], st[:, 2])).max() < 2e-6
    uv = rng.random((2000, 2))
    got = selftest_kernel(rt, "t_octahedral", len(uv), [uv], 3)
    assert np.abs(got - cv.dir_from_octahedral(uv[:, 0], uv[:, 1])).max() < 2e-6
    n = np.concatenate([random_dirs(1000, 5), np.eye(3), -np.eye(3)])
    tb = selftest_kernel(rt, "t_frame", len(n), [n], 6)
    t, b = cv.tangent_frame(n)
    assert np.abs(tb[:, :3] - t).max() < 2e-6 and np.abs(tb[:, 3:] - b).max() < 2e-6
