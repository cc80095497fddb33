"""`iblbake devices`: every OpenCL device, whether it works, and which one is used."""

from __future__ import annotations

import click

from iblbake.cli.options import Console, common_options
from iblbake.errors import IblbakeError


@click.command()
@common_options
def devices(quiet, as_json):
    """List OpenCL devices, whether each builds and runs a probe kernel, and which is used."""
    from iblbake.device import choice as cl

    from iblbake.device import icd

    con = Console(quiet, as_json)
    devs, errors, chosen = cl.probe_all()
    summary = {
        "devices": [{"index": d.index, "platform": d.platform, "name": d.name, "type": d.kind,
                     "works": d.ok, "probe": d.reason, "probe_s": round(d.probe_s, 4),
                     "selected": chosen is d} for d in devs],
        "platform_errors": errors,
        "selected": chosen.label if chosen else None,
        "drivers_registered": icd.note,
    }
    lines = []
    for d in devs:
        mark = "*" if chosen is d else " "
        lines.append(f"{mark} {d.index}  {d.kind:5s} {d.name} [{d.platform}]: "
                     f"{'works' if d.ok else 'FAILS'} ({d.reason})")
    lines += [f"  platform error: {e}" for e in errors]
    if icd.note:
        lines.append(f"  {icd.note}")
    lines.append(f"selected: {chosen.label}" if chosen else "selected: none")
    con.result(summary, "\n".join(lines))
    if chosen is None:
        raise IblbakeError(f"no working OpenCL device; {cl.FIX_HINT}")
