"""`iblbake compare`: two frames or two sheets, a metric, a tolerance, an exit status for CI."""

from __future__ import annotations

import click

from iblbake.cli.options import Console, common_options, non_negative
from iblbake.errors import IblbakeError


@click.command("compare")
@click.argument("reference", metavar="REFERENCE", type=click.Path(dir_okay=False))
@click.argument("test", metavar="TEST", type=click.Path(dir_okay=False))
@click.option("--metric", type=click.Choice(["flip", "rmse"]), default="flip", show_default=True,
              help="flip: mean FLIP (LDR-FLIP for PNG, HDR-FLIP for EXR; 0 identical, 1 as different as can "
                   "be); rmse: RMSE relative to the reference's RMS, in linear values for EXR.")
@click.option("--tolerance", type=float, default=0.0, show_default=True, callback=non_negative,
              help="Fail (exit 1) where an error is above this.")
@click.option("--layout", "layout_path", type=click.Path(dir_okay=False, exists=False), default=None,
              metavar="SHEET.json", help="The reference sheet's layout (iblbake sheet --layout): compare cell by "
                                         "cell and print each cell's error.")
@common_options
def compare_command(reference, test, metric, tolerance, layout_path, quiet, as_json):
    """Compare TEST against REFERENCE (two PNGs or two EXRs of one size): print the error, per
    cell for sheets, and exit 1 where any is above --tolerance."""
    from iblbake.study import compare

    boxes = compare.read_layout(layout_path, reference) if layout_path else None
    errors = compare.compare(reference, test, metric, boxes)
    over = [(n, e) for n, e in errors if not e <= tolerance]
    summary = {"reference": reference, "test": test, "metric": metric, "tolerance": tolerance,
               "errors": [{"name": n, "error": e} for n, e in errors], "failed": [n for n, _ in over]}
    lines = [f"{n}: {metric} {e:.6g}{'  > tolerance' if not e <= tolerance else ''}" for n, e in errors]
    Console(quiet, as_json).result(summary, "\n".join(lines))
    if over:
        raise IblbakeError(f"{test}: {len(over)} of {len(errors)} over --tolerance {tolerance:g} "
                           f"(worst {max(e for _, e in over):.4g}, {over[0][0]})")
