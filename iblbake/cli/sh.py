"""`iblbake sh`: spherical-harmonic irradiance coefficients of a panorama."""

from __future__ import annotations

import math
import os

import click

from iblbake.cli.options import (API_FLAGS, Console, check_inputs_exist, check_suffix, common_options,
                                  depfile_option, device_option, finite, input_files_of, input_options,
                                  non_negative, panorama_reads, refuse_foreign, report_results, write_texts)
from iblbake.io.guard import refuse_overlaps
from iblbake.errors import IblbakeError


@click.command("sh")
@click.argument("envs", metavar="ENV...", nargs=-1, required=True)
@click.option("--output", "-o", type=click.Path(), default=None,
              help="Write the JSON document here (atomically); with several ENV, a folder (DIR/NAME.json "
                   "each). Without it, nothing is written. An existing iblbake SH document is replaced; any "
                   "other existing file needs --force.")
@click.option("--force", "-f", is_flag=True, help="Overwrite --output (and --depfile) even where it is not a file "
                                                  "iblbake wrote.")
@click.option("--bands", type=click.IntRange(1, 16), default=3, show_default=True,
              help="Number of SH bands (l = 0..bands-1; 3 gives the classic 9 coefficients).")
@click.option("--window", type=click.Choice(["none", "hann", "lanczos"]), default="none", show_default=True,
              help="Ringing reduction applied per band: hann w_l=(1+cos(pi l/bands))/2, "
                   "lanczos w_l=sinc(l/bands). Reduces negative lobes around bright suns.")
@click.option("--backend", type=click.Choice(["auto", "opencl", "numpy"]), default="auto", show_default=True,
              help="opencl: the reduction kernel; numpy: the float64 host path (same math); auto: numpy "
                   "where it is quicker than starting OpenCL (texels x bands^2 up to 4e7: a 1024x512 "
                   "panorama up to 8 bands), else opencl.")
@click.option("--rotate-y", type=float, default=0.0, show_default=True, callback=finite, metavar="DEG",
              help="Rotate the panorama about +y by DEG degrees (+x towards -z).")
@click.option("--intensity", type=float, default=1.0, show_default=True, callback=non_negative,
              help="Scale the panorama's radiance.")
@click.option("--format", "fmt", type=click.Choice(["iblbake", "filament", "threejs", "gltf", "glsl"]),
              default="iblbake", show_default=True,
              help="What -o holds (or stdout without -o): iblbake's JSON document; filament: cmgen's sh.txt "
                   "(IndirectLight irradiance, pre-scaled by its basis constants and 1/pi); threejs: a "
                   "LightProbe's SphericalHarmonics3 as JSON (radiance coefficients); gltf: an "
                   "EXT_lights_image_based light's irradianceCoefficients (as Babylon.js reads them; "
                   "export-gltf writes the whole light); glsl: a function with the irradiance coefficients. "
                   "docs/manual.md 'SH for engines' gives each convention.")
@click.option("--glsl", is_flag=True, help="Print a GLSL function with the irradiance coefficients (--format glsl).")
@click.option("--error/--no-error", "with_error", default=True, show_default=True,
              help="Measure the SH irradiance against the exact irradiance (float64, every texel) at 256 "
                   "fixed normals: relative RMSE, max relative error, ringing (the JSON's error block).")
@depfile_option
@input_options
@device_option
@common_options
def sh_command(envs, output, force, bands, window, backend, rotate_y, intensity, fmt, glsl, with_error, nonfinite,
               negative, transfer, primaries, input_layout, max_pixels, depfile, device, quiet, as_json):
    """Project each panorama ENV onto spherical harmonics and bake irradiance coefficients (one
    process for a whole folder: `iblbake sh *.exr -o DIR/`).

    The JSON holds the basis description, the radiance coefficients L_lm, the irradiance
    coefficients E_lm = Ahat_l * L_lm (evaluate with max(0, sum E_lm Y_lm(n)); diffuse is
    albedo/pi times that), the input's size and hash, the options and timings.
    """
    from iblbake.io.atomic import check_writable

    from iblbake.bake import sh as shbake

    con = Console(quiet, as_json)
    if glsl:
        if fmt not in ("iblbake", "glsl"):
            raise click.UsageError(f"--glsl is --format glsl: leave out --format {fmt}")
        fmt = "glsl"
    if as_json and fmt != "iblbake" and not output:
        raise click.UsageError(f"--json prints the summary on stdout, where --format {fmt} prints its text: give -o "
                               "FILE for the text")
    if fmt in ("filament", "threejs", "gltf") and bands > 3:
        raise click.UsageError(f"--format {fmt} holds at most 3 bands (9 coefficients): give --bands 3 or fewer")
    if len(envs) > 1:
        if fmt != "iblbake" and not output:
            raise IblbakeError(f"--format {fmt} prints one panorama's coefficients; give one ENV or -o DIR/")
        if output and not (output.endswith("/") or os.path.isdir(output)):
            raise IblbakeError(f"-o {output}: with {len(envs)} panoramas, -o is a folder (end it with /)")
        outputs = [os.path.join(output, os.path.splitext(os.path.basename(e))[0] + shbake.SUFFIX[fmt])
                   if output else None for e in envs]
    else:
        outputs = [output]
    # one panorama named twice writes its one document once; two panoramas onto one name are refused
    same = {(os.path.realpath(e), o): o for e, o in zip(envs, outputs) if o}
    writes = [("-o", o) for o in same.values()] + ([("--depfile", depfile)] if depfile else [])
    refuse_overlaps(writes, panorama_reads(envs))
    if len(envs) == 1 and output:
        check_suffix(output, shbake.SUFFIXES[fmt], "-o", f"--format {fmt}")
    for flag, out in writes:
        check_writable(out)
    refuse_foreign(writes, force)      # its own earlier documents are replaced (Makefile reruns)
    check_inputs_exist(envs)
    # every panorama is projected before any file is written: a bad one among several leaves nothing
    results = [_project_one(env, bands, window, backend, rotate_y, intensity, fmt, with_error,
                            nonfinite, negative, transfer, primaries, input_layout, max_pixels, device, con)
               for env in envs]
    results = write_texts(results, outputs, fmt)
    if depfile:
        from iblbake.io import depfile as dep
        dep.write(depfile, [([out], [os.path.abspath(f) for f in input_files_of(env)]) for env, out in zip(envs, outputs) if out])
    report_results(con, results, fmt, not output, as_json, quiet)


def _project_one(env, bands, window, backend, rotate_y, intensity, fmt, with_error, nonfinite, negative, transfer,
                 primaries, input_layout, max_pixels, device, con):
    from iblbake import api

    with con.stages(["reading", "projecting"], label="sh") as stage:
        pano = api.load_panorama(env, primaries, layout=input_layout, nonfinite=nonfinite, negative=negative,
                                 transfer=transfer, max_pixels=max_pixels, names=API_FLAGS)
        stage()
        result = api.sh(pano, bands, window, rotate_y=rotate_y, intensity=intensity, backend=backend, device=device,
                        error=with_error, names=API_FLAGS)
        stage()
    for w in pano.warnings:
        con.warn(w)
    doc, info = result.document, pano.info
    text = result.export(fmt)
    summary = {k: doc[k] for k in ("format", "format_version", "bands", "window", "irradiance", "device",
                                   "timings", "elapsed_s") + (("error",) if with_error else ())}
    summary["input"] = {k: doc["input"][k] for k in ("path", "width", "height", "sha256")}
    dc = doc["radiance"][0]
    human = (f"{bands * bands} SH coefficients of "
             f"{info.path} ({info.width}x{info.height}) in {doc['elapsed_s']:.3f} s on {doc['device']}; "
             f"mean radiance {[round(c / (2 * math.sqrt(math.pi)), 5) for c in dc]}")
    if with_error:
        e = doc["error"]
        human += (f"; irradiance against the exact: relative RMSE {100 * e['relative_rmse']:.2f}%, max "
                  f"{100 * e['max_relative_error']:.1f}%, ringing {100 * e['most_negative_relative']:.2f}% of the mean")
    if info.negative and negative == "keep":
        human += (f"; {info.negative} {'tiny ' if info.negative_tiny else ''}negative values kept "
                  f"(min {info.negative_min:.3g}{'' if info.negative_tiny else ', see the warning'})")
    return summary, human, text
