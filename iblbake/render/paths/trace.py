"""The one driver of the path tracer: trace(source, engine) runs a ray source's launches one after
another through the engine and hands each launch's results to the source, which adds them where it
accumulates and says whether to stop (Mitsuba 3's one integrator over its sensors).

A source is a declared record (Source): its program and kernel function, how it binds them (its
defines, table and arguments: launch), the launches that generate its rays (launches(), which may
read what has accumulated so far) and where their results go (accumulate(), then result()). The
sources: the reference's camera samples (render/paths/camera.py CameraSamples), rays from points
(render/paths/rays.py PointRays: the irradiance probes' rays) and rays per texel from a point
(TexelRays: the reflection captures' texels). A lightmap's texels are one more Source: its kernel
(rays over each texel's hemisphere from its own position), launches of whole texels, each texel's
mean kept as TexelRays keeps it.

The engine turns a launch into device work. One is left: the megakernel, a work item following its
path to its end. The wavefront of stages (Laine, Karras and Aila 2013; kernels/paths/wavefront.cl)
gave the same frames but ran 0.64-0.83x the megakernel's samples per second on both CPU runtimes
and 4-10x slower on a GPU (docs/benchmarks.md "Megakernel or wavefront"); it is retired: its kernel,
driver and benchmark last stand in commit e6be59a (kernels/paths/wavefront.cl,
render/passes/reference.py Reference.wavefront, benchmarks/bench_wavefront.py)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

from iblbake.errors import InputError


def describe(progress, text: str):
    """Say the work's size before it starts, where the progress callback can (the command line's
    carries describe(text): a note on stderr and the bar's label); a plain callable is not told."""
    tell = getattr(progress, "describe", None)
    if callable(tell):
        tell(text)


@dataclass(frozen=True)
class Launch:
    """One launch of a source: its work items, its arguments beyond what the source binds, and
    `part`, the source's own note of what it covers (first sample, probe or texel, and more)."""
    size: int
    args: dict = field(default_factory=dict)
    part: tuple = ()


class Source(ABC):
    """A ray source. program, function: its kernel (kernels/NAME). launch(global size, function,
    **args): run it with the source's defines, table and bound arguments. launches(): the Launch
    records that generate its rays, in order (a generator may look at what accumulate() kept:
    the reference stops at its noise target). accumulate(launch): read that launch's results back
    and add them in; True stops the source. result(): what the source made."""
    program = ""
    function = ""

    @abstractmethod
    def launch(self, global_size, function, **args): ...

    @abstractmethod
    def launches(self): ...

    @abstractmethod
    def accumulate(self, launch: Launch) -> bool: ...

    @abstractmethod
    def result(self): ...


def megakernel(source: Source, la: Launch):
    """One kernel over the launch's work items, each following its path to its end."""
    source.launch((la.size,), source.function, **la.args)


ENGINES = {"megakernel": megakernel}


def trace(source: Source, engine: str = "megakernel"):
    """Run every launch of `source` through `engine` (ENGINES) until it is done or asks to stop;
    return source.result()."""
    run = ENGINES.get(engine)
    if run is None:
        raise InputError(f"path engine {engine!r} is not one of {' | '.join(ENGINES)} (the wavefront is retired)")
    for la in source.launches():
        run(source, la)
        if source.accumulate(la):
            break
    return source.result()
