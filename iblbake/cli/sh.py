"""`iblbake sh`: spherical-harmonic irradiance coefficients of a panorama."""

from __future__ import annotations

import json
import math
import os
import time

import click

from iblbake.cli.options import (POLICY_FLAGS, Console, common_options, device_option, finite, input_options,
                                  non_negative)
from iblbake.errors import IblbakeError


def _check_overwrite(output: str, force: bool, source: str):
    """sh replaces its own earlier documents (Makefile reruns) but nothing else unless --force,
    and never its input."""
    from iblbake.bake import sh as shbake

    out = os.path.realpath(output)
    if os.path.exists(source) and out == os.path.realpath(source):
        raise IblbakeError(f"-o {output}: is the input panorama; choose another output path")
    if force or not os.path.exists(out):
        return
    try:
        with open(out, "rb") as f:
            ours = json.loads(f.read(1 << 22)).get("format") == shbake.FORMAT
    except (OSError, ValueError, AttributeError):
        ours = False
    if not ours:
        raise IblbakeError(f"{output}: exists and is not an iblbake SH document; pass --force to "
                           f"overwrite it")


@click.command("sh")
@click.argument("env", metavar="ENV")
@click.option("--output", "-o", type=click.Path(dir_okay=False), default=None,
              help="Write the JSON document here (atomically). Without it, nothing is written. An "
                   "existing iblbake SH document is replaced; any other existing file needs --force.")
@click.option("--force", "-f", is_flag=True, help="Overwrite --output even if it is not an iblbake SH document.")
@click.option("--bands", type=click.IntRange(1, 16), default=3, show_default=True,
              help="Number of SH bands (l = 0..bands-1; 3 gives the classic 9 coefficients).")
@click.option("--window", type=click.Choice(["none", "hann", "lanczos"]), default="none", show_default=True,
              help="Ringing reduction applied per band: hann w_l=(1+cos(pi l/bands))/2, "
                   "lanczos w_l=sinc(l/bands). Reduces negative lobes around bright suns.")
@click.option("--backend", type=click.Choice(["opencl", "numpy"]), default="opencl", show_default=True,
              help="opencl: the reduction kernel; numpy: the float64 per-texel reference.")
@click.option("--rotate-y", type=float, default=0.0, show_default=True, callback=finite, metavar="DEG",
              help="Rotate the panorama about +y by DEG degrees (+x towards -z).")
@click.option("--intensity", type=float, default=1.0, show_default=True, callback=non_negative,
              help="Scale the panorama's radiance.")
@click.option("--glsl", is_flag=True, help="Print a GLSL function with the irradiance coefficients.")
@input_options
@device_option
@common_options
def sh_command(env, output, force, bands, window, backend, rotate_y, intensity, glsl, nonfinite, negative,
               max_pixels, device, quiet, as_json):
    """Project the panorama ENV onto spherical harmonics and bake irradiance coefficients.

    The JSON holds the basis description, the radiance coefficients L_lm, the irradiance
    coefficients E_lm = Ahat_l * L_lm (evaluate with max(0, sum E_lm Y_lm(n)); diffuse is
    albedo/pi times that), the input's size and hash, the options and timings.
    """
    from iblbake.io import images
    from iblbake.bake import sh as shbake

    con = Console(quiet, as_json)
    if output:
        from iblbake.io.atomic import check_writable
        check_writable(output)
        _check_overwrite(output, force, env)
    t_start = time.perf_counter()
    with con.stages(["reading", "projecting"], label="sh") as stage:
        t0 = time.perf_counter()
        image, info = images.read_panorama(env, max_pixels=max_pixels, nonfinite=nonfinite, negative=negative,
                                           names=POLICY_FLAGS)
        read_s = time.perf_counter() - t0
        stage()
        rt = None
        device_label = "numpy (float64, host)"
        if backend == "opencl":
            from iblbake.device import runtime as cl
            rt = cl.Runtime(device)
            device_label = rt.device_label
        coeffs, project_s = shbake.project(image, bands, backend, rt, rotate_y)
        stage()
    for w in info.warnings:
        con.warn(w)
    coeffs = coeffs * intensity
    options = {"bands": bands, "window": window, "backend": backend, "rotate_y_deg": rotate_y,
               "intensity": intensity, "nonfinite": nonfinite, "negative": negative}
    timings = {"read_s": round(read_s, 6), "project_s": round(project_s, 6)}
    doc = shbake.document(coeffs, bands=bands, window=window, info=info, options=options,
                          device=device_label, timings=timings)
    doc["elapsed_s"] = round(time.perf_counter() - t_start, 6)
    if output:
        from iblbake.io.atomic import write_json
        write_json(output, doc)
    if glsl:
        click.echo(shbake.glsl_snippet(doc), nl=False)
    summary = {k: doc[k] for k in ("format", "format_version", "bands", "window", "irradiance", "device",
                                   "timings", "elapsed_s")}
    summary["input"] = {k: doc["input"][k] for k in ("path", "width", "height", "sha256")}
    summary["output"] = output
    dc = doc["radiance"][0]
    human = (f"{'wrote ' + output + ': ' if output else ''}{bands * bands} SH coefficients of "
             f"{info.path} ({info.width}x{info.height}) in {doc['elapsed_s']:.3f} s on {device_label}; "
             f"mean radiance {[round(c / (2 * math.sqrt(math.pi)), 5) for c in dc]}")
    if info.negative and negative == "keep":
        human += f"; {info.negative} tiny negative values kept (min {info.negative_min:.3g})"
    if glsl and not as_json:
        if not quiet:
            click.echo(human, err=True)
    else:
        con.result(summary, human)
