"""The API's argument checks: each argument's kind and value checked before any work, an
InputError naming the argument (as `names` calls it) and what it takes."""

from __future__ import annotations

import math

from iblbake.errors import InputError

# the most memory a vector of a basis's evaluation takes (measured: 850 bytes, ambient dice's
# specular lobe)
VECTOR_BYTES = 1024


def _names(names: dict | None) -> dict:
    """A function's `names`: what its messages call its arguments, where not their own names."""
    if names is not None and not isinstance(names, dict):
        raise InputError(f"names: give a mapping of argument names to what messages call them, or None, "
                         f"not {_kind(names)}")
    return names or {}


def _name(names: dict | None, key: str, default: str | None = None) -> str:
    """What messages call argument `key`: names[key] where the caller says (the command line's
    flag), else `default`, else the argument's own name."""
    return _names(names).get(key, default or key)


def _kind(value) -> str:
    return type(value).__name__


def _shown(value) -> str:
    """A value as a message quotes it: repr on one line, cut to 60 characters (an array's repr
    spans lines, a long list's pages)."""
    try:
        if type(value).__module__ == "numpy" and getattr(value, "ndim", None) == 0:
            value = value.item()          # numpy's repr of a scalar depends on its print options
        text = " ".join(repr(value).split())
    except Exception:                              # noqa: BLE001 - a repr that fails is still a value
        text = f"<{_kind(value)}>"
    return text if len(text) <= 60 else text[:57] + "..."


def _gib(nbytes: float) -> str:
    return f"{nbytes / 2**30:.3g} GiB"


def _fits(what: str, nbytes: float, hint: str) -> None:
    """Before the work: an InputError saying how much memory `what` needs where that is more than
    this process may still allocate (its address-space limit, or the system's available memory)."""
    from iblbake.io.memory import host_bytes_available
    free = host_bytes_available()
    if free is not None and nbytes > free:
        raise InputError(f"{what}: needs about {_gib(nbytes)} of memory, more than the {_gib(max(free, 0))} "
                         f"this process may still allocate; {hint}")


def _whole(value) -> bool:
    """A whole number (a numpy integer too), not a bool."""
    import numbers
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _count(name: str, value, least: int = 1, most: int | None = None) -> int:
    """A whole number in [least, most] (numpy integers too; not a bool, nor a float such as 9.0)."""
    if not (_whole(value) and value >= least and (most is None or value <= most)):
        bounds = f">= {least}" if most is None else f"{least} to {most}"
        raise InputError(f"{name} {_shown(value)}: " + (f"use {bounds}" if _whole(value) and most is not None
                                                         else f"give a whole number {bounds}"))
    return int(value)


def _arguments(fn):
    """`fn` with its arguments checked as the others are: an unknown keyword or a missing argument
    is an InputError naming it (Python's own TypeError otherwise), as basis's options are."""
    import functools

    @functools.wraps(fn)
    def call(*args, **kwargs):
        import inspect
        sig = inspect.signature(fn)
        try:
            sig.bind(*args, **kwargs)
        except TypeError as e:
            what = fn.__qualname__.removesuffix(".__init__")
            takes = f"(its arguments: {', '.join(p for p in sig.parameters if p not in ('cls', 'self'))})"
            unknown = [k for k in kwargs if k not in sig.parameters]
            if unknown:
                raise InputError(f"{unknown[0]}: not an argument of {what} {takes}") from None
            raise InputError(f"{what}: {e} {takes}") from None
        return fn(*args, **kwargs)
    return call


def _real(name: str, value, least: float | None = None) -> float:
    """A finite real number (numpy's too; not a bool or a string), at least `least`."""
    import numbers
    if not (isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)
            and (least is None or value >= least)):
        raise InputError(f"{name} {_shown(value)}: give a finite number" + ("" if least is None else f" >= {least:g}"))
    return float(value)


def _flag(name: str, value) -> bool:
    """True or False (a numpy bool too): not 'no', 1 or None, which would read as one."""
    if isinstance(value, bool) or (type(value).__module__ == "numpy" and _kind(value) in ("bool", "bool_")):
        return bool(value)
    raise InputError(f"{name} {_shown(value)}: give True or False")


def _choice(name: str, value, choices) -> None:
    if not (isinstance(value, str) and value in choices):
        raise InputError(f"{name} {_shown(value)}: use one of {', '.join(map(str, choices))}")


def _callback(name: str, value):
    if value is not None and not callable(value):
        raise InputError(f"{name}: give a function (or None), not {_kind(value)} {_shown(value)}")
    return value


def _device(value) -> None:
    if value is not None and not isinstance(value, str):
        raise InputError(f"device: give an OpenCL device spec ('gpu', 'cpu', 'gpu:N', 'P:D' or part of a "
                         f"device's name) or None, not {_kind(value)} {_shown(value)}")


def _is_path(value) -> bool:
    import os
    return isinstance(value, (str, os.PathLike))


def _path(name: str, value, what: str):
    if not _is_path(value):
        raise InputError(f"{name}: give {what} path (a str or pathlib.Path), not {_kind(value)}")
    return _no_nul(name, value)


def _no_nul(name: str, path):
    """`path`, refused where it holds a NUL (no file can be named so: it read as a missing file,
    the NUL raw in the message), as a scene's path keys are."""
    import os
    text = os.fspath(path)
    if ("\0" if isinstance(text, str) else b"\0") in text:
        raise InputError(f"{name} {_shown(text)}: holds a NUL character, which no path can")
    return path


def _cache(cache):
    """The bake cache folder: None (the default) or a folder's path (made where missing; one that
    cannot be, a file say, is an InputError where the first bake needs it)."""
    return cache if cache is None else _path("cache", cache, "the bake cache folder's")


def _overrides(overrides) -> list:
    """'KEY.PATH=VALUE' strings: one string (one override), a list of them, or None."""
    if overrides is None:
        return []
    if isinstance(overrides, str):
        return [overrides]
    if not (isinstance(overrides, (list, tuple)) and all(isinstance(o, str) for o in overrides)):
        raise InputError(f"overrides: give 'KEY.PATH=VALUE' strings (one, or a list of them), not {_shown(overrides)}")
    return list(overrides)
def _intensity(panorama, value) -> float:
    """A scale of the panorama's radiance: finite, >= 0, and keeping its brightest texel within
    what a texel may hold (images.MAX_ABS_VALUE; beyond it the sums overflow)."""
    from iblbake.io.images import MAX_ABS_VALUE
    value = _real("intensity", value, 0)
    top = float(abs(panorama.pixels).max())
    if value * top > MAX_ABS_VALUE:
        raise InputError(f"intensity {value:g}: scales the panorama's brightest texel ({top:g}) past "
                         f"{MAX_ABS_VALUE:g}; give at most {MAX_ABS_VALUE / top:.3g}")
    return value


def _vectors(name: str, value):
    """An array (..., 3) of finite numbers, float64."""
    import numpy as np
    try:
        a = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: give unit vectors, an array (..., 3) of numbers, not {_kind(value)}") from None
    if a.ndim == 0 or a.shape[-1] != 3:
        raise InputError(f"{name}: give unit vectors, an array (..., 3) of numbers, not shape {a.shape}")
    # a basis's evaluation: measured at most 850 bytes a vector (ambient dice's specular lobe)
    _fits(f"{name} {a.shape}", VECTOR_BYTES * (a.size // 3), "give fewer vectors a call")
    if not np.isfinite(a).all():
        raise InputError(f"{name}: holds non-finite values; give finite unit vectors")
    length = np.linalg.norm(a, axis=-1)
    if a.size and np.abs(length - 1.0).max() > 1e-3:       # the formulas take directions, not any vector
        raise InputError(f"{name}: holds vectors of length {float(length.flat[np.abs(length - 1).argmax()]):.4g}; "
                         "give unit vectors (normalise them)")
    return a
