"""Checks of the records a bake leaves in its manifest and a later run reads back (a probe volume's
report, a lightmap's): each value a frame, a command or a warning reads has its type and range
checked, so a hand-edited or damaged record is refused in one line as the entry's arrays are, not
met as a KeyError or a TypeError inside a warning's format."""

from __future__ import annotations

import math


def number(v) -> bool:
    """A finite JSON number (not a bool)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def count(v) -> bool:
    """A non-negative JSON integer (not a bool)."""
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def box(v) -> bool:
    """[[x, y, z], [x, y, z]] of finite numbers."""
    return isinstance(v, list) and len(v) == 2 and all(isinstance(c, list) and len(c) == 3 and all(map(number, c))
                                                        for c in v)


def fields(spec: dict, required=()):
    """A check of a dict whose keys in `spec` pass their checks, those in `required` present."""
    return lambda v: isinstance(v, dict) and all(k in v for k in required) and \
        all(check(v[k]) for k, check in spec.items() if k in v)


def counts_by(key_ok=lambda k: True):
    """A check of a dict of counts whose keys pass key_ok."""
    return lambda v: isinstance(v, dict) and all(key_ok(k) and count(c) for k, c in v.items())


def wrong(record, spec: dict, required=()) -> str | None:
    """What is wrong with a record read back, by `spec` ({key: check}) and `required`, else None."""
    if not isinstance(record, dict):
        return "its report is not a JSON object"
    bad = [k for k in required if k not in record] + [k for k, ok in spec.items() if k in record and not ok(record[k])]
    return f"its report lacks or mangles {', '.join(bad)}" if bad else None
