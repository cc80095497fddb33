"""The pass contract. A pass declares when it runs (a predicate on the scene and its effect
modes), the bakes it reads, the kernel defines it adds and the buffers it needs allocated
(`Buffer`: element type and count, per sample, per pixel or per frame); which named buffers it
reads and writes follow from its kernels' parameters (`const` or not). setup() prepares its
per-frame arguments, run() carries out one tile. Lighting passes only add into `radiance`.
render/frame.py allocates, budgets and reuses buffers from these declarations alone. What a pass
keeps across the tiles of a frame is declared too: a record of its own (`keeps`: per-wave buffers,
what it found of the whole frame) and its counters summed over the tiles (`counters`, each a field
of its report row); the frame's context makes both, and a pass sets nothing on the context."""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from typing import Callable

from iblbake.render.buffers import ELEMENT_BYTES, Buffer  # noqa: F401 (the pass contract's record)
# what the scene's tables hold, shared with the bakes that trace the scene
from iblbake.render.device_scene import geometry_defines, material_defines  # noqa: F401
from iblbake.render.plan import Effects
from iblbake.scene.load import Scene


@dataclass(frozen=True)
class Counter:
    """A count a pass sums over a frame's tiles (Pass.count), shown in its report row as `name`
    where `shown(effects)` holds."""
    name: str
    shown: Callable = lambda _fx: True


class Pass:
    name = ""
    kernel = None            # kernels/<file> (None: host-only)
    function = None          # the kernel function, by default the pass's name
    functions: tuple = ()    # further kernels of the same file it launches
    # Passes of one program are built and loaded together (one binary: each program costs a load
    # even from the cache); their defines must agree, and each reads only its own.
    program = "frame"
    buffers: tuple = ()      # the Buffers this pass needs allocated
    host_sample_bytes = 0    # host memory it keeps per G-buffer sample of the tile (the tile budget)
    fills: tuple = ()        # what of the host's frame its run() reads back: hdr, aovs, png
    host_writes: tuple = ()  # buffers its run() writes from the host (no kernel parameter says so)
    params: tuple = ()       # kernel parameters its setup() and run() bind (the frame's table binds the rest)
    profiles = None          # "paths": profile() measures where its time goes (render(profile_paths=...))
    # its kernels read any pixel of the frame (SSR's rays): a tiled frame runs gather() on every
    # tile, then frame_run() once, before the tiles are run again (render/frame.py sweep)
    whole_frame = False
    keeps = None             # a dataclass of what it keeps across a frame's tiles, made with the frame (kept())
    counters: tuple = ()     # its Counters, summed over a frame's tiles (count()), added to its report row

    def bound_params(self) -> tuple:
        """The kernel parameters this pass binds itself (tests/test_render_passes.py checks that
        these and the frame's table cover every parameter of its kernels)."""
        return self.params

    def kernel_functions(self) -> tuple:
        return (self.function or self.name, *self.functions) if self.kernel else ()

    @property
    def reads(self) -> tuple:
        """Named buffers its kernels read (const pointer parameters)."""
        return _access(self.kernel, self.kernel_functions())[0]

    @property
    def writes(self) -> tuple:
        """Named buffers its kernels write (pointer parameters without const), and those its run()
        writes from the host."""
        return tuple(dict.fromkeys(_access(self.kernel, self.kernel_functions())[1] + self.host_writes))

    def runs(self, scene: Scene, fx: Effects) -> bool:
        return True

    def reads_bakes(self, scene: Scene, fx: Effects) -> list:
        return []

    def reads_environment(self, scene: Scene, fx: Effects) -> bool:
        """Whether setup() reads the panorama itself (ctx.image, ctx.background_image), beyond
        its bakes: the frame reads it from disk only then."""
        return False

    def defines(self, scene: Scene, fx: Effects) -> dict:
        return {}

    def scene_inputs(self, scene: Scene):
        """What this pass reads of the scene, for its reuse key (a frame in a series whose pass
        inputs are unchanged reuses that pass's outputs). By default all that lighting reads:
        the scene without its outputs, its sweep and the display settings."""
        return lighting_inputs(scene)

    def setup(self, ctx) -> dict:
        """Once per frame, before the tiles: named kernel arguments of this pass (tables, bakes)."""
        return {}

    def run(self, ctx) -> dict:
        """Do the work of one tile; returns report fields beyond the name and seconds."""
        raise NotImplementedError

    def profile(self, ctx, repeats: int | None) -> dict:
        """After the frame: where this pass's time went on the last tile (`repeats` rounds, None:
        the default), for the report; changes nothing of the frame."""
        raise NotImplementedError

    def kept(self, ctx):
        """This frame's record of what the pass keeps (its `keeps`)."""
        return ctx.kept[self.name]

    def count(self, ctx, **add) -> dict:
        """Adds to this frame's counters; their totals so far. A whole-frame pass's first sweep
        (ctx.gathering) adds nothing: its tiles are swept again."""
        totals = ctx.counters[self.name]
        for name, n in add.items():
            totals[name] += 0 if ctx.gathering else n
        return totals

    def counted(self, ctx) -> dict:
        """The report fields of its counters (those shown under the frame's effects)."""
        return {c.name: ctx.counters[self.name][c.name] for c in self.counters if c.shown(ctx.plan.effects)}

    def launch_samples(self, ctx) -> float:
        """Run this pass's kernel over every G-buffer sample of the tile with its setup()
        arguments, to completion; the seconds it took (for its rates in the report)."""
        t0 = time.perf_counter()
        ctx.launch(self, (ctx.table["n"],), **ctx.args[self.name])
        ctx.rt.finish()
        return time.perf_counter() - t0


@functools.lru_cache(maxsize=None)
def _access(kernel, functions) -> tuple:
    from iblbake.device.programs import kernel_buffers

    reads, writes = {}, {}
    for fn in functions:
        for name, written in kernel_buffers(kernel, fn).items():
            (writes if written else reads)[name] = True
    return tuple(r for r in reads if r not in writes), tuple(writes)


def surface_cuts(scene: Scene) -> dict:
    """What of the scene's materials changes where rays hit: alpha masks and sides."""
    return {n: {k: m[k] for k in ("alpha", "alpha_mode", "alpha_cutoff", "double_sided", "base_color_map")}
            for n, m in scene.data["materials"].items()}


def mode_defines(fx: Effects) -> dict:
    from iblbake.core.bases import DIFFUSE, SPECULAR
    from iblbake.scene.layout import DIFFUSE_MODES, SPECULAR_MODES
    diffuse = "basis" if fx.diffuse in DIFFUSE else fx.diffuse        # one mode, its header by BASIS_<NAME>
    specular = "basis" if fx.specular in SPECULAR else fx.specular
    return {"DIFFUSE_MODE": DIFFUSE_MODES[diffuse], "SPECULAR_MODE": SPECULAR_MODES[specular]}


DISPLAY_KEYS = ("tonemap", "exposure", "output_transfer", "gamma")


def lighting_inputs(scene: Scene) -> dict:
    d = scene.data
    return {"camera": d["camera"], "environment": d["environment"], "materials": d["materials"],
            "objects": d["objects"], "lights": d["lights"], "probes": d["probes"], "lightmap": d["lightmap"],
            "reflection_probes": d["reflection_probes"],
            "effects": {k: v for k, v in d["effects"].items() if k not in DISPLAY_KEYS}}
