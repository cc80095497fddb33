"""Sweeps: one or two axes of scene key paths (`sweep:` in the scene, or --rows/--columns), each a
list of steps; a step sets one or more keys. Expanded into cells, each a list of typed
(key path, value) assignments that scene.load applies and validates like --set.

    sweep:
      rows:    {key: materials.gold.roughness, range: {start: 0, stop: 1, count: 5}}
      columns: {key: effects.specular, values: [importance, prefiltered]}
      # or {steps: [{effects.specular: importance, effects.samples: 64, label: N = 64}, ...]}
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field

from iblbake.errors import InputError, UsageError
from iblbake.scene import schema

MAX_STEPS = 256
AXES = ("rows", "columns")


@dataclass
class Step:
    values: list                  # [(key path, value), ...]
    label: str


@dataclass
class Axis:
    name: str                     # rows | columns
    title: str                    # what the sheet writes beside it (the key path, or "variant")
    steps: list = field(default_factory=list)


@dataclass
class Cell:
    row: int
    column: int
    values: list                  # the row's assignments, then the column's
    label: str


def resolve_key(key: str, data: dict, where: str) -> None:
    """Fail in one line unless KEY.PATH names a value of the schema (not a section) that the scene
    has: a material or object the scene defines, a field the schema knows."""
    if not isinstance(key, str) or not key:
        raise InputError(f"{where}: expected a key path such as materials.NAME.roughness, got {key!r}")
    spec, node = schema.SCHEMA, data
    parts = key.split(".")
    for i, part in enumerate(parts):
        sofar = ".".join(parts[:i + 1])
        if isinstance(spec, schema.MapOf):
            names = list((node or {}).keys()) if isinstance(node, dict) else []
            if part not in names:
                raise InputError(f"{where}: {key}: no {sofar.rsplit('.', 1)[0]} named {part!r} in the scene "
                                 f"({', '.join(names) or 'none defined'})")
            spec, node = spec.section, node[part]
        elif isinstance(spec, schema.ListOf):
            n = len(node) if isinstance(node, list) else 0
            if not part.isdigit() or int(part) >= n:
                raise InputError(f"{where}: {key}: {sofar.rsplit('.', 1)[0]} has no item {part} (it has {n})")
            spec, node = spec.section, node[int(part)]
        elif isinstance(spec, schema.Section):
            if part not in spec.fields:
                near = difflib.get_close_matches(part, list(spec.fields), 1, 0.6)
                hint = f"did you mean {near[0]!r}?" if near else f"valid: {', '.join(spec.fields)}"
                raise InputError(f"{where}: {key}: unknown key {sofar!r} ({hint})")
            spec = spec.fields[part]
            node = node.get(part) if isinstance(node, dict) else None
        else:
            raise InputError(f"{where}: {key}: {'.'.join(parts[:i])} is a value, not a section")
    if isinstance(spec, schema.Section) and spec.optional:
        return                  # a material's map: a step may remove it (null) or give another
    if isinstance(spec, (schema.Section, schema.MapOf, schema.ListOf)):
        inside = ", ".join(spec.fields) if isinstance(spec, schema.Section) else "its entries"
        raise InputError(f"{where}: {key}: is a section; sweep one of its values ({inside})")
    if key.split(".")[0] == "sweep":
        raise InputError(f"{where}: {key}: a sweep cannot sweep itself")


def _range(spec, where: str) -> list:
    if not isinstance(spec, dict) or set(spec) - {"start", "stop", "count", "geometric"} \
            or not {"start", "stop", "count"} <= set(spec):
        raise InputError(f"{where}: expected {{start, stop, count}} (and geometric: true), got {spec!r}")
    a, b, n, geo = spec["start"], spec["stop"], spec["count"], spec.get("geometric", False)
    for k, v in (("start", a), ("stop", b)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f"{where}.{k}: {v!r} is not a finite number")
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_STEPS:
        raise InputError(f"{where}.count: {n!r}: give a whole number from 1 to {MAX_STEPS}")
    if not isinstance(geo, bool):
        raise InputError(f"{where}.geometric: {geo!r} is not true or false")
    if geo and (a <= 0 or b <= 0):
        raise InputError(f"{where}: a geometric range needs start and stop > 0 (got {a}, {b})")
    if n == 1:
        vals = [float(a)]
    elif geo:
        vals = [a * (b / a) ** (i / (n - 1)) for i in range(n)]
    else:
        vals = [a + (b - a) * i / (n - 1) for i in range(n)]
    if all(isinstance(x, int) for x in (a, b)) and (geo or (b - a) % max(n - 1, 1) == 0):
        vals = [int(round(v)) for v in vals]           # whole-number ranges stay whole (sample counts)
    return vals


def format_value(v) -> str:
    if isinstance(v, bool):       # YAML's on/off and true/false: the schema reads both as switches
        return "on" if v else "off"
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return "[" + ", ".join(format_value(x) for x in v) + "]"
    return str(v)


def parse_axis(name: str, spec, data: dict, where: str, label_format: str | None = None) -> Axis:
    """An axis from its YAML form (see the module doc)."""
    if isinstance(spec, list):
        spec = {"steps": spec}
    if not isinstance(spec, dict):
        raise InputError(f"{where}: expected {{key, values}}, {{key, range}} or {{steps}}, got {spec!r}")
    unknown = set(spec) - {"key", "values", "range", "steps"}
    if unknown:
        raise InputError(f"{where}: unknown key {sorted(unknown)[0]!r} (valid: key, values, range, steps)")
    if "steps" in spec:
        if set(spec) != {"steps"}:
            raise InputError(f"{where}: steps set their own keys; give steps alone, without key/values/range")
        steps_in = spec["steps"]
        if not isinstance(steps_in, list) or not steps_in:
            raise InputError(f"{where}.steps: give a non-empty list of {{KEY.PATH: value, label: text}} maps")
        steps, keys = [], []
        for i, st in enumerate(steps_in):
            w = f"{where}.steps.{i}"
            if not isinstance(st, dict) or not (set(st) - {"label"}):
                raise InputError(f"{w}: expected a map of KEY.PATH: value (and label), got {st!r}")
            vals = [(k, v) for k, v in st.items() if k != "label"]
            for k, _ in vals:
                resolve_key(k, data, w)
                keys.append(k)
            label = str(st["label"]) if "label" in st else ", ".join(f"{k.rsplit('.', 1)[-1]}={format_value(v)}"
                                                                      for k, v in vals)
            steps.append(Step(vals, label))
        title = keys[0] if len(set(keys)) == 1 else "variant"
    else:
        if "key" not in spec:
            raise InputError(f"{where}: missing 'key' (the key path this axis varies)")
        key = spec["key"]
        resolve_key(key, data, f"{where}.key")
        if ("values" in spec) == ("range" in spec):
            raise InputError(f"{where}: give exactly one of values or range")
        if "values" in spec:
            vals = spec["values"]
            if not isinstance(vals, list) or not vals:
                raise InputError(f"{where}.values: give a non-empty list of values")
        else:
            vals = _range(spec["range"], f"{where}.range")
        if len(vals) > MAX_STEPS:
            raise InputError(f"{where}: {len(vals)} steps, more than {MAX_STEPS}")
        fmt = label_format or "{value}"
        steps = [Step([(key, v)], fmt.format(value=format_value(v), key=key.rsplit(".", 1)[-1])) for v in vals]
        title = key
    return Axis(name, title, steps)


RANGE_SYNTAX = "START:STOP:COUNT[:linear|geometric]"
SPACINGS = {"linear": False, "geometric": True, "log": True}      # log: the older name of geometric


def parse_cli_axis(text: str, flag: str = "--rows") -> dict:
    """--rows KEY=START:STOP:COUNT[:linear|geometric] (a range) or KEY=v1,v2,... (values, as YAML).
    A spec that looks like a range (a ':' outside quotes) and is not one is refused, naming the
    syntax, before anything renders."""
    key, sep, rhs = text.partition("=")
    if not sep or not key.strip() or not rhs.strip():
        raise UsageError(f"{flag} {text!r}: expected KEY.PATH={RANGE_SYNTAX} or KEY.PATH=v1,v2,...")
    items = split_values(rhs)
    if any(":" in x and x.strip()[:1] not in ("'", '"', "[", "{") for x in items):
        parts = [x.strip() for x in rhs.split(":")]
        try:
            a, b, n = (_value(x, flag) for x in parts[:3]) if len(parts) in (3, 4) else (None, None, None)
        except InputError:
            a = b = n = None
        numbers = all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in (a, b))
        if len(items) > 1 or not numbers or isinstance(n, bool) or not isinstance(n, int) or (
                len(parts) == 4 and parts[3] not in SPACINGS):
            raise UsageError(f"{flag} {text!r}: a range is KEY.PATH={RANGE_SYNTAX} (numbers START and STOP, "
                             f"a whole COUNT), e.g. 0:1:5 or 1:256:9:geometric; values are v1,v2,... (quote "
                             f"a value with ':')")
        geometric = len(parts) == 4 and SPACINGS[parts[3]]
        return {"key": key.strip(), "range": {"start": a, "stop": b, "count": n, "geometric": geometric}}
    try:
        vals = [_value(x, flag) for x in items]
    except InputError as e:
        raise UsageError(f"{flag} {text!r}: a value does not parse ({str(e).split(': ', 1)[-1][:120]})") from None
    return {"key": key.strip(), "values": vals}


def _value(text: str, flag: str):
    """A step's value read as a scene file reads it (numbers in scientific notation included)."""
    from iblbake.scene.yaml_lines import parse_value
    return parse_value(text.strip(), flag)


def split_values(text: str) -> list:
    """v1,v2,... split at the commas outside brackets, braces and quotes, so a list-valued key
    sweeps whole lists: base_color=[1,0,0],[0,1,0] is two values."""
    out, depth, quote, start = [], 0, None, 0
    for i, ch in enumerate(text):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth = max(depth - 1, 0)
        elif ch == "," and depth == 0:
            out.append(text[start:i])
            start = i + 1
    return out + [text[start:]]


def plan_sheet(sc, rows=None, columns=None, label_format: str | None = None) -> tuple:
    """(axes, cells) of a scene's sweep; --rows / --columns (dicts from parse_cli_axis) replace the
    scene's axes. A scene with no axis is one cell."""
    sweep = sc.data.get("sweep") or {}
    specs = {"rows": rows if rows is not None else sweep.get("rows"),
             "columns": columns if columns is not None else sweep.get("columns")}
    axes = {}
    for name in AXES:
        if specs[name] is not None:
            where = f"--{name}" if (rows if name == "rows" else columns) is not None else \
                f"{sc.source}:{sc.lines.get(f'sweep.{name}', '?')}: sweep.{name}"
            axes[name] = parse_axis(name, specs[name], sc.data, where, label_format)
    r = axes.get("rows") or Axis("rows", "", [Step([], "")])
    c = axes.get("columns") or Axis("columns", "", [Step([], "")])
    cells = [Cell(i, j, rs.values + cs.values, " / ".join(x for x in (rs.label, cs.label) if x))
             for i, rs in enumerate(r.steps) for j, cs in enumerate(c.steps)]
    return r, c, cells
