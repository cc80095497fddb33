"""The interactive report of a study or a sheet: DIR/index.html (the page, its script and style
inline: iblbake/study/page/) and DIR/report/*.js, one per image, loaded by the page only when shown.

Each image is its linear HDR RGB as float16 (rows top to bottom; the low bytes of all values,
then the high bytes; clamped to float16's largest, 65504) followed by its metric mask
(np.packbits, one bit a pixel), deflated (zlib) and base64-encoded inside a script that hands it
to the page: a script, not a fetch(), because browsers refuse fetch() on file:// URLs and the
folder has to open offline from the file system. The page decodes the float16
itself and applies the exposure and tone mapping of iblbake/core/tonemap.py (the same operator
and numbers), so what it shows is what `render` writes for the same HDR value.
"""

from __future__ import annotations

import base64
import json
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iblbake.scene.load import object_label
from iblbake.study import report

PAGE = Path(__file__).with_name("page")
DATA_DIR = "report"


@dataclass
class Entry:
    """One image of the page: a rung's frame, a reference or a sheet's cell."""
    label: str
    hdr: np.ndarray                        # (H, W, >= 3) linear RGB
    mask: np.ndarray | None = None         # (H, W) bool: the pixels its metrics read (None: all)
    term: str = ""
    reference: int | None = None           # the index of the entry it is measured against
    is_reference: bool = False
    row: dict = field(default_factory=dict)   # what the table shows (report.COLUMNS' keys)
    regions: dict = field(default_factory=dict)   # object label -> the region's relative error
    effects: dict | None = None            # its own tone mapping, where it differs from the page's


@dataclass
class Page:
    title: str
    entries: list
    effects: dict                          # the scene's tonemap, exposure, output_transfer, gamma
    kind: str = "accuracy"                 # accuracy (a table, a plot) or sheet
    columns: tuple = report.COLUMNS
    objects: np.ndarray | None = None      # (H, W) object index, -1: none
    object_names: list = field(default_factory=list)


def data_names(n_entries: int, objects: bool) -> list:
    """The data files a page of n entries writes, relative to its folder."""
    return [f"{DATA_DIR}/{i:04d}.js" for i in range(n_entries)] + ([f"{DATA_DIR}/objects.js"] if objects else [])


def pack(hdr, mask) -> bytes:
    """float16 RGB, its low bytes then its high bytes (deflate finds the repeats of the high
    bytes, sign and exponent, once they sit together: a fifth smaller), then the packed mask,
    deflated."""
    f16 = float(np.finfo(np.float16).max)
    rgb = np.ascontiguousarray(np.clip(np.nan_to_num(np.asarray(hdr, np.float32)[..., :3], nan=0.0), -f16, f16),
                               dtype="<f2")
    split = rgb.view(np.uint8).reshape(-1, 2).T
    bits = np.packbits(np.ones(hdr.shape[:2], bool) if mask is None else np.asarray(mask, bool), axis=None)
    return zlib.compress(split.tobytes() + bits.tobytes(), 6)


def data_script(key: str, payload: bytes) -> str:
    from iblbake.io.guard import mark
    return (f"// {mark()}: the report's data (iblbake/study/html.py)\n"
            f"IBL.arrive({json.dumps(key)}, \"{base64.b64encode(payload).decode('ascii')}\");\n")


def magma_lut() -> str:
    """matplotlib's magma, 256 RGB bytes as hex: the colour scale of errors.png (metrics.error_image)."""
    from matplotlib import colormaps
    lut = (colormaps["magma"](np.linspace(0, 1, 256))[:, :3] * 255 + 0.5).astype(np.uint8)
    return lut.tobytes().hex()


def _number(v):
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, float, np.integer, np.floating)):
        v = float(v)
        return v if np.isfinite(v) else None
    return v


def _tonemap(fx: dict) -> dict:
    return {"operator": fx["tonemap"], "exposure": float(fx["exposure"]), "transfer": fx["output_transfer"],
            "gamma": float(fx["gamma"])}


def manifest(page: Page) -> dict:
    """What index.html holds inline: every entry's label, row and file, no pixels."""
    h, w = page.entries[0].hdr.shape[:2]
    return {
        "kind": page.kind, "title": page.title, "width": w, "height": h, "tonemap": _tonemap(page.effects),
        "columns": [list(c) for c in page.columns], "magma": magma_lut(),
        "objects": f"{DATA_DIR}/objects.js" if page.objects is not None else None,
        "object_names": list(page.object_names),
        "entries": [{"label": e.label, "term": e.term, "reference": e.reference, "is_reference": e.is_reference,
                     "file": f"{DATA_DIR}/{i:04d}.js", "row": {k: _number(v) for k, v in e.row.items()},
                     "regions": {k: _number(v) for k, v in e.regions.items()},
                     "tonemap": _tonemap(e.effects) if e.effects else None}
                    for i, e in enumerate(page.entries)]}


def index_html(page: Page) -> str:
    from iblbake.io.guard import mark
    data = json.dumps(manifest(page), allow_nan=False).replace("</", "<\\/")
    return (f"<!DOCTYPE html><!-- {mark()}: a study's interactive report (iblbake/study/html.py) -->\n"
            f"<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{_escape(page.title)}</title>\n"
            f"<style>\n{(PAGE / 'report.css').read_text()}</style></head>\n"
            f"<body>\n{(PAGE / 'report.html').read_text()}"
            f"<script>window.IBL_DATA = {data};</script>\n"
            f"<script>\n{(PAGE / 'report.js').read_text()}</script>\n</body></html>\n")


def _escape(s: str) -> str:
    return s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def write(out_dir, page: Page, batch) -> list:
    """index.html and its data files into out_dir (with `batch`'s other outputs); their paths."""
    out = Path(out_dir)
    if not page.entries:
        return []
    files = []
    for i, e in enumerate(page.entries):
        files.append(out / f"{DATA_DIR}/{i:04d}.js")
        batch.write_text(files[-1], data_script(str(i), pack(e.hdr, e.mask)))
    if page.objects is not None:
        ids = np.asarray(page.objects, "<i2")
        files.append(out / f"{DATA_DIR}/objects.js")
        batch.write_text(files[-1], data_script("objects", zlib.compress(ids.tobytes(), 6)))
    batch.write_text(out / "index.html", index_html(page))
    return [out / "index.html"] + files


def study_page(study, rungs, rows, front, title: str) -> Page:
    """The page of an accuracy study: each term's reference, then every rung that ran (its frame,
    metric mask, table row and per-object errors), from what the study already holds."""
    entries, ref_of = [], {}
    for t in study.terms:
        ref = study.reference[t]
        ref_of[t] = len(entries)
        entries.append(Entry(f"reference {t}", ref["hdr"], ref["mask"], t, None, True,
                             {"term": t, "label": "reference",
                              "samples": ref["samples_per_pixel"], "noise": ref["noise"]}))
    table = {(r["term"], r["label"]): r for r in report.table_rows(rows, front)}
    for r in rungs:
        if not r.result or r.frame is None:
            continue
        row = table.get((r.term, r.label), {})
        entries.append(Entry(r.label, r.frame.hdr, study.metric_mask(r.term, r.frame.hdr), r.term, ref_of[r.term],
                             False, row, r.result.get("region_errors", {})))
    # the object AOV every rung's region errors read (rendered once with the first rung: no cost here)
    objects = study.object_regions() if len(entries) > len(ref_of) else None
    names = [object_label(study.scene.data, i) for i in range(len(study.scene.data["objects"]))]
    return Page(title, entries, study.scene.data["effects"], "accuracy", report.COLUMNS, objects, names)


SHEET_COLUMNS = (("label", "cell"), ("row", "row"), ("column", "column"), ("time_ms", "time ms"))


def sheet_page(results, scenes, rows_axis, cols_axis, title: str) -> tuple:
    """(the page of a sheet, how many cells it leaves out): every cell that rendered at the first
    one's size (one view zooms them all), each with its own tone mapping; A the first cell, B
    the second until others are picked."""
    entries, left_out, size = [], 0, None
    for r, sc in zip(results, scenes):
        if r.frame is None or r.error:
            continue
        size = size or r.frame.hdr.shape[:2]
        if r.frame.hdr.shape[:2] != size:
            left_out += 1
            continue
        c = r.cell
        row = {"label": c.label or f"{c.row},{c.column}", "row": rows_axis.steps[c.row].label if rows_axis.steps else "",
               "column": cols_axis.steps[c.column].label if cols_axis.steps else "", "time_ms": 1000 * r.pass_seconds}
        entries.append(Entry(row["label"], r.frame.hdr, None, "", None, False, row, effects=sc.data["effects"]))
    effects = entries[0].effects if entries else {}
    columns = (SHEET_COLUMNS[0], ("row", f"row: {rows_axis.title}" if rows_axis.steps else "row"),
               ("column", f"column: {cols_axis.title}" if cols_axis.steps else "column"), SHEET_COLUMNS[3])
    return Page(title, entries, effects, "sheet", columns), left_out
