"""Each basis fitted for the quantity it serves (issue 62.5): SG and ambient dice fitted on the
irradiance for the diffuse term, against L2 SH on a sun sky; and the files `iblbake basis` writes
evaluated from their documented fields alone (axes, sharpness, amplitudes) by a separate
evaluator: a 2-D quadrature of each lobe times the clamped cosine, not iblbake's series."""

import json

import numpy as np
import pytest

from iblbake.bake import sh as bake_sh
from iblbake.core import conventions
from iblbake.core.bases import BASES
from iblbake.core.metrics import LUMINANCE
from tests.helpers import run_cli, write_exr


def sun_sky(w=128, h=64):
    """A sky brightening upwards with a sun (peak 60, sharpness 100) at (0.48, 0.6, 0.64)."""
    d = conventions.equirect_texel_dirs(w, h)
    sun = np.exp(100.0 * (d @ np.array([0.48, 0.6, 0.64]) - 1))
    sky = 0.6 + 0.4 * np.clip(d[..., 1], 0, 1)
    return np.stack([sky + 60 * sun, 0.9 * sky + 55 * sun, 1.2 * sky + 45 * sun], -1)


def rel_rmse(approx, exact):
    a, e = approx @ LUMINANCE, exact @ LUMINANCE
    return float(np.sqrt(np.mean((a - e) ** 2) / np.mean(e ** 2)))


def test_irradiance_fit_level_with_l2():
    """Relative RMSE of the irradiance (luminance, 1024 normals) against the exact convolution:
    measured L2 SH 3.41%; SG9 fitted on the irradiance 3.43%, on the radiance 6.58% (least
    squares: its misfit of the sun leaks into the low orders); SG12 3.16% against 6.43%; ambient
    dice 3.54% against 3.78%. The irradiance fits within 1.25x of L2, the radiance fits 1.9x."""
    img = sun_sky()
    normals = bake_sh.fibonacci_normals(1024)
    exact = bake_sh.exact_irradiance(img, normals)

    def err(name, opts):
        m = BASES[name]
        return rel_rmse(m.irradiance(m.project(img, opts), normals, opts), exact)
    l2 = err("sh", {"sh_bands": 3, "sh_window": "none"})
    assert 0.030 < l2 < 0.038, l2
    for k in (9, 12):
        irr = err("sg", {"sg_lobes": k, "sg_fit": "irradiance"})
        rad = err("sg", {"sg_lobes": k, "sg_fit": "least_squares"})
        assert irr < 1.25 * l2 and rad > 1.7 * irr, (k, irr, rad, l2)
    irr, rad = err("ambient_dice", {"ad_fit": "irradiance"}), err("ambient_dice", {"ad_fit": "least_squares"})
    assert irr < 1.1 * l2 and irr < 0.96 * rad, (irr, rad, l2)


def sphere_rule(n=160):
    x, w = np.polynomial.legendre.leggauss(n)
    phi = (np.arange(2 * n) + 0.5) * np.pi / n
    ct, ph = np.meshgrid(x, phi, indexing="ij")
    st = np.sqrt(1 - ct * ct)
    d = np.stack([st * np.cos(ph), ct, st * np.sin(ph)], -1).reshape(-1, 3)
    return d, np.repeat(w * np.pi / n, 2 * n)


def test_basis_file_evaluates_from_its_fields(tmp_path):
    """`iblbake basis --basis sg` (the irradiance fit by default) on the sun sky: its JSON's
    amplitudes, axes and sharpness, put through a 2-D quadrature of sum_k A_k exp(lambda (mu_k.w
    - 1)) max(0, n.w), give the irradiance the file's error block reports (at its 256 Fibonacci
    normals, luminance: measured 3.43%, within 1.25x of L2's 3.41% there), and the document's
    Legendre profile gives the same irradiance (measured 4.5e-6 of the largest: the quadrature's)."""
    env = write_exr(tmp_path / "sun.exr", sun_sky().astype(np.float32))
    out = tmp_path / "sg.json"
    r = run_cli("basis", env, "--basis", "sg", "-o", out, "-q")
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert doc["options"] == {"sg_lobes": 9, "sg_fit": "irradiance"} and doc["sharpness"] == 2.0
    amp, mu, lam = np.array(doc["coefficients"]), np.array(doc["axes"]), doc["sharpness"]
    # the documented Fibonacci axes
    k = np.arange(len(mu))
    y = 1 - (2 * k + 1) / len(mu)
    phi = k * np.pi * (3 - np.sqrt(5))
    assert np.allclose(mu, np.stack([np.sqrt(1 - y * y) * np.sin(phi), y, np.sqrt(1 - y * y) * np.cos(phi)], -1))
    n = bake_sh.fibonacci_normals(256)
    d, w = sphere_rule()
    lobes = np.exp(lam * (d @ mu.T - 1))                               # (dirs, K)
    per_lobe = (np.maximum(0, n @ d.T) * w) @ lobes                    # (normals, K)
    quad = np.maximum(0, per_lobe @ amp)
    series = np.maximum(0, np.polynomial.legendre.legval(np.clip(n @ mu.T, -1, 1),
                                                         np.array(doc["irradiance_legendre"])[:, None, None]) @ amp)
    assert np.abs(quad - series).max() < 2e-5 * quad.max()
    exact = bake_sh.exact_irradiance(sun_sky().astype(np.float32).astype(np.float64), n)
    got = rel_rmse(quad, exact)
    assert abs(got - doc["error"]["relative_rmse"]) < 1e-4 * got, (got, doc["error"])
    l2 = BASES["sh"]
    o = {"sh_bands": 3, "sh_window": "none"}
    assert got < 1.25 * rel_rmse(l2.irradiance(l2.project(sun_sky().astype(np.float32), o), n, o), exact)


@pytest.mark.external
def test_sg_irradiance_fit_within_1_25x_of_l2_on_every_example_panorama(panoramas):
    """The done criterion of issue 62.5 on the eight example panoramas (halved to 512 x 256, 1024
    normals): SG9 and SG12 fitted on the irradiance within 1.25x of L2 SH's relative RMSE on each
    (measured SG9 0.99-1.06x: its smoother lobes, lambda 2; at the K's own 4.5 sunset was 1.42x
    and forest 1.26x; SG12 0.69-0.91x)."""
    from iblbake.io import images
    normals = bake_sh.fibonacci_normals(1024)
    worst = {9: 0.0, 12: 0.0}
    for path in panoramas.values():
        img = np.asarray(images.read_exr(path))[::2, ::2, :3].astype(np.float64)
        exact = bake_sh.exact_irradiance(img, normals)

        def err(name, opts):
            m = BASES[name]
            return rel_rmse(m.irradiance(m.project(img, opts), normals, opts), exact)
        l2 = err("sh", {"sh_bands": 3, "sh_window": "none"})
        for k in worst:
            worst[k] = max(worst[k], err("sg", {"sg_lobes": k, "sg_fit": "irradiance"}) / l2)
    assert worst[9] < 1.12 and worst[12] < 1.0, worst
