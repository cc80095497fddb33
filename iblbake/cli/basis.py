"""`iblbake basis`: a panorama's light in a directional basis other than SH (api.basis)."""

from __future__ import annotations

import os

import click

from iblbake.cli.options import (API_FLAGS, Console, check_inputs_exist, check_suffix, common_options,
                                  depfile_option, input_files_of, input_options, non_negative, panorama_reads,
                                  refuse_foreign, report_results, write_texts)
from iblbake.errors import IblbakeError
from iblbake.io.guard import refuse_overlaps

SUFFIXES = {"iblbake": (".json",), "glsl": (".glsl", ".frag", ".vert", ".h", ".txt")}


def names() -> tuple:
    """The bases `iblbake basis` projects onto: core/bases BASES but sh (iblbake sh)."""
    from iblbake.core.bases import BASES
    return tuple(n for n, m in BASES.items() if m.HEADER)


def owners() -> dict:
    """Each basis option (its module's OPTIONS key) -> the basis it belongs to."""
    from iblbake.core.bases import BASES
    return {k: n for n in names() for k in BASES[n].OPTIONS}


def _flag(key: str) -> str:
    return "--" + key.replace("_", "-")


def basis_params() -> list:
    """--basis and every basis's option flags (--KEY of its OPTIONS: choices, default, doc), from BASES."""
    from iblbake.core.bases import BASES
    flags = {n: ", ".join(_flag(k) for k in BASES[n].OPTIONS) for n in names()}
    params = [click.Option(["--basis", "name"], type=click.Choice(names()), required=True,
                           help="; ".join(f"{n} ({BASES[n].TITLE}{': ' + flags[n] if flags[n] else ''})"
                                          for n in names()) + ": docs/conventions.md 'Directional bases'.")]
    for key, owner in owners().items():
        choices, default, doc = BASES[owner].OPTIONS[key]
        params.append(click.Option([_flag(key), key], type=click.Choice([str(c) for c in choices]),
                                   default=str(default), show_default=True, help=doc + "."))
    return params


class BasisCommand(click.Command):
    """`iblbake basis`, its --basis and option flags built from BASES when it parses or prints its
    help (the bases load numpy: `iblbake --help` lists the command without them)."""

    def get_params(self, ctx):
        if not any(p.name == "name" for p in self.params):
            self.params[1:1] = basis_params()          # after ENV...
        return super().get_params(ctx)


def basis_options(name: str, given: dict) -> dict:
    """The options of basis `name` from the flags' strings, typed as its OPTIONS' choices."""
    from iblbake.core.bases import BASES
    return {k: next(c for c in BASES[name].OPTIONS[k][0] if str(c) == given[k]) for k in BASES[name].OPTIONS}


@click.command("basis", cls=BasisCommand)
@click.argument("envs", metavar="ENV...", nargs=-1, required=True)
@click.option("--output", "-o", type=click.Path(), default=None,
              help="Write the document here (atomically); with several ENV, a folder (DIR/NAME.json or .glsl "
                   "each). Without it, --format glsl prints to stdout and the JSON is not written.")
@click.option("--force", "-f", is_flag=True, help="Overwrite --output (and --depfile) even where it is not a file "
                                                  "iblbake wrote.")
@click.option("--intensity", type=float, default=1.0, show_default=True, callback=non_negative,
              help="Scale the panorama's radiance.")
@click.option("--format", "fmt", type=click.Choice(["iblbake", "glsl"]), default="iblbake", show_default=True,
              help="What -o holds (or stdout without -o): iblbake's JSON document (the coefficients, their "
                   "layout, the bytes a probe of them takes, the error), or the basis's GLSL (its coefficients "
                   "and its irradiance function; a basis that carries a specular lobe adds its specular one).")
@click.option("--glsl", is_flag=True, help="Print the basis's GLSL (--format glsl).")
@click.option("--specular-table", type=click.Path(dir_okay=False), default=None, metavar="FILE.exr",
              help="A basis whose GLSL specular function reads a table: also write it (each lobe "
                   "averaged over the warped GGX lobe; one channel: docs/conventions.md 'Directional bases').")
@click.option("--error/--no-error", "with_error", default=True, show_default=True,
              help="Measure the basis's irradiance against the exact irradiance (float64, every texel) at 256 "
                   "fixed normals: relative RMSE and max relative error (the JSON's error block).")
@depfile_option
@input_options
@common_options
def basis_command(envs, name, output, force, intensity, fmt, glsl, specular_table, with_error, nonfinite, negative,
                  transfer, primaries, input_layout, max_pixels, depfile, quiet, as_json, **given):
    """Project each panorama ENV onto a directional basis (exact texel integrals, float64; least
    squares where the lobes are not orthogonal) and write its coefficients for an engine: the
    same projection `effects.diffuse: <basis>` renders with. Spherical harmonics: `iblbake sh`.
    """
    from iblbake.io.atomic import check_writable

    con = Console(quiet, as_json)
    if glsl:
        if fmt != "iblbake" and fmt != "glsl":
            raise click.UsageError(f"--glsl is --format glsl: leave out --format {fmt}")
        fmt = "glsl"
    ctx = click.get_current_context()
    for param, owner in owners().items():
        if owner != name and ctx.get_parameter_source(param) == click.core.ParameterSource.COMMANDLINE:
            raise click.UsageError(f"--{param.replace('_', '-')} is an option of --basis {owner}, not of {name}: "
                                   "leave it out")
    if as_json and fmt == "glsl" and not output:
        raise click.UsageError("--json prints the summary on stdout, where --format glsl prints the GLSL: give -o FILE "
                               "for the GLSL")
    options = basis_options(name, given)
    suffix = SUFFIXES[fmt][0]
    if len(envs) > 1:
        if fmt != "iblbake" and not output:
            raise IblbakeError(f"--format {fmt} prints one panorama's basis; give one ENV or -o DIR/")
        if output and not (output.endswith("/") or os.path.isdir(output)):
            raise IblbakeError(f"-o {output}: with {len(envs)} panoramas, -o is a folder (end it with /)")
        outputs = [os.path.join(output, os.path.splitext(os.path.basename(e))[0] + suffix) if output else None
                   for e in envs]
    else:
        outputs = [output]
    from iblbake.core.bases import BASES
    tables = [n for n in names() if hasattr(BASES[n], "specular_table")]
    if specular_table and name not in tables:
        raise click.UsageError(f"--specular-table is {' and '.join(tables)}'s (the others' specular, where they "
                               f"carry one, has a closed form): leave it out with --basis {name}")
    if specular_table:
        check_suffix(specular_table, (".exr",), "--specular-table", "a table")
    same = {(os.path.realpath(e), o): o for e, o in zip(envs, outputs) if o}
    writes = ([("-o", o) for o in same.values()] + ([("--depfile", depfile)] if depfile else [])
              + ([("--specular-table", specular_table)] if specular_table else []))
    refuse_overlaps(writes, panorama_reads(envs))
    if len(envs) == 1 and output:
        check_suffix(output, SUFFIXES[fmt], "-o", f"--format {fmt}")
    for _flag, out in writes:
        check_writable(out)
    refuse_foreign(writes, force)
    check_inputs_exist(envs)
    # every panorama is projected before any file is written: a bad one among several leaves nothing
    results = [_project_one(env, name, options, intensity, fmt, with_error, nonfinite, negative, transfer,
                            primaries, input_layout, max_pixels, con) for env in envs]
    if specular_table:
        from iblbake.io import images
        images.write_exr(specular_table, BASES[name].specular_table(options).astype("float32"),
                         channels=("R",))
    results = write_texts(results, outputs, fmt)
    if depfile:
        from iblbake.io import depfile as dep
        dep.write(depfile, [([o for o in (out, specular_table) if o],
                             [os.path.abspath(f) for f in input_files_of(env)])
                            for env, out in zip(envs, outputs) if out or specular_table])
    if specular_table:
        for summary, _ in results:
            summary["specular_table"] = specular_table
    report_results(con, results, fmt, not output, as_json, quiet)


def _project_one(env, name, options, intensity, fmt, with_error, nonfinite, negative, transfer, primaries,
                 input_layout, max_pixels, con):
    from iblbake import api

    with con.stages(["reading", "projecting"], label="basis") as stage:
        pano = api.load_panorama(env, primaries, layout=input_layout, nonfinite=nonfinite, negative=negative,
                                 transfer=transfer, max_pixels=max_pixels, names=API_FLAGS)
        stage()
        result = api.basis(pano, name, intensity=intensity, error=with_error, **options)
        stage()
    for w in pano.warnings:
        con.warn(w)
    doc, info = result.document, pano.info
    summary = {k: doc[k] for k in ("format", "format_version", "basis", "label", "options", "floats", "bytes",
                                   "specular", "coefficients", "timings", "elapsed_s") + (("error",) if with_error else ())}
    summary["input"] = {k: doc["input"][k] for k in ("path", "width", "height", "sha256")}
    human = (f"{result.label}: {doc['floats']} values a channel ({doc['bytes']['fp16']} bytes in fp16) of "
             f"{info.path} ({info.width}x{info.height}) in {doc['elapsed_s']:.3f} s")
    if with_error:
        e = doc["error"]
        human += (f"; irradiance against the exact: relative RMSE {100 * e['relative_rmse']:.2f}%, max "
                  f"{100 * e['max_relative_error']:.1f}%")
    return summary, human, result.export(fmt)
