"""`iblbake cache`: the bake cache's entries, and pruning it to a size."""

from __future__ import annotations

import re
import time

import click

from iblbake.cli.options import Console, cache_option, common_options

_UNITS = {"": 1, "k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}


def _size(ctx, param, value):
    m = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([kmgt]?)i?b?\s*", str(value).lower())
    if not m:
        raise click.BadParameter(f"{value!r}: give a size such as 500M or 2G")
    return int(float(m.group(1)) * _UNITS[m.group(2)])


def _human(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024


def _root(cache_dir):
    from pathlib import Path

    from iblbake.bake import cache
    return Path(cache_dir) if cache_dir else cache.default_root()




@click.group("cache", invoke_without_command=True)
@cache_option("The cache folder")
@common_options
@click.pass_context
def cache_group(ctx, cache_dir, quiet, as_json):
    """List the bake cache's entries (kind, size, last use); `iblbake cache prune` trims it."""
    if ctx.invoked_subcommand is not None:
        return
    from iblbake.bake import cache

    root = _root(cache_dir)
    rows = cache.entries(root)
    now = time.time()
    total = sum(e["bytes"] for e in rows)
    lines = [f"{e['key']:<32} {e['kind']:<12} {_human(e['bytes']):>10}  used {(now - e['used']) / 3600:7.1f} h ago"
             for e in rows]
    lines.append(f"{len(rows)} entries, {_human(total)} in {root}")
    Console(quiet, as_json).result({"cache": str(root), "entries": rows, "bytes": total}, "\n".join(lines))


@cache_group.command("prune")
@click.option("--max-size", required=True, callback=_size, metavar="SIZE",
              help="Remove least-recently-used entries until the cache holds at most SIZE (500M, 2G).")
@cache_option("The cache folder")
@common_options
def prune_command(max_size, cache_dir, quiet, as_json):
    """Trim the cache to --max-size, least recently used first. Safe while other processes use it:
    an entry being built, or used in the last two minutes, is kept."""
    from iblbake.bake import cache

    root = _root(cache_dir)
    removed, busy = cache.prune(root, max_size)
    left = sum(e["bytes"] for e in cache.entries(root))
    human = f"removed {len(removed)} entries ({_human(sum(e['bytes'] for e in removed))}); {_human(left)} left"
    if busy:
        human += f"; kept {len(busy)} in use"
    Console(quiet, as_json).result({"cache": str(root), "removed": removed, "kept_in_use": busy, "bytes": left},
                                   human)
