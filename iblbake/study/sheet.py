"""Contact sheets: every cell of a sweep rendered in one process (one runtime, one bake store, and
passes reused from cell to cell where their inputs did not change), assembled into one image
with a title, axis labels and a caption under each cell (text drawn by OpenImageIO's
render_text), or into a linear EXR mosaic."""

from __future__ import annotations

import functools
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iblbake.errors import IblbakeError
from iblbake.scene import load as scene_load
from iblbake.study import sweep

BACKGROUND = (0.13, 0.13, 0.14)
TEXT = (0.92, 0.92, 0.92)
FAILED = (0.55, 0.12, 0.12)
MARGIN, GAP = 14, 8
TITLE_PT, AXIS_PT, CAPTION_PT = 22, 16, 13


@dataclass
class CellResult:
    cell: sweep.Cell
    frame: object = None              # Frame, None where the cell failed
    seconds: float = 0.0
    error: str | None = None
    outputs: list = field(default_factory=list)
    key: str | None = None            # its cache entry, once known

    @property
    def repeats(self) -> list:
        """The passes' seconds of each timed full frame (time_frames), where the cell was timed."""
        timing = self.frame.report.get("timing") if self.frame is not None else None
        reps = timing.get("repeats") if isinstance(timing, dict) else None
        # read back from a cached cell's manifest: a damaged one counts as not timed
        if not isinstance(reps, list) or not all(isinstance(x, (int, float)) and x >= 0 for x in reps):
            return []
        return reps

    @property
    def pass_seconds(self) -> float:
        """What the frame's passes take: the median of its timed repeats where it was timed, else
        what its passes took in the sheet (reused passes cost nothing there). Kernel builds and
        bakes are one-off costs, not in it."""
        if self.frame is None:
            return 0.0
        if self.repeats:
            return statistics.median(self.repeats)
        return sum(p["seconds"] for p in self.frame.report["passes"])

    def to_json(self) -> dict:
        rep = self.frame.report if self.frame is not None else {}
        return {"row": self.cell.row, "column": self.cell.column, "label": self.cell.label,
                "values": {k: v for k, v in self.cell.values}, "seconds": round(self.seconds, 4),
                "pass_seconds": round(self.pass_seconds, 4),
                "reused": rep.get("reused", []), "cached": bool(rep.get("cell_cached")),
                "bakes_cached": [b["name"] for b in rep.get("bakes", []) if b.get("cached")],
                "passes": {p["name"]: p["seconds"] for p in rep.get("passes", [])},
                "timing": rep.get("timing"),
                "outputs": self.outputs, "error": self.error}


def cell_scenes(scene_path, overrides, cells, cell_size=None, keep_going=False):
    """Every cell's validated scene (a frame output so the tone-mapping pass runs, no AOVs), or
    its error; without keep_going the first error stops everything before any rendering."""
    size = [("camera.resolution", list(cell_size))] if cell_size else []
    out = []
    for c in cells:
        values = c.values + size + [(f"output.{a}", None) for a in scene_load.AOVS]
        try:
            out.append(scene_load.load(scene_path, overrides, ["cell.png"], values=values, origin="sweep"))
        except IblbakeError as e:
            if not keep_going:
                raise type(e)(f"cell ({cell_name(c)}): {e}") from None
            out.append(e)
    return out


@functools.lru_cache(maxsize=1)
def _kernels_hash() -> str:
    """Every pass's kernel source, headers inlined (read once per process)."""
    from iblbake.device.programs import source_hash
    from iblbake.render.passes import PASSES
    return source_hash(tuple(dict.fromkeys(p.kernel for p in PASSES if p.kernel)))


def cell_identity(sc, bakes) -> str:
    """What a cell is, whatever renders it and wherever its files lie: its scene (every value,
    display settings too, not its outputs) with each file it names replaced by that file's content
    hash (hashed once per store), and the renderer's kernel sources. So CI jobs whose checkouts
    lie in different folders share one cache of cells."""
    from iblbake.bake.cache import content_key

    hashes = {f: "sha256:" + h for f, h in bakes.input_hashes(sc).items()}
    data = scene_load.replace_strings({k: v for k, v in sc.data.items() if k not in ("output", "sweep")}, hashes)
    return content_key({"kind": "cell", "v": 2, "scene": data, "kernels": _kernels_hash()})


def cell_key(identity: str, device_kind: str) -> str:
    """The cache entry of a rendered cell: its identity on one kind of device (CPU and GPU round
    differently, so each keeps its own frames)."""
    from iblbake.bake.cache import content_key
    return "cell-" + content_key({"cell": identity, "device": device_kind})


def shard_cells(scenes, bakes, shard: tuple) -> set:
    """The indices of shard (i, n)'s cells, i from 1: the cells sorted by identity and dealt
    round-robin. A partition by key, so every machine of a CI matrix agrees on who renders what
    (an identity holds no path), and balanced: no shard holds more than one cell more than
    another (a key modulo n can leave a small sweep's shard empty). A cell whose scene failed to
    load sorts last, by position."""
    i, n = shard
    ids = [f"~{k:09d}" if isinstance(sc, Exception) else cell_identity(sc, bakes) for k, sc in enumerate(scenes)]
    order = sorted(range(len(scenes)), key=ids.__getitem__)
    return set(order[i - 1::n])


def cached_cell(bakes, key: str):
    """The Frame a cell's entry holds, or None (not rendered yet, or damaged)."""
    from iblbake.render import Frame
    from iblbake.bake import cache

    entry = bakes.root / key
    manifest = cache.verify(entry)
    if manifest is None:
        return None
    return Frame(np.load(entry / "hdr.npy"), np.load(entry / "png.npy") if manifest["png"] else None,
                        {}, {**manifest["report"], "cell_cached": True})


def store_cell(bakes, key: str, frame, warn=None) -> None:
    from iblbake.bake import cache

    def build(tmp: Path):
        np.save(tmp / "hdr.npy", frame.hdr)
        files = [{"name": "hdr.npy"}]
        if frame.png is not None:
            np.save(tmp / "png.npy", np.ascontiguousarray(frame.png))
            files.append({"name": "png.npy"})
        return {"kind": "cell", "files": files, "png": frame.png is not None, "report": frame.report}

    cache.get_or_build(bakes.root, key, build, warn=warn)


def cell_name(c: sweep.Cell) -> str:
    return f"row {c.row}, column {c.column}: {c.label or 'base'}"


def render_cells(scenes, cells, *, runtime, bakes, warn=None, progress=None, keep_going=False, resume=False,
                 shard=None, assemble=False, repeat: int = 0):
    """Every cell's CellResult. Each rendered cell is kept in the bake cache under its key; with
    `resume` (or `assemble`) a cell found there is read back instead of rendered. `shard` (i, n)
    renders only that shard's cells (the others' results are None); `assemble` renders nothing
    and fails in one line naming the cells no shard has rendered. `repeat` > 0 times each cell
    (time_frames) and keeps the repeats in its frame's report."""
    from iblbake.render import Reuse

    reuse = Reuse()
    kind = runtime.info.kind if runtime is not None else None
    if assemble:
        results, missing = [], []
        for sc, c in zip(scenes, cells):
            r = CellResult(c)
            if isinstance(sc, Exception):
                r.error = str(sc)
            else:
                r.frame = cached_cell(bakes, cell_key(cell_identity(sc, bakes), kind))
                if r.frame is None:
                    missing.append(cell_name(c))
            results.append(r)
        if missing:
            raise IblbakeError(f"--assemble: {len(missing)} of {len(cells)} cells are not in the cache "
                               f"{bakes.root} (for a {kind} device): {'; '.join(missing[:6])}"
                               f"{' ...' if len(missing) > 6 else ''}; run their shards first")
        return results
    mine = shard_cells(scenes, bakes, shard) if shard else range(len(cells))
    results = [None] * len(cells)
    for index in reuse_order(scenes, cells, mine):
        results[index] = render_cell(scenes[index], cells[index], runtime, bakes, reuse, warn, keep_going, resume,
                                     kind, repeat)
        if progress:
            progress()
    return results


def reuse_order(scenes, cells, indices) -> list:
    """The order to render the cells in: row by row or column by column, whichever runs fewer
    passes (a cell reuses each pass whose inputs did not change since the cell before: in a
    metallic x roughness sheet, going down a metallic column samples the panorama once per
    roughness instead of once per cell); row by row on a tie. Judged on the first cell and its
    neighbours along a row and down a column (three plans, not one per cell). Where the cells go
    does not change."""
    from iblbake.render.frame import pass_keys
    from iblbake.render.plan import plan

    by_rows = sorted(indices, key=lambda i: (cells[i].row, cells[i].column))
    by_columns = sorted(indices, key=lambda i: (cells[i].column, cells[i].row))
    at = {(cells[i].row, cells[i].column): i for i in indices}
    first = cells[by_rows[0]] if by_rows else None
    probe = [at.get((first.row, first.column)), at.get((first.row, first.column + 1)),
             at.get((first.row + 1, first.column))] if first else []
    if len(probe) < 3 or any(i is None or isinstance(scenes[i], Exception) for i in probe):
        return by_rows
    try:
        keys = [pass_keys(plan(scenes[i]), scenes[i]) for i in probe]
    except (IblbakeError, ValueError):            # the cell fails when rendered, with its name
        return by_rows

    def changed(a, b):
        return sum(1 for name in set(a) | set(b) if a.get(name) != b.get(name))

    return by_columns if changed(keys[0], keys[2]) < changed(keys[0], keys[1]) else by_rows


def time_frames(sc, runtime, bakes, repeat: int) -> list:
    """The passes' seconds of `repeat` full frames of `sc` (every pass run, no reuse: what
    `iblbake render` runs), after one warm-up frame that pays the programs' builds and the
    device's first-launch specialisation (PoCL specialises a program at its first launch: one
    sample per cell gave the first cell of a sheet that cost, and the ao sheet's captions read
    off 594 ms against 64 rays 510 ms)."""
    from iblbake.render import render
    render(sc, runtime=runtime, cache=bakes)
    return [round(sum(p["seconds"] for p in render(sc, runtime=runtime, cache=bakes).report["passes"]), 6)
            for _ in range(repeat)]


def render_cell(sc, c, runtime, bakes, reuse, warn, keep_going, resume, kind, repeat: int = 0):
    """One cell rendered (or, with `resume`, read back from the cache) and kept in the cache;
    with `repeat`, timed by time_frames (a cached cell timed with as many repeats keeps them)."""
    from iblbake.render import render
    from iblbake.errors import DeviceError

    r = CellResult(c)
    if isinstance(sc, Exception):
        r.error = str(sc)
        return r
    key = r.key = cell_key(cell_identity(sc, bakes), kind)
    t0 = time.perf_counter()
    r.frame = cached_cell(bakes, key) if resume else None
    timed = r.frame is not None and (not repeat or len(r.repeats) == repeat)
    if r.frame is None or not timed:
        try:
            r.frame = r.frame or render(sc, runtime=runtime, cache=bakes, reuse=reuse, warn=warn)
            if repeat:
                r.frame.report["timing"] = {"repeats": time_frames(sc, runtime, bakes, repeat),
                                            "what": f"passes of {repeat} full frames after a warm-up frame"}
            store_cell(bakes, key, r.frame, warn)
        except (IblbakeError, DeviceError) as e:
            if not keep_going:
                raise type(e)(f"cell ({cell_name(c)}): {e}") from None
            r.error = str(e)
            reuse.state = None
    r.seconds = time.perf_counter() - t0
    return r


def text_width(text: str, pt: int) -> int:
    import OpenImageIO as oiio
    return oiio.ImageBufAlgo.text_size(text, pt, "").width if text else 0


def _fit(text: str, pt: int, width: int) -> str:
    """The text, cut with an ellipsis to fit `width` pixels."""
    if text_width(text, pt) <= width:
        return text
    while text and text_width(text + "...", pt) > width:
        text = text[:-1]
    return text + "..."


def caption_lines(r: CellResult, caption: str) -> list:
    if r.error:
        return ["failed", r.error]
    lines = [r.cell.label] if caption in ("values", "time") and r.cell.label else []
    if caption == "time":            # its passes: builds and bakes are one-off costs (in --json)
        lines.append(f"{r.pass_seconds * 1000:.1f} ms")
    return lines


@dataclass
class Layout:
    width: int
    height: int
    left: int                         # x of the first column of cells
    top: int                          # y of the first row of cells
    cell: tuple                       # (w, h) of a cell's frame
    caption_h: int

    def origin(self, row: int, column: int) -> tuple:
        """(x, y) of the top-left pixel of a cell's frame in the sheet."""
        w, h = self.cell
        return self.left + column * (w + GAP), self.top + row * (h + self.caption_h + GAP)


def layout(results, rows: sweep.Axis, columns: sweep.Axis, title: str, caption: str) -> Layout:
    ok = [r for r in results if r.frame is not None]
    if not ok:
        raise IblbakeError("sheet: every cell failed; nothing to assemble")
    h, w = ok[0].frame.png.shape[:2]
    nr, nc = len(rows.steps), len(columns.steps)
    has_rows, has_cols = bool(rows.title), bool(columns.title)
    n_lines = max(len(caption_lines(r, caption)) for r in results)
    cap_h = n_lines * (CAPTION_PT + 5) + (4 if n_lines else 0)
    left = MARGIN + (max(text_width(x, AXIS_PT) for x in [s.label for s in rows.steps] + [rows.title]) + MARGIN
                     if has_rows else 0)
    top = MARGIN + TITLE_PT + 8 + (AXIS_PT + 6) * (2 if has_cols else 1 if has_rows else 0)
    width = max(left + nc * w + (nc - 1) * GAP + MARGIN, text_width(title, TITLE_PT) + 2 * MARGIN)
    height = top + nr * (h + cap_h) + (nr - 1) * GAP + MARGIN
    return Layout(width, height, left, top, (w, h), cap_h)


def assemble(results, rows: sweep.Axis, columns: sweep.Axis, title: str, caption: str, lay: Layout):
    """The contact sheet as an 8-bit RGB image in the layout `lay` (layout(): the same one the
    sheet's JSON gives the cells' boxes from): title, column and row labels, cells, captions."""
    import OpenImageIO as oiio
    w, h = lay.cell
    buf = oiio.ImageBuf(oiio.ImageSpec(lay.width, lay.height, 3, oiio.FLOAT))
    oiio.ImageBufAlgo.fill(buf, BACKGROUND)

    def draw(x, y, text, pt):
        oiio.ImageBufAlgo.render_text(buf, int(x), int(y), text, pt, "", TEXT)

    draw(MARGIN, MARGIN + TITLE_PT, title, TITLE_PT)
    header = MARGIN + TITLE_PT + 8
    if columns.title:
        draw(lay.left, header + AXIS_PT, columns.title, AXIS_PT)
        for j, s in enumerate(columns.steps):
            draw(lay.origin(0, j)[0], header + 2 * AXIS_PT + 6, _fit(s.label, AXIS_PT, w), AXIS_PT)
    if rows.title:                   # above the row labels, in the header's last line
        draw(MARGIN, lay.top - 6, _fit(rows.title, AXIS_PT, lay.left - MARGIN), AXIS_PT)
        for i, s in enumerate(rows.steps):
            draw(MARGIN, lay.origin(i, 0)[1] + h // 2 + AXIS_PT // 2, s.label, AXIS_PT)
    for r in results:
        x, y = lay.origin(r.cell.row, r.cell.column)
        for k, text in enumerate(caption_lines(r, caption)):
            draw(x, y + h + (k + 1) * (CAPTION_PT + 5), _fit(text, CAPTION_PT, w), CAPTION_PT)
    # the cells last, as 8-bit values: exactly the frames `iblbake render` writes
    out = np.ascontiguousarray(buf.get_pixels(oiio.UINT8).reshape(lay.height, lay.width, 3))
    for r in results:
        x, y = lay.origin(r.cell.row, r.cell.column)
        out[y:y + h, x:x + w] = r.frame.png if r.frame is not None else np.uint8(np.array(FAILED) * 255)
    return out


def mosaic(results, rows: sweep.Axis, columns: sweep.Axis):
    """The linear HDR cells side by side (RGBA, alpha = coverage), GAP pixels apart, no text."""
    ok = [r for r in results if r.frame is not None]
    if not ok:
        raise IblbakeError("sheet: every cell failed; nothing to assemble")
    h, w = ok[0].frame.hdr.shape[:2]
    nr, nc = len(rows.steps), len(columns.steps)
    out = np.zeros((nr * h + (nr - 1) * GAP, nc * w + (nc - 1) * GAP, 4), np.float32)
    for r in ok:
        x, y = r.cell.column * (w + GAP), r.cell.row * (h + GAP)
        out[y:y + h, x:x + w] = r.frame.hdr
    return out


def frame_paths(cell: sweep.Cell, folder: Path, exr: bool = False) -> list:
    """Where --frames writes a cell's own frame: rRR_cCC.png (and .exr)."""
    stem = Path(folder) / f"r{cell.row:02d}_c{cell.column:02d}"
    return [f"{stem}.png"] + ([f"{stem}.exr"] if exr else [])


def write_frames(results, folder: Path, exr: bool = False, batch=None) -> None:
    """Each cell's frame into `folder` (with `batch`'s other outputs, atomic.Batch, where given)."""
    from iblbake.io import images
    for r in results:
        if r.frame is None:
            continue
        png, *rest = frame_paths(r.cell, folder, exr)
        images.write_png(png, r.frame.png, batch)
        r.outputs.append(png)
        for p in rest:
            images.write_exr(p, r.frame.hdr, channels=("R", "G", "B", "A"), batch=batch)
            r.outputs.append(p)
