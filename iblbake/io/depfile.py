"""Make-format dependency files, as `gcc -MD -MF` writes them: `target ...: prerequisite ...`, with
a phony rule per prerequisite so that a deleted input does not stop make (gcc's -MP). Paths
under the working folder are written relative to it, as a Makefile run there names them."""

from __future__ import annotations

import os

from iblbake.io.atomic import write_bytes


def _name(path) -> str:
    """The path as make in the working folder sees it, quoted (spaces and '#' backslashed, '$'
    doubled)."""
    p = os.path.abspath(str(path))
    cwd = os.getcwd()
    if p == cwd or p.startswith(cwd + os.sep):
        p = os.path.relpath(p, cwd)
    return p.replace("$", "$$").replace("#", "\\#").replace(" ", "\\ ")


def _head(targets, prerequisites) -> str:
    deps = dict.fromkeys(_name(d) for d in prerequisites)
    return " ".join(_name(t) for t in targets) + ":" + "".join(f" \\\n  {d}" for d in deps) + "\n"


def rule(targets, prerequisites) -> str:
    """One rule and its phony prerequisite rules."""
    return write_rules([(targets, prerequisites)])


def write_rules(rules) -> str:
    rules = list(rules)
    inputs = dict.fromkeys(_name(d) for _, p in rules for d in p)
    return "\n".join(_head(t, p) for t, p in rules) + "\n" + "".join(f"{d}:\n" for d in inputs)


def write(path, rules, batch=None) -> None:
    """rules: [(targets, prerequisites), ...]; the phony rules for the inputs once (written with
    `batch`'s other outputs, atomic.Batch, where given). A name that is not UTF-8 is written as
    its raw bytes (os.fsencode), as make and `iblbake deps` name it."""
    write_bytes(path, os.fsencode(write_rules(rules)), batch)
