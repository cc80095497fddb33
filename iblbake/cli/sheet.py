"""`iblbake sheet`: a sweep's cells rendered in one process and assembled into a contact sheet."""

from __future__ import annotations

import os
import time
from pathlib import Path

import click

from iblbake.cli.options import (Console, cache_option, depfile_option, refuse_foreign, scene_options)
from iblbake.errors import IblbakeError


def _cell_size(ctx, param, value):
    if value is None:
        return None
    try:
        w, h = (int(x) for x in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"{value!r}: give WIDTHxHEIGHT, e.g. 256x256") from None
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise click.BadParameter(f"{value!r}: each side from 1 to 16384")
    return w, h


def _devices(ctx, param, value):
    if value is None:
        return None
    specs = [v.strip() for v in value.split(",")]
    if not all(specs):
        raise click.BadParameter(f"{value!r}: give device specs separated by commas, e.g. gpu:0,gpu:1,cpu")
    return specs


def _resources(ctx, param, value):
    if value is None:
        return None
    out = {}
    for part in value.split(","):
        name, _, amount = part.partition("=")
        try:
            out[name.strip()] = float(amount)
        except ValueError:
            raise click.BadParameter(f"{value!r}: give NAME=AMOUNT[,NAME=AMOUNT], e.g. GPU=1") from None
        if not name.strip() or out[name.strip()] <= 0:
            raise click.BadParameter(f"{part!r}: a resource name and an amount above 0")
    return out


def _shard(ctx, param, value):
    if value is None:
        return None
    try:
        i, n = (int(x) for x in value.split("/"))
    except ValueError:
        raise click.BadParameter(f"{value!r}: give I/N, e.g. 2/3") from None
    if not 1 <= i <= n:
        raise click.BadParameter(f"{value!r}: I from 1 to N")
    return i, n


@click.command("sheet")
@click.argument("scene_path", metavar="SCENE")
@click.option("--output", "-o", "outputs", multiple=True, type=click.Path(dir_okay=False),
              help="The sheet: .png (tone-mapped cells with title, axis labels and captions) or .exr (the "
                   "linear cells, a mosaic without text); repeatable. Required but with --shard.")
@click.option("--rows", "rows", default=None, metavar="KEY.PATH=SPEC",
              help="The row axis, replacing the scene's sweep.rows: KEY.PATH=START:STOP:COUNT[:linear|geometric] "
                   "(a range, e.g. 0:1:5 or 1:256:9:geometric) or KEY.PATH=v1,v2,... (values, as YAML).")
@click.option("--columns", "columns", default=None, metavar="KEY.PATH=SPEC", help="The column axis, as --rows.")
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE",
              help="Override a scene value for every cell (as render --set).")
@click.option("--cell-size", default=None, callback=_cell_size, metavar="WxH",
              help="Each cell's resolution (replaces camera.resolution).")
@click.option("--label-format", default=None, metavar="FMT",
              help="Caption of a step of a key/values or range axis, a Python format with {value} and {key}, "
                   "e.g. 'r = {value}'. Default: the value.")
@click.option("--caption", type=click.Choice(["values", "time", "none"]), default="values", show_default=True,
              help="Under each cell: its values, its values and the time of its passes (the median of "
                   "--repeat full frames after a warm-up; kernel builds and bakes are one-off costs, in "
                   "--json), or nothing.")
@click.option("--repeat", type=click.IntRange(0, 100), default=None, metavar="K",
              help="Time each cell as K full frames (every pass run, as `iblbake render` runs them) after "
                   "a warm-up frame that pays its programs' first launch; the caption shows the median, "
                   "--json every repeat. Default: 3 with --caption time, else 0 (not timed).")
@click.option("--title", default=None, help="The sheet's title. Default: sweep.title, else the scene file's name.")
@click.option("--frames", "frames_dir", type=click.Path(file_okay=False), default=None,
              help="Also write each cell's own frame here (rRR_cCC.png; with --frames-exr the linear .exr too).")
@click.option("--frames-exr", is_flag=True, help="With --frames: each cell's linear EXR as well.")
@click.option("--layout", "layout_path", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Also write the --json summary here, with each cell's box in the sheet (what "
                   "`iblbake compare --layout` reads to compare sheets cell by cell).")
@click.option("--html", "html_dir", type=click.Path(file_okay=False), default=None, metavar="DIR",
              help="Also write DIR/index.html: every cell interactive, offline (A/B flip, split, error map, "
                   "exposure and the scene's tone mapping, pixel values, zoom), its images in DIR/report/.")
@click.option("--keep-going", is_flag=True,
              help="Render the other cells when one fails, and mark it in the sheet (exit status still 1).")
@click.option("--resume", is_flag=True,
              help="Read back the cells an earlier run (killed, failed or a shard) left in the cache; "
                   "render only the others. Every rendered cell is kept there, keyed by its content.")
@click.option("--shard", default=None, callback=_shard, metavar="I/N",
              help="Render only shard I of N (the cells sorted by content key and dealt round-robin: "
                   "the same on every machine, balanced) into the cache, for CI matrices; then --assemble.")
@click.option("--assemble", is_flag=True,
              help="Render nothing: build the sheet from the cells the shards left in the cache (a "
                   "one-line error names the missing ones).")
@click.option("--jobs", "-j", type=click.IntRange(min=1), default=1, show_default=True,
              help="Worker processes rendering cells, each with its own OpenCL runtime on --device (or "
                   "one of --devices); bakes are built once in the shared cache. The sheet is the serial "
                   "one, bit for bit. With --scheduler local: the LocalCluster's workers (default: the cores).")
@click.option("--devices", default=None, callback=_devices, metavar="SPEC,SPEC,...",
              help="One device per worker, in turn (--jobs, --scheduler local), e.g. gpu:0,gpu:1,cpu.")
@click.option("--scheduler", default=None, metavar="local|ADDRESS",
              help="Render the cells on a Dask cluster: 'local' starts a LocalCluster of --jobs worker "
                   "processes, else the address of a running scheduler (tcp://HOST:PORT). Needs "
                   "`pip install 'iblbake[distributed]'`. Workers read --cache (a shared folder builds each "
                   "bake once for all); the panorama and meshes are sent by content where a worker lacks them.")
@click.option("--resources", default=None, callback=_resources, metavar="NAME=N,...",
              help="With --scheduler: Dask resources each cell needs (GPU=1 sends cells only to workers "
                   "started with `dask worker --resources GPU=1`; with local, every worker has them).")
@cache_option("Bake cache folder")
@depfile_option
@scene_options
def sheet_command(scene_path, outputs, rows, columns, overrides, cell_size, label_format, caption, repeat, title,
                  frames_dir, frames_exr, layout_path, html_dir, keep_going, resume, shard, assemble, jobs, devices, scheduler,
                  resources, cache_dir, depfile, force, device, quiet, as_json):
    """Render every cell of the sweep of SCENE (its sweep: section, or --rows / --columns) in one
    process and assemble a contact sheet. Cells share the runtime, every bake, and the passes whose
    inputs they share (a material sweep traces primary rays once, a tone-mapping sweep lights once);
    each cell's pixels are what `iblbake render` writes for the same settings."""
    from iblbake.render import Bakes
    from iblbake.device.runtime import Runtime
    from iblbake.io import images
    from iblbake.io.atomic import check_writable
    from iblbake.scene import load as scene_load
    from iblbake.study import sheet, sweep

    con = Console(quiet, as_json)
    if repeat is None:
        repeat = 3 if caption == "time" else 0
    if shard and assemble:
        raise click.UsageError("--shard renders one shard's cells, --assemble none: give one of them")
    if not outputs and not shard:
        raise click.UsageError("Missing option '--output' / '-o' (only --shard renders without a sheet)")
    if (shard or assemble) and (scheduler or jobs > 1):
        raise click.UsageError("--shard and --assemble run in one process: leave out --jobs and --scheduler")
    if resources and not scheduler:
        raise click.UsageError("--resources tags Dask tasks: give --scheduler too")
    if devices and not (scheduler or jobs > 1):
        raise click.UsageError("--devices gives each worker its device: give --jobs N or --scheduler too")
    for o in outputs:
        if Path(o).suffix.lower() not in (".png", ".exr"):
            raise click.BadParameter(f"{o}: the sheet is written as .png or .exr", param_hint="-o")
        check_writable(o)
    t_start = time.perf_counter()
    base = scene_load.load(scene_path, overrides, ["cell.png"])
    rows_axis, cols_axis, cells = sweep.plan_sheet(
        base, sweep.parse_cli_axis(rows, "--rows") if rows else None,
        sweep.parse_cli_axis(columns, "--columns") if columns else None,
        label_format)
    scenes = sheet.cell_scenes(scene_path, overrides, cells, cell_size, keep_going)
    from iblbake.io.guard import refuse_overlaps
    writes = [("-o", o) for o in outputs] + [(flag, p) for flag, p in (("--layout", layout_path),
                                                                       ("--depfile", depfile)) if p]
    if frames_dir:
        writes += [("--frames", p) for c in cells for p in sheet.frame_paths(c, frames_dir, frames_exr)]
    if html_dir:
        from iblbake.study import html
        writes += [("--html", str(Path(html_dir) / n)) for n in ["index.html"] + html.data_names(len(cells), False)]
    refuse_overlaps(writes, [("the scene file", str(Path(scene_path).resolve()))] + [
        named for s in scenes if not isinstance(s, Exception) for named in scene_load.named_input_files(s)])
    for _, p in writes[len(outputs):]:
        check_writable(p)
    refuse_foreign(writes, force)
    rt = Runtime(device)
    bakes = Bakes(cache_dir)
    mine = sheet.shard_cells(scenes, bakes, shard) if shard and not assemble else range(len(cells))
    todo = [c for i, c in enumerate(cells) if i in mine]
    spread = None                    # what the workers did, with --jobs or --scheduler
    with con.stages([c.label or "cell" for c in todo], label="sheet") as step:
        if scheduler:
            from iblbake.study import workers
            n, capped = jobs if jobs > 1 else (os.cpu_count() or 1), None
            if scheduler == "local":         # its workers are processes here, as --jobs's are
                n, capped = workers.worker_count(n, len(todo), warn=con.warn if jobs > 1 else None)
            client, cluster = workers.connect(scheduler, n, resources)
            try:
                results, spread = workers.render_cells_dask(
                    scenes, cells, client, devices=devices or [device], bakes=bakes,
                    resources=resources, progress=step, keep_going=keep_going, resume=resume, repeat=repeat)
                if scheduler == "local":
                    spread.update(jobs=n, jobs_asked=jobs, jobs_capped_by=capped)
            finally:
                client.close()
                if cluster is not None:
                    cluster.close()
        elif jobs > 1:
            from iblbake.study import workers
            results, spread = workers.render_cells_parallel(
                scenes, cells, jobs, devices=devices or [device], bakes=bakes, progress=step,
                keep_going=keep_going, resume=resume, warn=con.warn, repeat=repeat)
        else:
            results = sheet.render_cells(scenes, cells, runtime=rt, bakes=bakes, warn=con.warn, progress=step,
                                         keep_going=keep_going, resume=resume, shard=shard, assemble=assemble,
                                         repeat=repeat)
    if shard:
        done = [r for r in results if r is not None]
        failed = [r for r in done if r.error]
        summary = {"scene": str(scene_path), "shard": list(shard), "device": rt.device_label,
                   "cells": [r.to_json() for r in done], "of": len(results), "failed": len(failed),
                   "elapsed_s": round(time.perf_counter() - t_start, 4)}
        con.result(summary, f"shard {shard[0]}/{shard[1]}: {len(done)} of {len(results)} cells in the cache "
                            f"{bakes.root} in {summary['elapsed_s']:.3f} s" + (f"; {len(failed)} failed" if failed else ""))
        if failed:
            raise IblbakeError(f"{len(failed)} cells of shard {shard[0]}/{shard[1]} failed; first: "
                               f"{sheet.cell_name(failed[0].cell)}: {failed[0].error}")
        return
    title = title or (base.data.get("sweep") or {}).get("title") or Path(scene_path).name
    lay = sheet.layout(results, rows_axis, cols_axis, title, caption)
    from iblbake.io import atomic
    from iblbake.io.guard import mark
    with atomic.Batch() as batch:    # the sheets, frames, layout and depfile: all replaced, or none
        for o in outputs:
            if o.lower().endswith(".png"):
                images.write_png(o, sheet.assemble(results, rows_axis, cols_axis, title, caption, lay), batch)
            else:
                images.write_exr(o, sheet.mosaic(results, rows_axis, cols_axis), channels=("R", "G", "B", "A"),
                                 batch=batch)
        if frames_dir:
            sheet.write_frames(results, Path(frames_dir), frames_exr, batch)
        if html_dir:
            page, left_out = html.sheet_page(results, scenes, rows_axis, cols_axis, title)
            if left_out:
                con.warn(f"--html {html_dir}: {left_out} cells differ in size from the first and are left out of the page")
            html.write(html_dir, page, batch)
        if depfile:                  # every file any cell read (a cell may sweep the panorama or a mesh)
            from iblbake.io import depfile as dep
            read = [f for s in scenes if not isinstance(s, Exception) for f in scene_load.input_files(s)]
            dep.write(depfile, [(list(outputs), read)], batch)
        failed = [r for r in results if r.error]
        cells_json = []
        for r in results:
            c = r.to_json()
            x, y = lay.origin(r.cell.row, r.cell.column)
            w, h = lay.cell
            c["png_box"] = [x, y, w, h]
            c["exr_box"] = [r.cell.column * (w + sheet.GAP), r.cell.row * (h + sheet.GAP), w, h]
            cells_json.append(c)
        summary = {"scene": str(scene_path), "outputs": list(outputs), "device": rt.device_label,
                   "rows": {"key": rows_axis.title, "labels": [s.label for s in rows_axis.steps]},
                   "columns": {"key": cols_axis.title, "labels": [s.label for s in cols_axis.steps]},
                   "cells": cells_json, "failed": len(failed), "elapsed_s": round(time.perf_counter() - t_start, 4)}
        if spread:
            summary["workers"] = spread
        if layout_path:
            atomic.write_json(layout_path, {"generator": mark(), **summary}, batch)
    con.result(summary, f"wrote {', '.join(outputs)}: {len(rows_axis.steps)} x {len(cols_axis.steps)} cells "
                        f"in {summary['elapsed_s']:.3f} s on {rt.device_label}"
                        + (f"; {len(failed)} failed" if failed else ""))
    if failed:
        raise IblbakeError(f"{len(failed)} of {len(results)} cells failed; first: row {failed[0].cell.row}, "
                           f"column {failed[0].cell.column}: {failed[0].error}")
