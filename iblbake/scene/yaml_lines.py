"""YAML with line numbers: safe YAML (the standard tags only, so no object construction; merge
keys `<<: *base` too), the line of every dotted key for error messages, and budgets on size, values and depth that stop
alias bombs and recursive aliases before they cost memory."""

from __future__ import annotations

import re

import yaml

from iblbake.errors import InputError


class Loader(yaml.SafeLoader):
    """SafeLoader reading numbers as a user writes them: YAML 1.1's float needs a dot and a signed
    exponent (1.0e+30), so 1e-6, 1e3, 1E3, 0.5e1 and 1.0e30 were strings (and then "not a
    number"). Plain scalars in scientific notation are floats here, as in YAML 1.2 and JSON."""


Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))



MAX_SCENE_BYTES = 1 << 20      # a scene is a few KB; a bigger file is a mistake or an attack
MAX_SCENE_VALUES = 100_000     # values after YAML aliases are expanded (alias bombs stop here)
MAX_SCENE_DEPTH = 32
_PLAIN_TAGS = {f"tag:yaml.org,2002:{t}" for t in ("map", "seq", "str", "int", "float", "bool", "null")}


def load_with_lines(text: str, source: str):
    """Safe YAML (no tags beyond the standard ones, so no object construction) with the line of
    every dotted key; aliases are expanded under a value and depth budget."""
    if len(text) > MAX_SCENE_BYTES:
        raise InputError(f"{source}: {len(text)} characters; a scene file is at most "
                         f"{MAX_SCENE_BYTES} (meshes and panoramas go in their own files)")
    try:
        node = yaml.compose(text, Loader=Loader)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"{source}:{mark.line + 1}" if mark else source
        problem = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise InputError(f"{where}: not valid YAML: {problem}") from None
    except RecursionError:
        raise InputError(f"{source}: nested too deeply to be a scene") from None
    lines: dict[str, int] = {}
    constructor = Loader(text)
    budget = [MAX_SCENE_VALUES]

    def scalar(n, path):
        try:
            return constructor.construct_object(n, deep=True)
        except yaml.YAMLError as e:
            problem = " ".join(str(getattr(e, "problem", None) or e).split())[:160]
            raise InputError(f"{source}:{n.start_mark.line + 1}: {path or 'document'}: {problem} "
                             f"(scene files use plain YAML values, no tags)") from None

    def walk(n, path, depth):
        if n.tag not in _PLAIN_TAGS:
            tag = n.tag.replace("tag:yaml.org,2002:", "!!")
            hint = "quote it if it is text" if tag == "!!timestamp" else "plain values only"
            raise InputError(f"{source}:{n.start_mark.line + 1}: {path or 'document'}: YAML tag {tag} "
                             f"is not allowed in a scene ({hint})")
        budget[0] -= 1
        if budget[0] < 0:
            raise InputError(f"{source}: expands to more than {MAX_SCENE_VALUES} values (YAML "
                             f"aliases?); a scene needs far fewer")
        if depth > MAX_SCENE_DEPTH:
            short = path if len(path) < 60 else path[:57] + "..."
            raise InputError(f"{source}:{n.start_mark.line + 1}: {short}: nested deeper than "
                             f"{MAX_SCENE_DEPTH} levels (a recursive YAML alias?)")
        lines.setdefault(path, n.start_mark.line + 1)
        if isinstance(n, yaml.MappingNode):
            own, bases = _merge_keys(n, source, path)
            base = {}
            for b in reversed(bases):      # `<<: [*a, *b]`: the first one given wins (its lines too)
                base.update(walk(b, path, depth + 1))
            out = {}
            for k, v in own:
                key = scalar(k, path) if isinstance(k, yaml.ScalarNode) else k
                if not isinstance(key, (str, int, float)) or isinstance(key, bool):
                    what = "a collection" if isinstance(key, yaml.Node) else repr(key)
                    raise InputError(f"{source}:{k.start_mark.line + 1}: {path or 'document'}: a key "
                                     f"must be a plain name, not {what}")
                sub = f"{path}.{key}" if path else str(key)
                lines[sub] = k.start_mark.line + 1
                if key in out:
                    raise InputError(f"{source}:{k.start_mark.line + 1}: {sub}: key given twice")
                out[key] = walk(v, sub, depth + 1)
            return {**base, **out}     # a key written beside the merge key wins over a merged one
        if isinstance(n, yaml.SequenceNode):
            return [walk(v, f"{path}.{i}" if path else str(i), depth + 1) for i, v in enumerate(n.value)]
        return scalar(n, path)

    data = walk(node, "", 0) if node is not None else None
    return data, lines


def _merge_keys(n, source: str, path: str):
    """A mapping's own (key, value) nodes, and the mappings its merge keys bring in (YAML's `<<:`,
    one alias or a list of them), in the order given."""
    own, bases, merged = [], [], False
    for k, v in n.value:
        if k.tag != "tag:yaml.org,2002:merge":
            own.append((k, v))
            continue
        if merged:                 # as any other key given twice (the first would win silently)
            raise InputError(f"{source}:{k.start_mark.line + 1}: {path + '.' if path else ''}<<: key given twice; "
                             f"merge several mappings with one list (<<: [*a, *b])")
        merged = True
        for b in v.value if isinstance(v, yaml.SequenceNode) else [v]:
            if not isinstance(b, yaml.MappingNode):
                raise InputError(f"{source}:{k.start_mark.line + 1}: {path or 'document'}: the merge key << takes "
                                 f"a mapping or a list of them (<<: *name, where &name marks a mapping)")
            bases.append(b)
    return own, bases


def parse_value(text: str, source: str):
    """One value as a scene file would read it (a --set value, a sweep step on the command line)."""
    return load_with_lines(text, source)[0]
