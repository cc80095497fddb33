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
           ("relative_rmse", "rel. RMSE"), ("mean_relative_error", "mean rel."), ("max_relative_error", "max rel."),
           ("worst_region_error", "worst object"), ("flip", "HDR-FLIP"), ("pareto", "frontier"))


def table_rows(rows, front) -> list:
    out = []
    for r in rows:
        out.append({"term": r["term"], "label": r["label"], "time_ms": r["time_s"] * 1000, "bake_s": r["bake_s"],
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


def plot(rows, front, path, title: str) -> None:
    """plot_figure written to `path` (PNG, atomic)."""
    import matplotlib.pyplot as plt

    fig = plot_figure(rows, front, title)
    from iblbake.io.atomic import atomic_path
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=fig.dpi, format="png")
    plt.close(fig)


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
            ax.annotate(r["label"], (x, y), fontsize=6, xytext=(3, 2), textcoords="offset points",
                        color="black" if r["label"] in on else "dimgray")
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
    return fig


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
