"""`iblbake export-gltf`: a panorama as a glTF EXT_lights_image_based light."""

from __future__ import annotations

import os
import time
from pathlib import Path

import click

from iblbake.cli.options import (POLICY_FLAGS, Console, cache_option, check_inputs_exist, common_options,
                                 depfile_option, device_option, input_files_of, input_options, panorama_reads,
                                 refuse_foreign)
from iblbake.io.guard import refuse_overlaps


def _power_of_two(ctx, param, value):
    if value is not None and (value < 1 or value & (value - 1)):
        raise click.BadParameter(f"{value} is not a power of two (the extension's images are 2^n square)")
    return value


def _scale(ctx, param, value):
    if value == "auto":
        return value
    try:
        v = float(value)
    except ValueError:
        raise click.BadParameter(f"{value!r}: give a number > 0 or 'auto'") from None
    if not (v > 0 and v < float("inf")):
        raise click.BadParameter(f"{value}: give a finite number > 0 or 'auto'")
    return v


@click.command("export-gltf")
@click.argument("env", metavar="ENV")
@click.option("--output", "-o", type=click.Path(dir_okay=False), required=True,
              help="OUT.gltf (the face PNGs beside it, OUT_specular_MIP_FACE.png) or OUT.glb (one file).")
@click.option("--force", "-f", is_flag=True,
              help="Overwrite -o (and its face PNGs, --depfile) even where it is not a light iblbake wrote.")
@click.option("--size", type=click.IntRange(min=1), default=256, show_default=True, callback=_power_of_two,
              help="specularImageSize: the face size of mip 0 (a power of two).")
@click.option("--min-size", type=click.IntRange(min=1), default=16, show_default=True, callback=_power_of_two,
              help="Face size of the last mip, which is roughness 1 (the extension suggests 16).")
@click.option("--roughness-mapping", "mapping", type=click.Choice(["babylon", "linear"]), default="babylon",
              show_default=True,
              help="The GGX roughness each mip is baked at. babylon: what Babylon.js reads mip k of N for, "
                   "alpha = size^(k/(N-1) - 1) (mip 0 the mirror); linear: r = k/(N-1), as the extension's "
                   "text puts it.")
@click.option("--rgbd-scale", "scale", default="1", show_default=True, callback=_scale, metavar="X|auto",
              help="Divide the images by X and write X as the light's intensity (RGBD holds up to 255 per "
                   "texel: brighter texels, a sun, clip). auto: the smallest X that clips nothing, at the cost "
                   "of 8-bit precision in everything dimmer.")
@click.option("--method", type=click.Choice(["auto", "spectral", "convolve", "fis"]), default="auto",
              show_default=True, help="How each prefiltered mip is computed (as iblbake mips --method).")
@cache_option("Bake cache folder")
@click.option("--backend", type=click.Choice(["opencl", "numpy"]), default="opencl", show_default=True,
              help="opencl: the kernels; numpy: their float64 twins (slow; small sizes).")
@depfile_option
@input_options
@device_option
@common_options
def export_gltf_command(env, output, force, size, min_size, mapping, scale, method, cache_dir, backend, nonfinite, negative,
                        transfer, primaries, input_layout, max_pixels, depfile, device, quiet, as_json):
    """Write ENV as a glTF 2.0 image-based light (EXT_lights_image_based): the GGX-prefiltered cube
    map as RGBD PNGs, mip by mip, and the SH irradiance coefficients, in the conventions Babylon.js
    (the extension's reference loader) reads; docs/manual.md "export-gltf" maps them to
    iblbake's. Every file is written atomically, the .gltf last."""
    from iblbake.bake import cache, gltf_light, inputs
    from iblbake.bake import mips as mipsbake
    from iblbake.errors import IblbakeError
    from iblbake.io import images
    from iblbake.io.atomic import check_writable

    con = Console(quiet, as_json)
    out = Path(output)
    if out.suffix.lower() not in (".gltf", ".glb"):
        raise click.BadParameter(f"{output}: give a .gltf or .glb path", param_hint="-o")
    if min_size > size:
        raise click.BadParameter(f"{min_size} is larger than --size {size}", param_hint="--min-size")
    from iblbake.io import gltf
    sizes = gltf_light.level_sizes(size, min_size)
    writes = [("-o", str(out))] + [("-o (a face image beside it)", str(p)) for p in gltf.sidecars(out, len(sizes))]
    refuse_overlaps(writes + ([("--depfile", depfile)] if depfile else []), panorama_reads([env]))
    check_writable(out)
    check_inputs_exist([env])
    if not force:
        # a light export-gltf wrote (its PNGs with it) is replaced, so Makefile rules rerun; nothing else
        if out.exists() and not gltf.written_by_iblbake(out):
            raise IblbakeError(f"{output}: exists and is not a light iblbake wrote; pass --force to overwrite it")
        taken = [p for p in gltf.sidecars(out, len(sizes)) if p.exists()]
        if taken and not (out.exists() and gltf.written_by_iblbake(out)):
            raise IblbakeError(f"{taken[0]}: exists (a face image -o would write); pass --force to overwrite it")
    if depfile:
        refuse_foreign([("--depfile", depfile)], force)
        check_writable(depfile)
    t_start = time.perf_counter()
    root = Path(cache_dir) if cache_dir else cache.default_root()
    check_writable(root / "manifest.json", "cache", shown=root)
    baker = mipsbake.Baker(backend, device)
    mipsbake.check_chain_fits("cubemap", size, lambda s: gltf_light.level_sizes(s, min_size), baker.rt, "--size",
                              candidates=[min_size << k for k in range((size // min_size).bit_length())])
    image, info = inputs.read_environment(env, layout=input_layout, runtime=baker.rt, max_pixels=max_pixels,
                                          nonfinite=nonfinite, negative=negative, transfer=transfer,
                                          primaries=primaries, names=POLICY_FLAGS)
    for w in info.warnings:
        con.warn(w)
    policies = images.read_policies(nonfinite, negative, transfer, primaries, input_layout)
    with con.stages([f"mip {k} (face {s})" for k, s in enumerate(sizes)], label="prefiltering") as step:
        parts = gltf_light.bake(baker, image, info, root, policies, size=size, min_size=min_size, mapping=mapping,
                                method=method, warn=con.warn, progress=step)
    t0 = time.perf_counter()
    from iblbake import __version__
    report = gltf_light.write(out, parts, scale, name=Path(env).stem,
                              extras={"generator": f"iblbake {__version__}", "source": info.path,
                                      "source_sha256": info.sha256, "roughness_mapping": mapping,
                                      "roughness": [round(r, 6) for r in parts["roughness"]]})
    write_s = time.perf_counter() - t0
    if depfile:
        from iblbake.io import depfile as dep
        dep.write(depfile, [([str(out)], [os.path.abspath(f) for f in input_files_of(env)])])
    summary = {"input": env, "output": str(out), "device": baker.device_label, "cache": str(root),
               "entries": parts["entries"], "roughness_mapping": mapping, **report,
               "timings": {"write_s": round(write_s, 4), "elapsed_s": round(time.perf_counter() - t_start, 4)}}
    lines = [f"wrote {out} ({len(report['files'])} file{'s' if len(report['files']) > 1 else ''}): "
             f"{len(sizes)} mips of face {size} to {sizes[-1]}, intensity {report['intensity']:.6g}"]
    for k, m in enumerate(report["mips"]):
        lines.append(f"  mip {k}: face {m['size']}, roughness {m['roughness']:.4f} (alpha {m['alpha']:.5f}), "
                     f"{m['method']}; RGBD round trip {100 * m['relative_rmse']:.3f}% RMSE, "
                     f"{100 * m['clipped_energy']:.3f}% of the energy clipped")
        if m["clipped_energy"] > 1e-3:
            con.warn(f"{out}: mip {k} clips {100 * m['clipped_energy']:.2f}% of its energy at RGBD's 255 "
                     f"(--rgbd-scale auto keeps it, at 8-bit precision cost)")
    lines.append(f"done in {summary['timings']['elapsed_s']:.3f} s on {baker.device_label}")
    con.result(summary, "\n".join(lines))
