"""`iblbake basis`: a panorama's light in a directional basis other than SH (api.basis)."""

from __future__ import annotations

import os

import click

from iblbake.cli.options import (API_FLAGS, Console, check_inputs_exist, check_suffix, common_options,
                                  depfile_option, input_files_of, input_options, non_negative, panorama_reads,
                                  refuse_foreign, report_results, write_texts)
from iblbake.errors import IblbakeError
from iblbake.io.guard import refuse_overlaps

NAMES = ("l1_geomerics", "zh3", "sg", "ambient_dice", "haar")     # core/bases BASES but sh (iblbake sh)
SUFFIXES = {"iblbake": (".json",), "glsl": (".glsl", ".frag", ".vert", ".h", ".txt")}


@click.command("basis")
@click.argument("envs", metavar="ENV...", nargs=-1, required=True)
@click.option("--basis", "name", type=click.Choice(NAMES), required=True,
              help="l1_geomerics (4 floats, Geomerics' non-linear L1), zh3 (5, L1 and a zonal L2), sg (spherical "
                   "Gaussians: --sg-lobes, --sg-fit), ambient_dice (12, the RBF variant: --ad-fit), haar (cube-face "
                   "wavelets, the --haar-coefficients largest kept): docs/conventions.md 'Directional bases'.")
@click.option("--sg-lobes", type=click.Choice(["5", "6", "9", "12"]), default="9", show_default=True,
              help="sg: the number of lobes (fixed Fibonacci axes, one sharpness).")
@click.option("--sg-fit", type=click.Choice(["irradiance", "least_squares", "nnls"]), default="irradiance",
              show_default=True, help="sg: least squares on the irradiance (what the diffuse term reads), or on the "
                                      "radiance: exact least squares, or non-negative (the specular lobe's).")
@click.option("--ad-fit", type=click.Choice(["irradiance", "least_squares", "nnls"]), default="irradiance",
              show_default=True, help="ambient_dice: least squares on the irradiance (what the diffuse term reads), "
                                      "or on the radiance: exact least squares, or non-negative (no negative "
                                      "radiance: the specular lobe's).")
@click.option("--haar-coefficients", type=click.Choice(["16", "32", "64", "128", "256"]), default="64",
              show_default=True, help="haar: the coefficients kept (the largest; 6 of them the faces' means).")
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
                   "and its irradiance function; sg and ambient_dice add their specular ones).")
@click.option("--glsl", is_flag=True, help="Print the basis's GLSL (--format glsl).")
@click.option("--specular-table", type=click.Path(dir_okay=False), default=None, metavar="FILE.exr",
              help="ambient_dice: also write the table its GLSL specular function reads (each lobe averaged over "
                   "the warped GGX lobe; one channel, 129 x 65: docs/conventions.md 'Directional bases').")
@click.option("--error/--no-error", "with_error", default=True, show_default=True,
              help="Measure the basis's irradiance against the exact irradiance (float64, every texel) at 256 "
                   "fixed normals: relative RMSE and max relative error (the JSON's error block).")
@depfile_option
@input_options
@common_options
def basis_command(envs, name, sg_lobes, sg_fit, ad_fit, haar_coefficients, output, force, intensity, fmt, glsl,
                  specular_table, with_error, nonfinite, negative, transfer, primaries, input_layout, max_pixels,
                  depfile, quiet, as_json):
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
    owners = {"sg_lobes": "sg", "sg_fit": "sg", "ad_fit": "ambient_dice", "haar_coefficients": "haar"}
    ctx = click.get_current_context()
    for param, owner in owners.items():
        if owner != name and ctx.get_parameter_source(param) == click.core.ParameterSource.COMMANDLINE:
            raise click.UsageError(f"--{param.replace('_', '-')} is an option of --basis {owner}, not of {name}: "
                                   "leave it out")
    if as_json and fmt == "glsl" and not output:
        raise click.UsageError("--json prints the summary on stdout, where --format glsl prints the GLSL: give -o FILE "
                               "for the GLSL")
    options = {"sg": {"sg_lobes": int(sg_lobes), "sg_fit": sg_fit}, "ambient_dice": {"ad_fit": ad_fit},
               "haar": {"haar_coefficients": int(haar_coefficients)}}.get(name, {})
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
    if specular_table and name != "ambient_dice":
        raise click.UsageError(f"--specular-table is ambient_dice's (sg's specular has a closed form): leave it out "
                               f"with --basis {name}")
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
        from iblbake.core import bases
        from iblbake.io import images
        images.write_exr(specular_table, bases.BASES[name].specular_table(options).astype("float32"),
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
