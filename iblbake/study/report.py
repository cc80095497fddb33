"""The study's reports: the table (markdown, text, CSV), the error-time plot with the Pareto
frontier, and the sheet of every rung's frame beside its error image."""

from __future__ import annotations

import csv
import io
import math

import numpy as np

from iblbake.core.metrics import error_image
from iblbake.study import sweep
from iblbake.study.ladder import TERMS

COLUMNS = (("term", "term"), ("label", "setting"), ("time_ms", "time ms"), ("bake_s", "bake s"),
           ("bytes", "bytes fp16"),
           ("relative_rmse", "rel. RMSE"), ("mean_relative_error", "mean rel."), ("max_relative_error", "max rel."),
           ("worst_region_error", "worst object mean"), ("flip", "HDR-FLIP"), ("pareto", "frontier"))


def table_rows(rows, front) -> list:
    out = []
    for r in rows:
        out.append({"term": r["term"], "label": r["label"], "time_ms": r["time_s"] * 1000, "bake_s": r["bake_s"],
                    "bytes": r.get("bytes"),
                    "relative_rmse": r["relative_rmse"], "mean_relative_error": r["mean_relative_error"],
                    "max_relative_error": r["max_relative_error"], "flip": r["flip"],
                    "worst_region_error": r.get("worst_region_error"),
                    "pareto": r["label"] in front.get(r["term"], [])})
    return out


def _fmt(key, v) -> str:
    if v is None:
        return "-"
    if key == "pareto":
        return "*" if v else ""
    if key in ("relative_rmse", "mean_relative_error", "max_relative_error", "worst_region_error"):
        return f"{100 * v:.2f}%"
    if key == "flip":
        return f"{v:.4f}"
    if key == "time_ms":
        return f"{v:.3g}"
    if key == "bake_s":
        return f"{v:.3f}"
    return str(v)


def markdown(rows, front) -> str:
    lines = ["| " + " | ".join(h for _, h in COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in table_rows(rows, front):
        lines.append("| " + " | ".join(_fmt(k, r[k]) for k, _ in COLUMNS) + " |")
    return "\n".join(lines) + "\n"


def text_table(rows, front) -> str:
    cells = [[h for _, h in COLUMNS]] + [[_fmt(k, r[k]) for k, _ in COLUMNS] for r in table_rows(rows, front)]
    widths = [max(len(c[i]) for c in cells) for i in range(len(COLUMNS))]
    return "\n".join("  ".join(c[i].ljust(widths[i]) if i < 2 else c[i].rjust(widths[i]) for i in range(len(c)))
                     for c in cells) + "\n"


def csv_text(rows, front) -> str:
    buf = io.StringIO()
    keys = [k for k, _ in COLUMNS]
    wr = csv.DictWriter(buf, fieldnames=keys + ["frame_s", "kernel_build_s"], lineterminator="\n")
    wr.writeheader()
    for r, t in zip(rows, table_rows(rows, front)):
        wr.writerow({**t, "frame_s": r["frame_s"], "kernel_build_s": r["kernel_build_s"]})
    return buf.getvalue()


PLOT_SIZE = (1400, 640)          # pixels


def plot(rows, front, path, title: str, batch=None) -> None:
    """plot_figure written to `path` (PNG, atomic: with `batch`'s other outputs where given),
    named iblbake's in its Software chunk (the overwrite rule's mark)."""
    import io

    import matplotlib.pyplot as plt

    from iblbake.io.atomic import write_bytes
    from iblbake.io.guard import mark

    fig = plot_figure(rows, front, title)
    buf = io.BytesIO()
    fig.savefig(buf, dpi=fig.dpi, format="png", metadata={"Software": mark()})
    plt.close(fig)
    write_bytes(path, buf.getvalue(), batch)


def header_lines() -> tuple:
    """The first lines of table.md and table.csv: what marks them as iblbake's (the overwrite rule)."""
    return markdown([], {}).split("\n", 1)[0], csv_text([], {}).split("\n", 1)[0]


def plot_figure(rows, front, title: str):
    """Log-log error (relative RMSE) against time per frame of the lighting pass, a panel per
    term, each point labelled; the Pareto frontier drawn as a line through its points."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import ticker

    terms = [t for t in TERMS if any(r["term"] == t for r in rows)]
    dpi = 100
    fig, axes = plt.subplots(1, len(terms), figsize=(PLOT_SIZE[0] / dpi, PLOT_SIZE[1] / dpi), dpi=dpi, squeeze=False)
    for ax, t in zip(axes[0], terms):
        sel = [r for r in rows if r["term"] == t]
        on = set(front.get(t, []))
        for r in sel:
            x, y = max(r["time_s"] * 1000, 1e-3), max(r["relative_rmse"], 1e-5)
            ax.scatter([x], [y], s=36 if r["label"] in on else 14,
                       color="tab:red" if r["label"] in on else ("tab:green" if r["configured"] else "tab:gray"),
                       zorder=3)
        fr = [r for r in sel if r["label"] in on]
        fr.sort(key=lambda r: r["time_s"])
        ax.plot([max(r["time_s"] * 1000, 1e-3) for r in fr], [max(r["relative_rmse"], 1e-5) for r in fr],
                color="tab:red", lw=1.2, zorder=2, label="Pareto frontier")
        ax.set_xscale("log")
        ax.set_yscale("log")
        for axis in (ax.xaxis, ax.yaxis):  # labels at 1, 2, 5 per decade only: a narrow range
            axis.set_major_locator(ticker.LogLocator(base=10, subs=(1.0, 2.0, 5.0)))  # gets a few,
            axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))     # never a pile
            axis.set_minor_formatter(ticker.NullFormatter())
        ax.set_xlabel("time of the lighting pass per frame (ms, median)")
        ax.set_ylabel("relative RMSE against the reference")
        ax.set_title(f"{t}", fontsize=11)
        ax.grid(True, which="both", alpha=0.3)
    # one legend under the panels, where it hides no point
    fig.legend(handles=[plt.Line2D([], [], color="tab:red", lw=1.2, marker="o", label="Pareto frontier"),
                        plt.Line2D([], [], color="tab:green", lw=0, marker="o", label="configured"),
                        plt.Line2D([], [], color="tab:gray", lw=0, marker="o", label="other rungs")],
               loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=12)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    fig.canvas.draw()                    # the final limits and layout (autoscaling waits for a draw)
    for ax, t in zip(axes[0], terms):    # labels last: their places depend on the final layout
        on = set(front.get(t, []))
        sel = [r for r in rows if r["term"] == t]
        place_labels(ax, [(max(r["time_s"] * 1000, 1e-3), max(r["relative_rmse"], 1e-5), r["label"],
                           "black" if r["label"] in on else "dimgray", r["label"] in on) for r in sel])
    return fig


LABEL_PT = 6
_RINGS_PX = (3, 8, 14, 22, 32, 44, 58, 76, 98, 124, 156)
_ANGLES = [k * math.pi / 8 for k in range(16)]


def place_labels(ax, points) -> None:
    """Label each point (x, y, text, colour, first) without one label over another or over a
    point: a simple repel. The frontier's labels are placed first, each label at the nearest free
    spot on rings around its point (inside the panel), with a leader line once it is moved off;
    where no spot is free, the least covered one."""
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    panel = ax.get_window_extent(renderer)
    xy = ax.transData.transform([(x, y) for x, y, *_ in points]) if points else np.zeros((0, 2))
    marks = [(px - 4, py - 4, px + 4, py + 4) for px, py in xy]
    placed = []

    def covered(box) -> float:
        area = 0.0
        for o in placed + marks:
            w = min(box[2], o[2]) - max(box[0], o[0])
            h = min(box[3], o[3]) - max(box[1], o[1])
            if w > 0 and h > 0:
                area += w * h
        outside = (max(panel.x0 - box[0], 0) + max(box[2] - panel.x1, 0)) * (box[3] - box[1]) + \
                  (max(panel.y0 - box[1], 0) + max(box[3] - panel.y1, 0)) * (box[2] - box[0])
        return area + 4 * outside

    order = sorted(range(len(points)), key=lambda i: (not points[i][4], -xy[i][1]))
    for i in order:
        x, y, text, colour, _ = points[i]
        probe = ax.text(0, 0, text, fontsize=LABEL_PT)
        ext = probe.get_window_extent(renderer)
        probe.remove()
        w, h = ext.width + 2, ext.height + 2
        px, py = xy[i]
        best = None
        for r in _RINGS_PX:
            for a in _ANGLES:
                dx, dy = r * math.cos(a), r * math.sin(a)
                left, bottom = dx >= -1e-9, dy >= -1e-9       # the label grows away from its point
                x0 = px + dx if left else px + dx - w
                y0 = py + dy if bottom else py + dy - h
                box = (x0, y0, x0 + w, y0 + h)
                cost = covered(box)
                if best is None or cost < best[0]:
                    best = (cost, r, dx, dy, left, bottom, box)
                if cost == 0:
                    break
            if best[0] == 0:
                break
        _, r, dx, dy, left, bottom, box = best
        placed.append(box)
        far = r > _RINGS_PX[1]
        ax.annotate(text, (x, y), xytext=(dx + (1 if left else -1), dy + (1 if bottom else -1)),
                    textcoords="offset pixels", fontsize=LABEL_PT, color=colour,
                    ha="left" if left else "right", va="bottom" if bottom else "top", zorder=4,
                    arrowprops={"arrowstyle": "-", "color": "0.6", "lw": 0.5, "shrinkA": 0, "shrinkB": 2}
                    if far else None)


def error_sheet(study, rungs, title: str) -> np.ndarray:
    """A contact sheet (the sheet code's layout): per term, the reference, then the best
    approximation and the worst rung (lowest and highest relative RMSE; fewer reference samples
    count as an approximation only where nothing else ran), each beside its error map."""
    from iblbake.core import tonemap
    from iblbake.render.frame import Frame
    from iblbake.study import sheet

    fx = study.scene.data["effects"]
    columns = sweep.Axis("columns", "rung", [sweep.Step([], s) for s in
                                             ("reference", "best", "best: error", "worst", "worst: error")])
    rows = sweep.Axis("rows", "term", [])
    results = []
    for i, t in enumerate(study.terms):
        sel = [r for r in rungs if r.term == t and r.result]
        if not sel:
            continue
        rows.steps.append(sweep.Step([], t))
        ref = study.reference[t]
        ref_png = tonemap.to_u8(tonemap.tonemap(ref["hdr"][..., :3], fx["tonemap"], fx["exposure"],
                                                fx["output_transfer"], fx["gamma"]))
        approx = [r for r in sel if r.result["mode"] != "reference"] or sel
        best = min(approx, key=lambda r: r.result["relative_rmse"])
        worst = max(sel, key=lambda r: r.result["relative_rmse"])
        row = len(rows.steps) - 1
        cells = [(ref_png, f"{ref['samples_per_pixel'][0]} spp, noise {100 * ref['noise']:.2f}%")]
        for r in (best, worst):
            mask = study.metric_mask(t, r.frame.hdr)
            cells.append((r.frame.png, f"{r.label}: {100 * r.result['relative_rmse']:.1f}%"))
            cells.append((error_image(r.frame.hdr, ref["hdr"], mask), "|dL| / L, 0 .. 50%"))
        for j, (png, label) in enumerate(cells):
            results.append(sheet.CellResult(sweep.Cell(row, j, [], label),
                                            Frame(np.zeros(png.shape[:2] + (4,), np.float32), png, {}, {})))
    # small study frames (--max-side 64) are enlarged by whole pixels until every header and
    # caption fits under its cell, rather than cutting the words
    w = results[0].frame.png.shape[1] if results else 1
    need = max([sheet.text_width(s.label, sheet.AXIS_PT) for s in columns.steps]
               + [sheet.text_width(r.cell.label, sheet.CAPTION_PT) for r in results])
    k = max(1, math.ceil(need / w))
    if k > 1:
        for r in results:
            r.frame.png = np.repeat(np.repeat(r.frame.png, k, axis=0), k, axis=1)
    lay = sheet.layout(results, rows, columns, title, "values")
    return sheet.assemble(results, rows, columns, title, "values", lay)
