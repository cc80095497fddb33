"""`iblbake basis` and iblbake.basis: a panorama's directional basis for an engine (the JSON
document, the GLSL, ambient dice's specular table), the same coefficients the renderer's `basis`
bake projects, and one-line refusals."""

import json

import numpy as np
import pytest

import iblbake
from iblbake.core import bases
from tests.helpers import run_cli, write_exr


def sky():
    v, u = np.meshgrid((np.arange(32) + 0.5) / 32, (np.arange(64) + 0.5) / 64, indexing="ij")
    return np.stack([1 + 0.8 * np.cos(2 * np.pi * u), 1 + 0.6 * np.cos(np.pi * v), 1 + 0.5 * np.sin(2 * np.pi * u)],
                    -1).astype(np.float32)


@pytest.mark.parametrize("name, args, opts", [("zh3", [], {}), ("sg", ["--sg-lobes", "12", "--sg-fit", "nnls"],
                                                                  {"sg_lobes": 12, "sg_fit": "nnls"}),
                                               ("ambient_dice", ["--ad-fit", "nnls"], {"ad_fit": "nnls"}),
                                               ("haar", ["--haar-coefficients", "32"],
                                                                          {"haar_coefficients": 32})])
def test_document_is_the_basis_projection(tmp_path, name, args, opts):
    """The JSON holds the basis's float64 projection (the renderer's `basis` bake and iblbake.basis
    compute it), its options, layout and bytes; its error block is the irradiance against the exact
    one (the same figure bench_bases measures); a second run replaces its own document."""
    env = write_exr(tmp_path / "sky.exr", sky())
    out = tmp_path / "b.json"
    for _ in range(2):
        r = run_cli("basis", env, "--basis", name, *args, "-o", out, "-q")
        assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    m = bases.BASES[name]
    want = m.project(sky().astype(np.float64), opts)
    assert doc["format"] == "iblbake.basis" and doc["basis"] == name and doc["options"] == opts
    assert doc["floats"] == m.floats(opts) and doc["bytes"]["fp16"] == bases.probe_bytes(name, opts, 2)
    assert doc["specular"] == (name in bases.SPECULAR) and doc["layout"]
    got = np.array(doc["coefficients"])
    assert got.shape == want.shape and np.abs(got - want).max() <= 1e-12 * np.abs(want).max()
    api = iblbake.basis(iblbake.load_panorama(env), name, **opts)
    assert api.error == doc["error"] and 0 < doc["error"]["relative_rmse"] < 0.3
    normals = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1.0]])
    assert np.allclose(api.irradiance(normals), m.irradiance(want, normals, opts), rtol=1e-12)


def test_glsl_and_the_specular_table(tmp_path):
    """--glsl prints the basis's GLSL (its coefficients, irradiance and, for the bases that carry
    one, its specular function); --specular-table writes ambient dice's table as the GLSL reads it
    (the module's table, one channel, 129 x 65); sg has none, and says so."""
    from iblbake.io import images
    env = write_exr(tmp_path / "sky.exr", sky())
    r = run_cli("basis", env, "--basis", "ambient_dice", "--glsl", "--specular-table", tmp_path / "t.exr", "-q")
    assert r.returncode == 0, r.stderr
    assert "vec3 ambientDiceIrradiance(vec3 n)" in r.stdout and "ambientDiceSpecularRadiance" in r.stdout
    table = images.read_exr(tmp_path / "t.exr")
    want = bases.BASES["ambient_dice"].specular_table({})
    assert table.shape[:2] == want.shape and np.abs(table[..., 0] - want).max() < 1e-6
    r = run_cli("basis", env, "--basis", "sg", "--specular-table", tmp_path / "s.exr")
    assert r.returncode == 2 and "closed form" in r.stderr and not (tmp_path / "s.exr").exists()
    r = run_cli("basis", env, "--basis", "sg", "--glsl", "-q")
    assert "vec3 sgSpecularRadiance(vec3 n, vec3 v, float roughness)" in r.stdout


def test_specular_radiance_of_the_api_is_the_renderers(tmp_path):
    """Basis.specular_radiance is the twin the shade pass's SPECULAR_BASIS is tested against
    (tests/test_bases_specular.py): the radiance along the warped lobe at the lobe's own axis and
    sharpness; a basis without a specular lobe refuses."""
    from iblbake.core.bases import common
    env = write_exr(tmp_path / "sky.exr", sky())
    b = iblbake.basis(iblbake.load_panorama(env), "ambient_dice")
    n, v = np.array([[0, 1.0, 0]]), np.array([[0, 0.6, 0.8]])
    alpha = np.array([0.25])
    want = bases.specular_radiance("ambient_dice", b.coefficients, common.lobe_axis(n, v, alpha),
                                   common.warp_sharpness(alpha, np.array([0.6])), {})
    assert np.allclose(b.specular_radiance(n, v, 0.5), want, rtol=1e-12)
    with pytest.raises(iblbake.InputError, match="carries no specular lobe"):
        iblbake.basis(iblbake.load_panorama(env), "zh3").specular_radiance(n, v, 0.5)


def test_refusals(tmp_path):
    env = write_exr(tmp_path / "sky.exr", sky())
    mine = tmp_path / "mine.json"
    mine.write_text('{"mine": 1}')
    r = run_cli("basis", env, "--basis", "zh3", "-o", mine)
    assert r.returncode == 1 and "--force" in r.stderr and mine.read_text() == '{"mine": 1}'
    r = run_cli("basis", env, "--basis", "sh")
    assert r.returncode == 2 and "'sh' is not one of" in r.stderr
    r = run_cli("basis", env, tmp_path / "missing.exr", "--basis", "zh3", "-o", f"{tmp_path}/out/")
    assert r.returncode == 1 and "missing.exr" in r.stderr and not (tmp_path / "out").exists()
    with pytest.raises(iblbake.InputError, match="sg_lobes 7: use one of 5, 6, 9, 12"):
        iblbake.basis(iblbake.load_panorama(env), "sg", sg_lobes=7)
    with pytest.raises(iblbake.InputError, match="lobes: not an option of basis zh3"):
        iblbake.basis(iblbake.load_panorama(env), "zh3", lobes=3)
    with pytest.raises(iblbake.InputError, match="iblbake.sh"):
        iblbake.basis(iblbake.load_panorama(env), "sh")


def test_options_of_another_basis_are_refused_or_said(tmp_path):
    """`--sg-lobes` with `--basis zh3` is refused (iblbake.basis refuses it too); --json beside
    GLSL on stdout is refused (both printed there made invalid JSON); the depfile and the summary
    name ambient dice's table. In a scene, a basis option no basis of the frame reads is a note:
    effects.sg_lobes beside diffuse zh3, or beside probes storing SG (they read probes.sg_lobes),
    probes.ad_fit beside probes storing SG."""
    from iblbake.render.plan import plan
    from tests.helpers import load_scene
    env = write_exr(tmp_path / "sky.exr", sky())
    r = run_cli("basis", env, "--basis", "zh3", "--sg-lobes", "12")
    assert r.returncode == 2 and "--sg-lobes is an option of --basis sg, not of zh3" in r.stderr
    r = run_cli("basis", env, "--basis", "sg", "--glsl", "--json")
    assert r.returncode == 2 and "give -o FILE" in r.stderr and not r.stdout
    r = run_cli("basis", env, "--basis", "ambient_dice", "-o", tmp_path / "d.json", "--specular-table",
                tmp_path / "t.exr", "--depfile", tmp_path / "d.d", "--json", "-q")
    assert r.returncode == 0 and json.loads(r.stdout)["specular_table"] == str(tmp_path / "t.exr")
    assert str(tmp_path / "t.exr") in (tmp_path / "d.d").read_text().split(":")[0]
    doc = {"camera": {"resolution": [8, 8]}, "environment": {"path": str(env)},
           "materials": {"m": {"roughness": 0.5}}, "objects": [{"sphere": {"radius": 1}, "material": "m"}],
           "effects": {"diffuse": "zh3", "specular": "off", "sg_lobes": 12}}
    notes = plan(load_scene(tmp_path, "a", doc)).notes
    assert any("effects.sg_lobes is not read" in n for n in notes)
    doc["effects"] = {"diffuse": "probes", "specular": "off", "sg_lobes": 12}
    doc["probes"] = {"irradiance": "sg", "ad_fit": "nnls"}
    notes = plan(load_scene(tmp_path, "b", doc)).notes
    assert any("effects.sg_lobes is not read" in n and "probes.sg_lobes" in n for n in notes)
    assert any("probes.ad_fit is not read" in n for n in notes)
    doc["effects"] = {"diffuse": "probes", "specular": "off"}
    doc["probes"] = {"irradiance": "sg", "sg_lobes": 12}
    assert not [n for n in plan(load_scene(tmp_path, "c", doc)).notes if "is not read" in n]


def test_sh_and_basis_say_what_they_wrote(tmp_path):
    """Both commands write through one helper (cli/options.py write_texts), whose summary line
    starts with the file it wrote, one line per panorama."""
    env = write_exr(tmp_path / "sky.exr", sky())
    for argv, out in ((["sh", env], tmp_path / "sh.json"), (["basis", env, "--basis", "sg"], tmp_path / "sg.json")):
        p = run_cli(*argv, "-o", out)
        assert p.returncode == 0 and out.exists(), p.stderr
        said = (p.stdout + p.stderr).strip().splitlines()
        assert said[-1].startswith(f"wrote {out}: "), said
