"""`iblbake accuracy`: what each approximation of a scene's lighting costs in time and how far it
is from the converged reference (iblbake/study/accuracy.py)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from iblbake.cli.options import (Console, common_options, device_option, force_option, max_pixels_option,
                                  max_texture_pixels_option, non_negative, refuse_foreign)
from iblbake.errors import IblbakeError

FILES = {"table.md": "Markdown table", "table.csv": "CSV", "accuracy.json": "JSON", "plot.png": "error-time plot",
         "errors.png": "best and worst rungs with error maps"}


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
                   "frontier marked) and errors.png (best and worst rungs beside their error maps) here.")
@click.option("--ladder", "ladder_path", type=click.Path(dir_okay=False), default=None, metavar="FILE|realtime|bases",
              help="The rungs to run instead of the default ladder: `realtime` (the real-time modes as shipped: "
                   "SH, GTAO, probes; importance, the split sum, lobe, SSR, reflection probes), `bases` (every "
                   "directional basis and size of the diffuse light: SH, L1 Geomerics, ZH3, SG, ambient dice, Haar), "
                   "or a file "
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
@click.option("--cache", "cache_dir", type=click.Path(file_okay=False), default=None,
              help="Bake cache folder (the reference is cached there too). Default: $IBLBAKE_CACHE, else "
                   "the per-user cache folder.")
@click.option("--jobs", "-j", type=click.IntRange(min=1), default=1, show_default=True,
              help="Render the reference seeds in N worker processes (each its own OpenCL runtime on "
                   "--device or one of --devices) into the cache; the rungs are then timed alone.")
@click.option("--devices", default=None, metavar="SPEC,SPEC,...",
              help="With --jobs: one device per worker, in turn, e.g. gpu,cpu.")
@force_option
@device_option
@max_pixels_option
@max_texture_pixels_option
@common_options
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
    from iblbake import render
    from iblbake.device.runtime import Runtime
    from iblbake.io import atomic, images
    from iblbake.scene import load as scene_load
    from iblbake.study import accuracy as acc, ladder, report

    con = Console(quiet, as_json)
    t_start = time.perf_counter()
    out = Path(out_dir) if out_dir else None
    if out is not None:              # the folder is made when the results are written, not before
        for name in FILES:
            atomic.check_writable(out / name)
    settings = acc.Settings(max_side=max_side, repeats=repeats, target_noise=target_noise, max_samples=max_samples,
                            flip=flip, visibility=visibility, bounces=bounces)
    rt = Runtime(device)
    study = acc.Study(scene_path, overrides, settings, runtime=rt, bakes=render.Bakes(cache_dir), warn=con.warn)
    if click.get_current_context().get_parameter_source("bounces") == click.core.ParameterSource.COMMANDLINE \
            and bounces != 1 and not study.paths:
        why = ("with --no-visibility every object is lit as if alone, so no light passes between them"
               if not visibility else "no light passes between this scene's surfaces")
        con.warn(f"--bounces {bounces}: {why}; the reference is the direct light (bounces 1)")
    if ladder_path in ladder.LADDERS:
        rungs = ladder.LADDERS[ladder_path](study.scene, study.fx)
        ladder_path = None
    elif ladder_path:
        rungs = ladder.ladder_from_file(ladder_path, study.scene, study.fx)
    else:
        rungs = ladder.default_ladder(study.scene, study.fx, rt.info.kind, paths=study.paths)
        over = [r for r in rungs if dict(r.values).get("effects.reference.max_samples", 0) > max_samples]
        if over:                     # measured against a reference of fewer samples: their error is its noise
            con.warn(f"left out {len(over)} rungs with more samples than the reference's --max-samples "
                     f"{max_samples}: {', '.join(r.label for r in over)}")
            rungs = [r for r in rungs if r not in over]
    rungs = [ladder.configured_rung(study.scene, t) for t in study.terms] + rungs
    reads = scene_load.named_input_files(study.scene) + ([("the ladder", ladder_path)] if ladder_path else [])
    for r in rungs:                  # every rung's scene validates before anything renders
        reads += scene_load.named_input_files(study.load(study.rung_values(r), origin=f"ladder rung {r.label!r}"))
    if out is not None:
        from iblbake.io.guard import refuse_overlaps
        refuse_overlaps([("-o", str(out / name)) for name in FILES], reads)
        refuse_foreign([("-o", str(out / name)) for name in FILES], force, report.header_lines())
    names = [f"reference {t} seed {s}" for t in study.terms for s in settings.seeds] + [r.label for r in rungs]
    spread = None
    if jobs > 1:
        from iblbake.study import workers
        specs = [d.strip() for d in devices.split(",")] if devices else [device]
        spread = workers.render_references_parallel(study, jobs, specs)
    elif devices:
        raise click.UsageError("--devices gives each worker its device: give --jobs N too")
    with con.stages(names, label="accuracy") as step:
        study.progress = step
        refs = {t: study.render_reference(t) for t in study.terms}
        rows = [study.run_rung(r) for r in rungs]
    for t in study.terms:
        r = refs[t]
        if "max_samples" in r["stopped"] and r["noise_each"] > 2 * target_noise:
            con.warn(f"the {t} reference stopped at {max_samples} samples per pixel with noise "
                     f"{100 * r['noise']:.2f}% (target {100 * target_noise:g}% per seed): errors below about twice "
                     f"that are its noise. Slow convergence on a path-traced reference is light reaching a "
                     f"surface by a mirror or a glossy lobe from a small bright source (a caustic), which "
                     f"only BSDF sampling finds: raise --max-samples, or --bounces 1 for the direct light")
    configured = study.configured_frame()
    front = acc.frontiers(rows)
    high = acc.above_reference(rows)
    if high:
        con.warn(f"{len(high)} {'rungs have' if len(high) > 1 else 'rung has'} more samples than the reference reached "
                 f"({', '.join(r['label'] for r in high)}): their error is the reference's noise; kept off "
                 f"the frontier (raise --max-samples above theirs to measure them)")
    title = f"{Path(scene_path).name}: error against time ({rt.device_label})"
    summary = {
        "scene": str(scene_path), "device": rt.device_label,
        "resolution": acc.study_resolution(study.scene, max_side), "repeats": repeats,
        "reference": {t: {k: v for k, v in refs[t].items() if k not in ("hdr", "mask")} | {
            "stopping_rule": f"each seed: relative standard error <= {target_noise} or {max_samples} samples",
            "bounces": bounces if study.paths else 1,
            "object_pixels": int(refs[t]["mask"].sum()),
            "measured_pixels": int(study.metric_mask(t, refs[t]["hdr"]).sum())} for t in study.terms},
        "rungs": [{**r, "pareto": r["label"] in front.get(r["term"], [])} for r in rows],
        "frontier": front, "configured": configured,
        "time_split_s": {k: round(v, 3) for k, v in study.times.items()},
    }
    if spread:
        summary["reference_workers"] = spread
    if out is not None:
        from iblbake.io.guard import mark
        with atomic.Batch() as batch:    # the five files replaced together, or none (a full disk)
            batch.write_text(out / "table.md", report.markdown(rows, front))
            batch.write_text(out / "table.csv", report.csv_text(rows, front))
            report.plot(rows, front, out / "plot.png", title, batch)
            images.write_png(out / "errors.png",
                             report.error_sheet(study, rungs, f"{Path(scene_path).name}: best and worst"), batch)
            summary["outputs"] = [str(out / n) for n in FILES]
            summary["elapsed_s"] = round(time.perf_counter() - t_start, 3)
            batch.write_text(out / "accuracy.json",
                             json.dumps({"generator": mark(), **summary}, indent=2, allow_nan=False) + "\n")
    summary["elapsed_s"] = round(time.perf_counter() - t_start, 3)
    split = ", ".join(f"{k[:-2]} {v:.1f} s" for k, v in summary["time_split_s"].items())
    noise = ", ".join(f"{t} {100 * refs[t]['noise']:.2f}%" for t in study.terms)
    con.result(summary, report.text_table(rows, front)
               + f"\nreference: bounces {bounces if study.paths else '1 (no light passes between surfaces)'}, "
                 f"noise (two seeds) {noise}; configured frame: relative RMSE "
                 f"{100 * configured['relative_rmse']:.2f}%\n"
               + f"{len(rows)} rungs in {summary['elapsed_s']:.1f} s ({split}) on {rt.device_label}"
               + (f"; wrote {out}/" if out else ""))
    if max_error is not None and configured["relative_rmse"] > max_error:
        raise IblbakeError(f"{scene_path}: as configured, relative RMSE {configured['relative_rmse']:.4f} against "
                           f"the reference is above --max-error {max_error}")
