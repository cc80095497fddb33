"""`iblbake render`: plan the effect set of a scene, load what it reads, run the passes.

render() is a sequence of named steps: plan (plan_frame: the effect set and its passes), place
the scene (place_scene: its units, render/units.py, and the camera's table), load the bakes the
passes read (bakes.load_all, the one place a report's bake rows come from), allocate (the tiles,
the passes a series reuses, the host's frame, each pass set up: one Context, a declared record),
sweep (every pass over every tile, a whole-frame pass's first sweep before) and report (finish).
It returns the frame and a report of every unit and pass with its time, cache hit or miss, and
the device. A caller that renders many frames passes its runtime and Bakes, so nothing is probed,
compiled, read or baked twice. A frame whose buffers do not fit the device renders in tiles of
rows (the same pixels), and one that cannot fit fails in one line.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iblbake.io.memory import host_bytes_available
from iblbake.errors import InputError
from iblbake.render import enclosure
from iblbake.render.bakes import Bakes, load_all
from iblbake.render.device_scene import TABLE as DEVICE_SCENE_TABLE
from iblbake.render.device_scene import environment_frame
from iblbake.render.passes.base import DISPLAY_KEYS
from iblbake.render.plan import Plan, plan
from iblbake.render.units import Job
from iblbake.scene import pack
from iblbake.scene.load import AOVS, Scene

DEVICE_SHARE = 0.5                        # of the device's global memory, for one frame's buffers
FRAME_HOST_PIXEL_BYTES = 16 + 4 + 40      # the host's frame: hdr, png and AOVs
PLACEHOLDER_BYTES = 16                    # a buffer no running pass needs, bound for its parameter
TABLE_TILE = ("n", "npix", "pixel0")      # per tile: samples, pixels, the first pixel's index
# per frame: the camera, the geometry (scene/pack.py), materials and textures, the panorama's frame
TABLE_SCENE = ("cam", "width", "height", "spp", "jitter", *DEVICE_SCENE_TABLE, "env_rot", "env_scale")


class Report:
    def __init__(self, device: str):
        self.device = device
        self.bakes: list = []
        self.passes: dict = {}

    def bake(self, name, seconds, cached, **extra):
        self.bakes.append({"name": name, "seconds": round(seconds, 4), "cached": cached, **extra})

    def run(self, name, seconds, **extra):
        p = self.passes.setdefault(name, {"name": name, "seconds": 0.0})
        p["seconds"] = round(p["seconds"] + seconds, 6)   # summed over tiles (microseconds: a GPU pass takes 0.1 ms)
        p.update(extra)


@dataclass
class Frame:
    """A rendered frame (iblbake.Frame).

    hdr: float32 (H, W, 4), linear RGB radiance and coverage (alpha).
    png: uint8 (H, W, 3) as the device tone-mapped it, where the scene writes a PNG, else None;
        tonemapped is the display image either way.
    aovs: normal and albedo (H, W, 4) float32, depth and object (H, W) float32, where rendered.
    report: the effect set, every bake and pass with its seconds and cache hit, the kernel
        builds, the device, the resolution and elapsed_s.
    display: the scene's tone map settings (effects.tonemap, exposure, output_transfer, gamma
        and output.dither), for tonemapped.
    """

    hdr: np.ndarray
    png: np.ndarray | None
    aovs: dict
    report: dict
    display: dict | None = None
    _host_png: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def tonemapped(self) -> np.ndarray:
        """uint8 (H, W, 3), the display image: what a PNG output holds. Where the device did not
        tone-map (no PNG output), the same operator and dither on the host, on first use."""
        if self.png is not None:
            return self.png
        if self._host_png is None:
            from iblbake.core import tonemap
            d = self.display
            if d is None:
                raise ValueError("a frame without its display settings has no tone-mapped image")
            self._host_png = tonemap.display_u8(self.hdr, d, d.get("dither", False))
        return self._host_png


class Reuse:
    """What the last frame of a series left on the device, for the next one: its buffers, host
    frames and the input key of every pass. A pass whose inputs (the scene values it reads, its
    defines, the passes upstream of it) are unchanged is not run again; its outputs are the last
    frame's. Single-tile frames on one runtime only."""

    def __init__(self):
        self.state = None


def pass_keys(pl: Plan, scene: Scene, loaded: dict | None = None) -> dict:
    """Each pass's input key: the scene values it reads, its defines, the keys upstream of it, and
    which baked value each bake it reads is (a panorama rewritten at the same path bakes anew: the
    scene is the same, the bake's value is not; a Renderer kept the last frame's image)."""
    from iblbake.bake.cache import content_key

    loaded = loaded or {}
    keys = {}
    for i, p in enumerate(pl.passes):
        upstream = [keys[q.name] for q in pl.passes[:i] if set(q.writes) & set(p.reads)]
        # the bakes' store keeps each value it baked alive (memoised by content): its id names it
        bakes = [(b, id(loaded.get(b))) for b in p.reads_bakes(scene, pl.effects)]
        keys[p.name] = content_key({"scene": p.scene_inputs(scene), "defines": pl.defines.get(p.name),
                                    "upstream": upstream, "bakes": bakes})
    return keys


def passes_to_run(pl: Plan, keys: dict, previous: dict | None) -> set:
    """The passes whose key changed, and every other writer of a buffer one of them rebuilds
    (lighting passes add into one radiance buffer: it is cleared and all of them run)."""
    run = {p.name for p in pl.passes if previous is None or previous.get(p.name) != keys[p.name]}
    grew = True
    while grew:
        grew = False
        for buf in {b for p in pl.passes for b in p.writes}:
            writers = {p.name for p in pl.passes if buf in p.writes}
            if writers & run and not writers <= run:
                run |= writers
                grew = True
    return run


@dataclass(eq=False, slots=True)
class Context:
    """One frame's state, declared: the runtime, scene, plan, bake store and report; the table of
    named buffers and values that kernel parameters are bound from (Runtime.launch); each pass's
    setup() arguments; every unit the frame loaded (units.py: the scene's and the bakes, by name);
    the host's frame the passes read back into; what each pass keeps across the tiles and its
    counters (Pass.keeps, Pass.counters); the tile being swept (start_tile). Made once the frame is
    planned, placed and allocated (render() below); passes read it and fill its tables, never set it."""

    rt: object
    scene: Scene
    plan: Plan
    bakes: Bakes
    report: Report
    warn: object
    progress: object
    table: dict                     # named buffers and values (the scene's, then each tile's)
    loaded: dict                    # unit name -> value (render/units.py)
    frame_hdr: np.ndarray           # the host's frame: hdr, the tone-mapped PNG, the AOVs
    frame_png: np.ndarray | None
    frame_aovs: dict
    tile_count: int
    args: dict = field(default_factory=dict)         # pass name -> its setup() arguments
    kept: dict = field(default_factory=dict)         # pass name -> its `keeps` record
    counters: dict = field(default_factory=dict)     # pass name -> {counter: total over the tiles}
    tile_index: int = 0
    row0: int = 0                   # the tile's first row and its number of rows
    tile_rows: int = 0
    gathering: bool = False         # a whole-frame pass's first sweep: the passes' counts are the second's

    def __post_init__(self):
        for p in self.plan.passes:
            if p.keeps is not None:
                self.kept[p.name] = p.keeps()
            self.counters[p.name] = {c.name: 0 for c in p.counters}

    @property
    def image(self):
        """The panorama as read (the `panorama` unit), where a bake or pass reads it, else None."""
        return self.loaded.get("panorama", (None, None))[0]

    @property
    def background_image(self):
        """The panorama as the background shows it (an extracted sun stays visible in it)."""
        return self.loaded.get("panorama", (None, None))[1]

    @property
    def device_scene(self):
        """The scene's tables on the device (render/device_scene.py), once placed."""
        return self.loaded.get("device_scene")

    @property
    def arrays(self):
        """The scene's device records (scene/pack.py SceneArrays)."""
        return self.device_scene.arrays

    def start_tile(self, index: int, row0: int, rows: int, gathering: bool = False):
        self.tile_index, self.row0, self.tile_rows, self.gathering = index, row0, rows, gathering

    def launch(self, p, global_size, function=None, **args):
        """Run pass p's kernel (or another `function` of its program) over global_size."""
        files, defines = self.plan.program(p)
        return self.rt.launch(files, function or p.function or p.name, defines, global_size, self.table, **args)

    def chain(self, levels) -> dict:
        return self.bakes.chain(self.rt, levels)

    def no_chain(self) -> dict:
        z = self.rt.to_device(np.zeros(4, np.int32))
        return {"chain": self.rt.to_device(np.zeros(4, np.float32)), "off": z, "lw": z, "lh": z, "nlev": 1}


def buffer_names() -> tuple:
    """Every buffer any pass declares: each is in the frame's table, full size or a placeholder."""
    from iblbake.render.passes import PASSES
    return tuple(dict.fromkeys(b.name for p in PASSES for b in p.buffers))


def planned_buffers(pl: Plan, tiled: bool) -> dict:
    """{name: Buffer} of the buffers the running passes need at full size: each declared by a
    running pass, with its `when` define among that pass's defines (or TILED, in a tiled frame).
    Passes declaring one buffer must declare it alike."""
    out = {}
    for p in pl.passes:
        for b in p.buffers:
            if b.when is not None and not (tiled if b.when == "TILED" else b.when in pl.defines.get(p.name, {})):
                continue
            if out.setdefault(b.name, b) != b:
                raise ValueError(f"passes declare buffer {b.name} differently: {out[b.name]} and {b}")
    return out


def frame_bytes(scene: Scene, pl: Plan, rows: int, tiled: bool = False) -> int:
    """Device bytes of a frame's buffers at tiles of `rows` rows: per-sample and per-pixel
    buffers of one tile, per-frame buffers once, and the host memory the passes keep per sample
    (their declarations: render/passes/base.py)."""
    d = scene.data
    w, _h = d["camera"]["resolution"]
    samples, pixels = rows * w * d["camera"]["spp"], rows * w
    total = samples * sum(p.host_sample_bytes for p in pl.passes)
    for b in planned_buffers(pl, tiled).values():
        total += b.element_bytes(d) * {"sample": samples, "pixel": pixels, "frame": 1}[b.per]
    return total


def tile_rows(rt, scene: Scene, pl: Plan, device_budget: int | None = None) -> int:
    """Rows of pixels per tile: the whole frame where its buffers fit the device, else the most
    that do. Fails in one line (naming camera.resolution and camera.spp) where even one row, or
    the frame on the host, does not fit."""
    w, h = scene.data["camera"]["resolution"]
    spp = scene.data["camera"]["spp"]
    largest = max([b.element_bytes(scene.data) for b in planned_buffers(pl, False).values() if b.per == "sample"],
                  default=16)
    largest_row_buffer = w * spp * largest          # the largest per-sample buffer of one row
    dev = rt.info.device
    budget = device_budget if device_budget is not None else int(dev.global_mem_size * DEVICE_SHARE)
    max_alloc = dev.max_mem_alloc_size
    host = host_bytes_available()
    frame_host = w * h * FRAME_HOST_PIXEL_BYTES
    if rt.info.kind == "CPU" and host is not None:  # a CPU device's buffers are host memory too
        budget = min(budget, (host - frame_host) // 2)
    if host is not None and frame_host > host:
        raise InputError(f"camera.resolution: {w}x{h} needs {frame_host / 2**30:.1f} GiB on the host for "
                         f"the frame, more than the {max(host, 0) / 2**30:.1f} GiB available; lower it")
    rows = h if frame_bytes(scene, pl, h) <= budget else 0
    if rows < h:                    # tiles: the frame buffers a tiled frame needs come off the budget
        fixed = frame_bytes(scene, pl, 0, tiled=True)
        rows = max(0, budget - fixed) // max(frame_bytes(scene, pl, 1, tiled=True) - fixed, 1)
    row = frame_bytes(scene, pl, 1, tiled=True)
    rows = min(h, rows, max_alloc // largest_row_buffer)
    if rows < 1:
        raise InputError(f"camera.resolution/camera.spp: one row of {w} pixels at {spp} spp needs "
                         f"{row / 2**20:.0f} MiB on {rt.device_label}, over its "
                         f"{max(budget, 0) / 2**20:.0f} MiB for frame buffers; lower camera.resolution or camera.spp")
    return int(rows)


@dataclass
class Sweep:
    """How the frame is swept: the passes that run (the others reused from the last frame of a
    series), their input keys, the last frame's state where it is reused, and the tiles."""
    run: set
    keys: dict
    prev: dict | None
    rows: int                       # rows per tile
    row0s: list                     # each tile's first row
    names: tuple                    # every buffer name of the table (buffer_names)
    planned: dict                   # the buffers the running passes need at full size

    @property
    def tiled(self) -> bool:
        return len(self.row0s) > 1


def render(scene: Scene, *, runtime=None, cache: Bakes | None = None, reuse: Reuse | None = None,
           device: str | None = None, cache_root: Path | None = None, warn=None, progress=None,
           device_budget: int | None = None, profile_paths: int = 0) -> Frame:
    """Render `scene`. `runtime` (a device.runtime.Runtime) and `cache` (a Bakes) are reused when
    given; otherwise made for this frame (`device`, `cache_root`). With `reuse` (a Reuse kept
    across a series of frames), passes whose inputs did not change since the last frame are not
    run again. `device_budget` overrides the device bytes a frame's buffers may take (tests
    force tiling with it). `profile_paths` (a number of repeats; True: the default's) measures
    where the reference pass's time goes after the frame (render/paths/profile.py): the report's
    `paths_profile`; a plan without the reference pass raises InputError."""
    from iblbake.device.runtime import Runtime

    t_start = time.perf_counter()
    pl = plan_frame(scene, reuse, profile_paths)
    rt = runtime or Runtime(device)
    bakes = cache or Bakes(cache_root)
    bakes.runtime = bakes.runtime or rt
    builds_before = len(rt.builds)
    rep = Report(rt.device_label)
    job = Job(scene, rt, bakes, warn or (lambda _m: None), progress)
    table = place_scene(job, pl, rep)
    load_all(job, pl.bakes, rep)                  # the bakes the passes read
    ctx, sweep = allocate(job, pl, rep, table, reuse, device_budget)
    sweep_frame(ctx, sweep)
    if reuse is not None:
        keep_for_series(reuse, ctx, sweep)
    return finish(ctx, sweep, builds_before, t_start, profile_paths)


def plan_frame(scene: Scene, reuse: Reuse | None, profile_paths) -> Plan:
    """The effect set and its passes (render/plan.py); one program unless a series reuses passes."""
    pl = plan(scene, one_program=reuse is None)
    if profile_paths and not any(p.profiles == "paths" for p in pl.passes):
        raise InputError("profile_paths: this frame has no reference pass to profile (effects.diffuse or "
                         "effects.specular: reference)")
    return pl


def scene_units(scene: Scene, pl: Plan, arrays=None) -> list:
    """The scene's units a frame places: its geometry, the panorama and its sun where some bake or
    pass reads them, its textures where a material has maps, and the scene on the device."""
    names = ["geometry"]
    if bool(pl.bakes) or any(p.reads_environment(scene, pl.effects) for p in pl.passes):
        names += ["panorama", "sun"]
    if arrays is not None and any(r["maps"] for r in arrays.records):
        names.append("textures")
    return names + ["device_scene"]


def place_scene(job: Job, pl: Plan, rep: Report) -> dict:
    """The scene's units into job.loaded (render/units.py; a row each in the report) and the
    frame's table of the scene: the camera, the scene's device tables, the panorama's frame."""
    load_all(job, ["geometry"], rep)
    load_all(job, scene_units(job.scene, pl, job.loaded["geometry"])[1:], rep)
    d = job.scene.data
    cam = d["camera"]
    pos, fwd, right, up, ortho = pack.camera_vectors(cam)
    cam4 = np.zeros((4, 4), np.float32)
    cam4[0, :3], cam4[0, 3] = pos, 1.0 if ortho else 0.0
    cam4[1, :3], cam4[2, :3], cam4[3, :3] = fwd, right, up
    width, height = cam["resolution"]
    rt = job.rt
    return {"cam": rt.to_device(cam4), "width": width, "height": height, "spp": cam["spp"],
            "jitter": rt.to_device(pack.pixel_jitter(cam["spp"]).astype(np.float32)),
            **job.loaded["device_scene"].table, **environment_frame(d["environment"])}


def allocate(job: Job, pl: Plan, rep: Report, table: dict, reuse: Reuse | None, device_budget) -> tuple:
    """(context, sweep): the tiles, the passes to run (a series' last frame's buffers and host
    frame for the others), the host's frame, and every running pass set up."""
    scene, rt = job.scene, job.rt
    width, height = scene.data["camera"]["resolution"]
    spp = scene.data["camera"]["spp"]
    rows = tile_rows(rt, scene, pl, device_budget)
    hdr, png, aovs = host_frame(width, height, planned_buffers(pl, False))
    keys = pass_keys(pl, scene, job.loaded)
    prev = reuse.state if reuse is not None else None
    if prev is not None and not (prev["runtime"] is rt and prev["shape"] == (width, height, spp) and rows == height):
        prev = None
    run = passes_to_run(pl, keys, prev["keys"] if prev else None)
    if prev is not None:              # the last frame's buffers hold what the skipped passes wrote
        table.update(prev["buffers"])
        kept = {f for p in pl.passes if p.name not in run for f in p.fills}   # and its host frame
        hdr = prev["hdr"].copy() if "hdr" in kept else hdr
        aovs = {a: v.copy() for a, v in prev["aovs"].items()} if "aovs" in kept else aovs
        png = prev["png"].copy() if "png" in kept and prev["png"] is not None else png
    row0s = list(range(0, height, rows))
    ctx = Context(rt, scene, pl, job.bakes, rep, job.warn, job.progress, table, job.loaded, hdr, png, aovs,
                  len(row0s))
    for p in pl.passes:
        if p.name not in run:
            continue
        if p.kernel:                  # built (or loaded from the program cache) before any timing
            files, defines = pl.program(p)
            rt.kernel(files, p.function or p.name, defines)
        ctx.args[p.name] = p.setup(ctx)
    return ctx, Sweep(run, keys, prev, rows, row0s, buffer_names(), planned_buffers(pl, len(row0s) > 1))


def host_frame(width: int, height: int, planned: dict) -> tuple:
    """(hdr, png, aovs): the host's frame the buffers the passes fill are read back into."""
    hdr = np.empty((height, width, 4), np.float32)
    png = np.empty((height, width, 4), np.uint8) if "png_u8" in planned else None
    aovs = {"normal": np.empty((height, width, 4), np.float32),
            "albedo": np.empty((height, width, 4), np.float32),
            "depth": np.empty((height, width), np.float32),
            "object": np.empty((height, width), np.float32)} if "aov_normal" in planned else {}
    return hdr, png, aovs


def start_tile(ctx: Context, sweep: Sweep, index: int, row0: int, gathering: bool = False):
    """Tile `index` in the table: its buffers (re)allocated where the size this tile and plan need
    differs from what the table holds (a series of frames reusing buffers may switch AO or AOVs
    on: their buffers grow, and the passes writing them run, being new or redefined), its counts,
    and the radiance the lighting passes add into cleared."""
    width, height = ctx.table["width"], ctx.table["height"]
    ctx.start_tile(index, row0, min(sweep.rows, height - row0), gathering)
    npix = ctx.tile_rows * width
    n = npix * ctx.table["spp"]
    count = {"sample": n, "pixel": npix, "frame": 1}
    for name in sweep.names:
        b = sweep.planned.get(name)
        nbytes = b.element_bytes(ctx.scene.data) * count[b.per] if b else PLACEHOLDER_BYTES
        if name not in ctx.table or ctx.table[name].size != nbytes:
            ctx.table[name] = ctx.rt.empty(nbytes)
    ctx.table.update({"n": n, "npix": npix, "pixel0": row0 * width})
    writers = [p.name for p in ctx.plan.passes if "radiance" in p.writes]
    if not writers or any(w in sweep.run for w in writers):        # none: resolve reads zeros
        ctx.rt.cl.enqueue_fill_buffer(ctx.rt.queue, ctx.table["radiance"], np.float32(0), 0, n * 16)


def sweep_frame(ctx: Context, sweep: Sweep):
    """Every running pass over every tile, each timed into its report row (with its counters);
    a whole-frame pass in a tiled frame is first swept over the whole frame (sweep_whole)."""
    whole = next((p for p in ctx.plan.passes if p.whole_frame and p.name in sweep.run), None)
    if whole is not None and sweep.tiled:
        sweep_whole(ctx, sweep, whole)
    for index, row0 in enumerate(sweep.row0s):
        start_tile(ctx, sweep, index, row0)
        for p in ctx.plan.passes:
            if p.name not in sweep.run:
                ctx.report.run(p.name, 0.0, reused=True)
                continue
            t0 = time.perf_counter()
            extra = p.run(ctx)
            ctx.report.run(p.name, time.perf_counter() - t0, **extra, **p.counted(ctx))


def sweep_whole(ctx: Context, sweep: Sweep, whole):
    """A whole-frame pass (SSR: its rays read any pixel) in a tiled frame: a first sweep runs the
    passes before it over every tile and gathers what it reads of each into frame-sized buffers;
    it then works on the whole frame, and the second sweep (sweep_frame) runs every pass again (the
    per-sample buffers of a tile do not outlive it) with that pass applying what it found. The
    passes count (Pass.count) in the second sweep only: each sample once."""
    before = ctx.plan.passes[:ctx.plan.passes.index(whole)]
    gather_s = 0.0
    for index, row0 in enumerate(sweep.row0s):
        start_tile(ctx, sweep, index, row0, gathering=True)
        for p in before:
            if p.name in sweep.run:
                p.run(ctx)
        t0 = time.perf_counter()
        whole.gather(ctx)
        gather_s += time.perf_counter() - t0
    t0 = time.perf_counter()
    whole.frame_run(ctx)
    ctx.rt.finish()
    ctx.report.run(whole.name, gather_s + time.perf_counter() - t0, sweeps=2)


def keep_for_series(reuse: Reuse, ctx: Context, sweep: Sweep):
    """What the next frame of a series may reuse: the buffers, host frame and pass keys of an
    untiled frame."""
    cam = ctx.scene.data["camera"]
    reuse.state = None if sweep.tiled else {
        "runtime": ctx.rt, "shape": (*cam["resolution"], cam["spp"]), "keys": sweep.keys,
        "buffers": {b: ctx.table[b] for b in (*sweep.names, *TABLE_TILE)},
        "hdr": ctx.frame_hdr, "aovs": ctx.frame_aovs, "png": ctx.frame_png}


def finish(ctx: Context, sweep: Sweep, builds_before: int, t_start: float, profile_paths) -> Frame:
    """The frame and its report, after the enclosure's warnings (once a series) and the paths'
    profile where asked for."""
    rt, pl, d = ctx.rt, ctx.plan, ctx.scene.data
    if sweep.prev is None:            # said once a series, after the frame (an error stays one line)
        for w in enclosure.warnings(ctx.scene, pl.effects, ctx.arrays):       # the sky mirrored inside a room
            ctx.warn(w)
        for w in enclosure.far_camera(ctx.scene, ctx.arrays):                 # a camera left unscaled
            ctx.warn(w)
    elapsed = time.perf_counter() - t_start
    builds = [{"kernel": b["kernel"], "defines": b["defines"], "seconds": round(b["seconds"], 4)}
              for b in rt.builds[builds_before:]]          # the frame's: the profile counts its own
    paths_profile = None
    if profile_paths:             # after the frame, which it does not touch: the last tile's G-buffer
        profiled = next(p for p in pl.passes if p.profiles == "paths")
        if profiled.name not in ctx.args:             # reused from the last frame of a series
            ctx.args[profiled.name] = profiled.setup(ctx)
        paths_profile = profiled.profile(ctx, None if profile_paths is True else int(profile_paths))
    report = {
        "device": rt.device_label,
        "effects": pl.to_json(),
        "bakes": ctx.report.bakes,
        "passes": list(ctx.report.passes.values()),
        "kernel_builds": builds,
        "resolution": list(d["camera"]["resolution"]),
        "spp": d["camera"]["spp"],
        "tiles": len(sweep.row0s),
        "reused": [p.name for p in pl.passes if p.name not in sweep.run],
        "elapsed_s": round(elapsed, 4),
    }
    if paths_profile is not None:
        report["paths_profile"] = paths_profile
    png = ctx.frame_png[..., :3] if ctx.frame_png is not None else None     # RGBA as read back; RGB shown
    display = {**{k: d["effects"][k] for k in DISPLAY_KEYS}, "dither": d["output"]["dither"]}
    return Frame(ctx.frame_hdr, png, ctx.frame_aovs, report, display)


def output_paths(scene: Scene) -> list:
    out = scene.data["output"]
    return [*out["frame"], *(out[a] for a in AOVS if out[a])]


def write_outputs(frame: Frame, scene: Scene) -> list:
    """Write every requested output atomically, together (`batch`, atomic.Batch: all replaced or,
    on a failed write, none); returns the paths written."""
    from iblbake.io import atomic, images

    out = scene.data["output"]
    written = []
    with atomic.Batch() as batch:
        for p in out["frame"]:
            if p.lower().endswith(".png"):
                images.write_png(p, frame.tonemapped, batch)
            else:
                images.write_exr(p, frame.hdr, channels=("R", "G", "B", "A"), batch=batch)
            written.append(p)
        for a in AOVS:
            if out[a]:
                img = frame.aovs[a]
                if a in ("depth", "object"):
                    images.write_exr(out[a], img[..., None], channels=("Z" if a == "depth" else "Y",), batch=batch)
                else:
                    images.write_exr(out[a], img, channels=("R", "G", "B", "A"), batch=batch)
                written.append(out[a])
    return written
