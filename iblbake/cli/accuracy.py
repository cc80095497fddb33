"""`iblbake accuracy`: what each approximation of a scene's lighting costs in time and how far it
is from the converged reference (iblbake/study/accuracy.py)."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path

import click

from iblbake.cli.options import (API_FLAGS, Console, cache_option, json_text, non_negative, refuse_foreign,
                                 scene_options)
from iblbake.errors import IblbakeError

FILES = {"table.md": "Markdown table", "table.csv": "CSV", "accuracy.json": "JSON", "plot.png": "error-time plot",
         "errors.png": "best and worst rungs with error maps", "index.html": "the interactive report"}


def bounces_value(v: str):
    from iblbake.scene.schema import MAX_BOUNCES     # the scene key's range, effects.reference.bounces
    if v == "unbounded":
        return v
    if v.isdigit() and 1 <= int(v) <= MAX_BOUNCES:
        return int(v)
    raise click.BadParameter(f"{v!r}: use unbounded or a count from 1 to {MAX_BOUNCES}")


@click.command("accuracy")
@click.argument("scene_path", metavar="SCENE")
@click.option("--output", "-o", "out_dir", type=click.Path(file_okay=False), default=None, metavar="DIR",
              help="Write table.md, table.csv, accuracy.json, plot.png (error against time, the Pareto "
                   "frontier marked), errors.png (best and worst rungs beside their error maps) and "
                   "index.html (every rung against the reference, interactive; its images in report/) here.")
@click.option("--ladder", "ladder_path", type=click.Path(dir_okay=False), default=None, metavar="FILE|realtime|bases|probe_bases|lightmaps",
              help="The rungs to run instead of the default ladder: `realtime` (the real-time modes as shipped: "
                   "SH, GTAO, probes; importance, the split sum, lobe, SSR, reflection probes), `bases` (every "
                   "directional basis and size of the diffuse light: SH, L1 Geomerics, ZH3, SG, ambient dice, Haar), "
                   "`probe_bases` (every representation of the irradiance probes: octahedral, L2 SH and the bases "
                   "that fit from a probe's rays; and the specular term from the bases that carry it), "
                   "`lightmaps` (the scene's lightmap: section baked in irradiance, L1 SH, L2 SH and SG at its "
                   "texels_per_unit x 0.5, 1 and 2, each rung's atlas bytes and bake time), or a file "
                   "{rungs: [AXIS, ...]}, each axis in the sweep syntax ({key, values}, {key, range}, {steps}) "
                   "with optional term: and with:.")
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE",
              help="Override a scene value for the reference and every rung (as render --set).")
@click.option("--max-side", type=click.IntRange(8, 8192), default=320, show_default=True,
              help="The study's resolution: the scene's, scaled so its longer side is at most this.")
@click.option("--repeats", type=click.IntRange(1, 100), default=3, show_default=True,
              help="Timed renders per rung; its time is their median.")
@click.option("--target-noise", type=float, default=0.003, show_default=True, callback=non_negative,
              help="The reference's stopping rule: each seed stops when its relative standard error is below this...")
@click.option("--max-samples", type=click.IntRange(1, 1 << 20), default=4096, show_default=True,
              help="...or at this many samples per pixel.")
@click.option("--visibility/--no-visibility", default=True, show_default=True,
              help="The reference traces occlusion (what the approximations leave out: the frame's true "
                   "error); --no-visibility measures each approximation's own error, every object lit as alone.")
@click.option("--bounces", default="unbounded", show_default=True, callback=lambda _c, _p, v: bounces_value(v),
              help="The reference's bounces: unbounded (the converged answer, light between surfaces "
                   "included) or N; 1 is the direct light alone, the reference before paths.")
@click.option("--flip/--no-flip", default=True, show_default=True, help="Also measure mean HDR-FLIP.")
@click.option("--max-error", type=float, default=None, callback=non_negative, metavar="X",
              help="Exit non-zero if the scene as configured (both terms) is further than X (relative RMSE) "
                   "from the reference: a CI guard.")
@cache_option("Bake cache folder (the reference is cached there too)")
@click.option("--jobs", "-j", type=click.IntRange(min=1), default=1, show_default=True,
              help="Render the reference seeds in N worker processes (each its own OpenCL runtime on "
                   "--device or one of --devices) into the cache; the rungs are then timed alone.")
@click.option("--devices", default=None, metavar="SPEC,SPEC,...",
              help="With --jobs: one device per worker, in turn, e.g. gpu,cpu.")
@scene_options
def accuracy_command(scene_path, out_dir, ladder_path, overrides, max_side, repeats, target_noise, max_samples,
                     visibility, bounces, flip, max_error, cache_dir, jobs, devices, force, device, quiet, as_json):
    """Render SCENE's converged reference (diffuse and specular with visibility and every
    bounce, two seeds, its noise measured), then a ladder of approximations of each term the
    scene calls for (SH bands and windows; importance N, mip selection and bias; prefiltered chain
    size, levels, method and dominant direction; lobe K; AO; fewer reference samples; the direct
    light alone where light passes between surfaces), each timed (median lighting-pass time;
    bakes and kernel builds reported apart as one-off costs) and measured over the object pixels:
    relative RMSE, mean and max relative error, HDR-FLIP. Prints the table with each term's
    Pareto frontier of error against time: for an error budget, the cheapest setting."""
    from iblbake import api
    from iblbake.io import atomic, images
    from iblbake.study import report

    con = Console(quiet, as_json)
    t_start = time.perf_counter()
    out = Path(out_dir) if out_dir else None
    if out is not None:              # the folder is made when the results are written, not before
        for name in FILES:
            atomic.check_writable(out / name)
    if devices and jobs == 1:
        raise click.UsageError("--devices gives each worker its device: give --jobs N too")
    given = click.get_current_context().get_parameter_source("bounces") == click.core.ParameterSource.COMMANDLINE
    stack = contextlib.ExitStack()

    def before_run(study, rungs, reads):
        if out is not None:
            from iblbake.io.guard import refuse_overlaps
            from iblbake.study import html
            writes = [("-o", str(out / name))
                      for name in list(FILES) + html.data_names(len(study.terms) + len(rungs), objects=True)]
            refuse_overlaps(writes, reads)
            refuse_foreign(writes, force, report.header_lines())
        names = [f"reference {t} seed {s}" for t in study.terms for s in study.settings.seeds] + [r.label for r in rungs]
        progress[0] = stack.enter_context(con.stages(names, label="accuracy"))

    progress = [None]
    with stack:
        result = api.accuracy(scene_path, ladder_path, overrides=overrides, max_side=max_side, repeats=repeats,
                              target_noise=target_noise, max_samples=max_samples, visibility=visibility,
                              bounces=bounces if given else None, flip=flip, cache=cache_dir, device=device,
                              jobs=jobs, devices=[d.strip() for d in devices.split(",")] if devices else None,
                              warn=con.warn, progress=lambda: progress[0](), before_run=before_run,
                              names=API_FLAGS)
    study, rungs, rows, front, refs = result.study, result.rungs, result.records, result.frontier, result.reference
    configured, summary = result.configured, result.summary
    title = f"{Path(scene_path).name}: error against time ({summary['device']})"
    if out is not None:
        from iblbake.io.guard import mark
        from iblbake.study import html
        with atomic.Batch() as batch:    # the files replaced together, or none (a full disk)
            batch.write_text(out / "table.md", report.markdown(rows, front))
            batch.write_text(out / "table.csv", report.csv_text(rows, front))
            report.plot(rows, front, out / "plot.png", title, batch)
            images.write_png(out / "errors.png",
                             report.error_sheet(study, rungs, f"{Path(scene_path).name}: best and worst"), batch)
            t_page = time.perf_counter()
            html.write(out, html.study_page(study, rungs, rows, front, title), batch)
            summary["time_split_s"]["report_s"] = round(time.perf_counter() - t_page, 4)
            summary["outputs"] = [str(out / n) for n in FILES]
            summary["elapsed_s"] = round(time.perf_counter() - t_start, 3)
            batch.write_text(out / "accuracy.json",
                             json_text({"generator": mark(), **summary}) + "\n")
    summary["elapsed_s"] = round(time.perf_counter() - t_start, 3)
    split = ", ".join(f"{k[:-2]} {v:.1f} s" for k, v in summary["time_split_s"].items())
    noise = ", ".join(f"{t} {100 * refs[t]['noise']:.2f}% (99% of pixels {100 * refs[t]['noise_bulk']:.2f}%)"
                      for t in study.terms)
    con.result(summary, report.text_table(rows, front)
               + f"\nreference: bounces {bounces if study.paths else '1 (no light passes between surfaces)'}, "
                 f"noise (two seeds) {noise}; configured frame: relative RMSE "
                 f"{100 * configured['relative_rmse']:.2f}%\n"
               + f"{len(rows)} rungs in {summary['elapsed_s']:.1f} s ({split}) on {summary['device']}"
               + (f"; wrote {out}/" if out else ""))
    if max_error is not None and configured["relative_rmse"] > max_error:
        raise IblbakeError(f"{scene_path}: as configured, relative RMSE {configured['relative_rmse']:.4f} against "
                           f"the reference is above --max-error {max_error}")
