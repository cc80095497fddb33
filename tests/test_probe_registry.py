"""The probe bases are a registry (core/bases/probes.py PROBE_BASES, issue 61.2): no module outside
it compares what a volume stores (probes.irradiance, a volume's representation) with a name or
with the directional subset; the schema, the files, the kernels' switches and the CLI derive from
it."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1] / "iblbake"
REGISTRY = ROOT / "core" / "bases" / "probes.py"

# a probe basis's name compared, or the old directional subset (core/bases PROBES) asked
COMPARED = re.compile(
    r"""(representation|irradiance)["']\]\s*(==|!=|not\s+in|in)\s*[("'b]"""      # settings["irradiance"] == "sh"
    r"""|\b(rep|irradiance|representation)\s*(==|!=)\s*["']"""                  # rep == "octahedral"
    r"""|(==|!=)\s*["'](octahedral|ambient_dice)["']"""                          # ... == "ambient_dice"
    r"""|\bbases\.PROBES\b|\bimport\b[^\n]*\bPROBES\b|\bin\s+PROBES\b""")       # in bases.PROBES


def compared_lines(root: Path = ROOT) -> list:
    """(file, line number, line) of every comparison of a probe basis's name outside the registry."""
    out = []
    for path in sorted(root.rglob("*.py")):
        if path == REGISTRY or path == ROOT / "core" / "bases" / "__init__.py":      # where they are defined
            continue
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if COMPARED.search(line):
                out.append(f"{path.relative_to(root.parent)}:{i}: {line.strip()}")
    return out


def test_no_module_compares_a_probe_basis_by_name():
    """26 places across 11 files compared the representation with string literals or asked
    `in bases.PROBES` (issue 61.2); a consumer asks the registry's entry instead."""
    assert compared_lines() == []


def test_the_pattern_finds_the_comparisons_it_forbids(tmp_path):
    """The grep above is not vacuous: each way the old code compared is found."""
    (tmp_path / "iblbake").mkdir()
    old = ['    if settings["irradiance"] == "sh":', '    elif rep in bases.PROBES:',
           '        if rep == "octahedral":', "    sh_rep = rep == 'sh'",
           '    table = [T] if irradiance == "ambient_dice" else []',
           '    if volume["representation"] in ("octahedral", "sh") else',
           '    from iblbake.core.bases import BASES, PROBES, SPECULAR']
    (tmp_path / "iblbake" / "old.py").write_text("\n".join(old + ['    basis = PROBE_BASES[settings["irradiance"]]'])
                                                 + "\n")
    assert len(compared_lines(tmp_path / "iblbake")) == len(old)


def test_the_schema_files_and_switches_come_from_the_registry():
    """probes.irradiance's choices and option keys, each basis's file, and the kernel's switch (one
    of PROBES_SH, PROBES_BASIS or none: the octahedral atlas) are the entries'."""
    from iblbake.core import bases
    from iblbake.core.bases.probes import PROBE_BASES
    from iblbake.render import probes
    from iblbake.render.sources.probes import probe_defines
    from iblbake.scene.schema import SCHEMA

    fields = SCHEMA.fields["probes"].fields
    assert fields["irradiance"].choices == tuple(PROBE_BASES) == ("octahedral", "sh", "l1_geomerics", "zh3", "sg",
                                                                   "ambient_dice")
    assert {k for b in PROBE_BASES.values() for k in b.option_specs} <= set(fields)
    assert probes.FILES == {"octahedral": "irradiance.exr", "sh": "irradiance_sh.exr",
                            **{n: f"basis_{n}.exr" for n in ("l1_geomerics", "zh3", "sg", "ambient_dice")}}
    base = {"visibility": False, "classification": False}
    switches = {n: {k for k in probe_defines({**base, "irradiance": n}) if k in ("PROBES_SH", "PROBES_BASIS")}
                for n in PROBE_BASES}
    assert switches == {"octahedral": set(), "sh": {"PROBES_SH"},
                        **{n: {"PROBES_BASIS"} for n in ("l1_geomerics", "zh3", "sg", "ambient_dice")}}
    sg = probe_defines({**base, "irradiance": "sg", "sg_lobes": 5})
    assert sg["PROBE_BASIS_ROWS"] == len(bases.BASES["sg"].pack(np.zeros((5, 3)), {"sg_lobes": 5, "sg_fit": "nnls"}))


def test_the_basis_command_takes_its_names_and_flags_from_bases():
    """`iblbake basis`'s --basis choices are the directional bases and its option flags their
    OPTIONS (cli/basis.py listed them by hand)."""
    import click

    from iblbake.cli.basis import basis_command
    from iblbake.core import bases
    opts = {p.name: p for p in basis_command.get_params(click.Context(basis_command)) if isinstance(p, click.Option)}
    assert tuple(opts["name"].type.choices) == tuple(n for n, m in bases.BASES.items() if m.HEADER)
    for n, m in bases.BASES.items():
        for k, (choices, default, _doc) in m.OPTIONS.items():
            assert list(opts[k].type.choices) == [str(c) for c in choices] and opts[k].default == str(default)


def test_the_volume_record_is_read_by_the_kernel_as_the_host_packs_it(rt):
    """One volume record (scene/layout.py PROBE_VOLUME, emitted to kernels/layout.h) replaces the
    kernel's loose grid parameters and the biases in w lanes: the host's packer and the kernel's
    accessors agree on every field (selftest.cl t_probe_volume)."""
    from iblbake.render.sources.probes import probe_args
    from iblbake.scene.layout import PROBE_VOLUME

    vol = {"counts": (5, 3, 7), "origin": (-1.5, 0.25, 2.0), "spacing": (0.5, 0.75, 0.625), "normal_bias": 0.125,
           "view_bias": 0.0625, "irradiance_texels": 6, "distance_texels": 14,
           "data": np.zeros((105, 4)), "irradiance": np.zeros((105, 9, 3)), "distance": np.zeros((16, 16, 2)),
           "representation": "sh", "settings": {}}
    args = probe_args(rt, vol)
    assert set(args) == {"probe_data", "probe_irr", "probe_dist", "probe_volume"}
    out = rt.empty(16 * 4)
    rt.launch("selftest.cl", "t_probe_volume", {"SH_BANDS": 3}, (1,), {}, out=out, **args)
    got = rt.read(out, (4, 4))
    want = [*vol["origin"], vol["normal_bias"], *vol["spacing"], vol["view_bias"], *vol["counts"],
            vol["irradiance_texels"], vol["distance_texels"], 0, 0, 0]
    assert got.ravel().tolist() == want
    assert list(PROBE_VOLUME) == ["counts", "origin", "spacing", "normal_bias", "view_bias", "irradiance_texels",
                                  "distance_texels"]


def test_ddgi_weights_are_defined_once_per_language():
    """The DDGI weights (wrap floor, Chebyshev floor, crush, trilinear floor) are scene/layout.py's
    PROBE_WEIGHTS: layout.h's defines for the kernel, the twin's constants, probes.glsl's literals;
    kernels/probes.h and the GLSL writer hold none of their own."""
    from iblbake.render.twin import probes as twin
    from iblbake.scene.layout import PROBE_WEIGHTS, header_text

    assert (twin.WRAP_FLOOR, twin.CHEBYSHEV_FLOOR, twin.CRUSH, twin.TRILINEAR_FLOOR) == (
        PROBE_WEIGHTS["WRAP_FLOOR"], PROBE_WEIGHTS["CHEBYSHEV_FLOOR"], PROBE_WEIGHTS["CRUSH"],
        PROBE_WEIGHTS["TRILINEAR_FLOOR"])
    assert all(f"#define PROBE_{k} {v!r}f" in header_text() for k, v in PROBE_WEIGHTS.items())
    kernel = (Path(__file__).resolve().parents[1] / "kernels" / "probes.h").read_text()
    writer = (ROOT / "render" / "probes" / "glsl.py").read_text()
    for k, x in PROBE_WEIGHTS.items():
        if x == 0.5:       # STEP_FLOOR: half a texel or a cell is geometry's too; its one use named instead
            assert f"PROBE_{k}" in kernel and f"w['{k}']" in writer, k
            continue
        assert not re.search(rf"(?<![\w.]){re.escape(repr(x))}f?(?![\w])", kernel), k
        assert not re.search(rf"(?<![\w.]){re.escape(repr(x))}(?![\w])", writer), k


def test_basis_headers_are_generated_from_bases():
    """kernels/basis_headers.h is what scene/layout.py emits from BASES (make docs), so a new
    basis's module and header are all the kernels need; the module is found by its NAME and placed
    by its RANK, with no list of bases by hand."""
    from iblbake.core import bases
    from iblbake.scene.layout import basis_headers_text

    path = Path(__file__).resolve().parents[1] / "kernels" / "basis_headers.h"
    assert path.read_text() == basis_headers_text(), "stale: run make docs"
    src = (ROOT / "core" / "bases" / "__init__.py").read_text()
    assert "import ambient_dice" not in src and list(bases.BASES) == ["sh", "l1_geomerics", "zh3", "sg",
                                                                      "ambient_dice", "haar"]


def test_a_volume_is_a_frozen_record_with_its_basis():
    """bake() and load() give a Volume (render/probes/volume.py): frozen, its basis the registry's
    entry, its grid and texel counts read from its grid and settings; sampled() a new record with
    the sampling settings, read by the names of the volume record's fields."""
    import dataclasses

    import pytest

    from iblbake.core.bases.probes import PROBE_BASES
    from iblbake.render import probes
    from iblbake.scene.layout import PROBE_VOLUME

    grid = probes.Grid((0.0, 0.0, 0.0), (0.5, 0.5, 0.5), (2, 3, 4))
    st = {"irradiance": "zh3", "irradiance_texels": 6, "distance_texels": 14, "classification": True,
          "visibility": True, "normal_bias": 0.25, "view_bias": 0.1, "sg_lobes": 9}
    vol = probes.volume_dict(grid, st, np.zeros((24, 5, 3)), np.zeros((48, 64, 2)), np.zeros((24, 4)), {})
    assert vol.basis is PROBE_BASES["zh3"] and vol.representation == "zh3" and vol.counts == (2, 3, 4)
    assert "sg_lobes" not in vol.settings and "visibility" not in vol
    with pytest.raises(dataclasses.FrozenInstanceError):
        vol.representation = "sh"
    s = probes.sampled(vol, st)
    assert isinstance(s, probes.Volume) and s is not vol and vol.normal_bias is None
    assert {k: s[k] for k in PROBE_VOLUME} == {"counts": (2, 3, 4), "origin": (0.0, 0.0, 0.0),
                                               "spacing": (0.5, 0.5, 0.5), "normal_bias": 0.125, "view_bias": 0.05,
                                               "irradiance_texels": 6, "distance_texels": 14}
