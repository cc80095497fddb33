"""Where the reference's time goes, measured (docs/manual.md "Where the path tracer's time goes").

OpenCL has no portable clock inside a kernel, so every figure is a launch timed on the host: the
frame's first batch of the reference (the same G-buffer, seeds and sample numbers), launched
again after the frame into a buffer of its own (the frame is not touched).

- Per bounce, by differential launches of the same batch: the reference built with BOUNCES = 1,
  2, 3, ... up to the scene's bounces or `depth`; bounce k costs the launch with k bounces less the one with k - 1.
  Past `depth` (an unbounded or deeper scene) one entry, "k+", holds what the whole launch costs
  beyond.
- Traversal: the reference built with PROFILE_RAYS 1 (kernels/scene.h) records every ray it
  traces (origin, direction, tmax, closest or any hit, the vertex it leaves from); each bounce's
  closest-hit and shadow rays are then traced alone (kernels/trace_rays.cl: the same rays on the
  same work items in the same order, nothing else), less a launch of no ray. A bounce's shading
  is its time less its rays' traversal: sampling, materials, BSDFs, the environment's lookups.
- A check, independent of that split: the reference built with PROFILE_RAYS 2 answers every ray
  from the record without traversing (its sums are the record's, bit for bit): shading alone.
  That plus all the traversal alone, against the whole launch, says how far the parts add up.

Every launch runs once per round, the rounds one after another (the first a warm-up: PoCL
specialises a program at its first launch); a bounce's time is the difference of two launches
next to each other in a round, each figure the median over the rounds. The clock: on a CPU
device the process's CPU time (the device's threads are this process's: other work on the
machine stretches a launch's wall time, not the work it does), on a GPU wall time.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from iblbake.device.programs import kernel_params

DEPTH = 4                     # bounces profiled one by one; the rest of a deeper path is one entry
REPEATS = 5
RECORD_BYTES = 256 << 20      # the profiled batch's record at most (fewer samples where it would be more)
INDEX_INTS = 8                # kernels/scene.h PROFILE_INDEX_INTS
RAY_FLOAT4S = 3               # kernels/scene.h PROFILE_RAY_FLOAT4S
TRACE_KERNEL = "trace_rays.cl"


def variants(defines: dict, depth: int) -> tuple:
    """([(bounces, defines)] of the cumulative launches, one per bounce profiled; whether the
    whole launch holds bounces past them). A path's bounce k is BOUNCES = k (its first vertex is a
    path vertex: BOUNCES = 1 is that vertex alone, its closest-hit ray finding the emission it
    sees); the scene's BOUNCES 0 is unbounded. The direct light (no BOUNCES, the scene's
    `bounces: 1`) is one launch."""
    if "BOUNCES" not in defines:
        return [(1, dict(defines))], False
    n = int(defines["BOUNCES"])
    last = depth if n == 0 else min(n, depth)
    return [(k, {**defines, "BOUNCES": k}) for k in range(1, last + 1)], n == 0 or n > depth


def _name(key) -> str:
    """A launch's name in the record: 'bounces 2', 'whole', 'replay', 'no rays', 'trace 2 closest'."""
    if isinstance(key, tuple):
        return f"trace {key[0]} {key[1]}"
    return f"bounces {key}" if isinstance(key, int) else key


class _Launches:
    """Timed launches on the frame's first batch: the reference's variants and the rays alone."""

    def __init__(self, ctx, ref_pass, b: int, slices: int, defines: dict):
        self.ctx, self.rt = ctx, ctx.rt
        self.n = ctx.table["n"]
        self.items = self.n * min(slices, b)
        self.out = self.rt.empty(16 * self.items)
        self.sink = self.rt.empty(4 * self.items)        # what the rays alone found (kept from the optimiser)
        self.size, self.args = ref_pass.batch_args(ctx, 0, b, slices, self.out)
        self.file, self.fn = ref_pass.kernel, ref_pass.function or ref_pass.name
        self.defines = defines                       # the scene's geometry, for the rays alone
        self.cpu = self.rt.info.kind == "CPU"
        # the profiled program's parameters: the frame's, with prof_rays and prof_index after the
        # scene's tables (kernels/scene.h SCENE_PARAMS under PROFILE_RAYS); the scene's last
        # table is the one before ray_sink in trace_rays.cl's signature
        params = list(kernel_params(self.file, self.fn))
        last_scene = kernel_params(TRACE_KERNEL, "trace_closest")[-2][0]
        i = [p for p, _ in params].index(last_scene) + 1
        self.profiled = tuple(params[:i] + [("prof_rays", None), ("prof_index", None)] + params[i:])

    def _timed(self, kernel, size, params, bound: dict) -> tuple:
        """(wall seconds, CPU seconds of this process) of one launch, to completion."""
        values = []
        for pname, conv in params:
            v = bound[pname] if pname in bound else self.ctx.table[pname]
            values.append(v if conv is None else conv(v))
        self.rt.finish()
        w0, c0 = time.perf_counter(), time.process_time()
        self.rt.run(kernel, size, None, *values)
        self.rt.finish()
        return time.perf_counter() - w0, time.process_time() - c0

    def reference(self, defines: dict, **extra) -> tuple:
        params = self.profiled if "PROFILE_RAYS" in defines else kernel_params(self.file, self.fn)
        return self._timed(self.rt.kernel(self.file, self.fn, defines), self.size, params, {**self.args, **extra})

    def rays_alone(self, kind: str, rays, ix, start) -> tuple:
        fn = "trace_closest" if kind == "closest" else "trace_shadow"
        return self._timed(self.rt.kernel(TRACE_KERNEL, fn, self.defines), (self.items,),
                           kernel_params(TRACE_KERNEL, fn),
                           {"prof_rays": rays, "ray_ix": ix, "ray_start": start, "items": self.items,
                            "ray_sink": self.sink})

    def sums(self) -> np.ndarray:
        return self.rt.read(self.out, (self.items, 4))


def profile_reference(ctx, ref_pass, repeats: int = REPEATS, depth: int | None = None,
                      record_bytes: int | None = None) -> dict:
    """The reference pass's time on this tile split per bounce into shading, closest-hit traversal
    and shadow-ray traversal (the module's docstring says how). ctx: the frame's context after its
    passes ran (the last tile's G-buffer in its table); ref_pass: the Reference pass; depth and
    record_bytes: DEPTH and RECORD_BYTES where None. Returns the `paths_profile` record of the
    frame's report; changes nothing of the frame."""
    t_start = time.perf_counter()
    depth = DEPTH if depth is None else depth
    record_bytes = RECORD_BYTES if record_bytes is None else record_bytes
    rt = ctx.rt
    builds_before = len(rt.builds)
    _, defines = ctx.plan.program(ref_pass)
    ref = ctx.scene.data["effects"]["reference"]
    batch, slices = ref_pass.batching(ctx)
    b = min(batch, ref["max_samples"])
    steps, tail = variants(defines, depth)
    traced = "VISIBILITY" in defines

    def index(items, first, room):
        st = np.zeros((items, INDEX_INTS), np.int32)
        st[:, 0], st[:, 2], st[:, 3] = first, room, 1
        return rt.to_device(st, read_only=False)

    def record(la, first, room, total, mode=1):
        """One launch that records the rays (room 0: counts them); (rays, each item's count)."""
        rays = rt.empty(max(total, 1) * RAY_FLOAT4S * 16)
        idx = index(la.items, first, room)
        la.reference({**defines, "PROFILE_RAYS": mode}, prof_rays=rays, prof_index=idx)
        return rays, rt.read(idx, (la.items, INDEX_INTS), np.int32)[:, 1].astype(np.int64)

    la = _Launches(ctx, ref_pass, b, slices, defines)
    counts = np.zeros(la.items, np.int64)
    if traced:
        zeros = np.zeros(la.items, np.int32)
        counts = record(la, zeros, zeros, 0)[1]
        per_ray = RAY_FLOAT4S * 16 + 4
        if counts.sum() * per_ray > record_bytes and b > 2:       # fewer samples: the record fits
            b = max(2, int(b * record_bytes / (counts.sum() * per_ray)) & ~1)
            la = _Launches(ctx, ref_pass, b, slices, defines)
            zeros = np.zeros(la.items, np.int32)
            counts = record(la, zeros, zeros, 0)[1]
    total = int(counts.sum())
    first = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int32)
    room = counts.astype(np.int32)
    segments, count_of = {}, {}     # (bounce, "closest" | "shadow") -> (ray_ix, ray_start); its rays
    replay_same, rays = None, rt.to_device(np.zeros(4, np.float32))
    if total:
        rays, again = record(la, first, room, total)
        if not np.array_equal(again, counts):
            raise RuntimeError("the reference traced other rays on a second launch of the same batch")
        recorded_sums = la.sums()
        flags = rt.read(rays, (total, RAY_FLOAT4S, 4))[:, 1, 3].view(np.int32)
        closest = (flags & 1) == 0
        # every ray from vertex k (its shadow rays, the closest-hit ray of its BSDF sample) is
        # first traced by the launch with k bounces: bounce k's
        bounce = flags >> 4
        if tail:
            bounce = np.minimum(bounce, steps[-1][0] + 1)
        item = np.repeat(np.arange(la.items), counts)
        for k in np.unique(bounce):
            for kind, mask in (("closest", closest), ("shadow", ~closest)):
                m = (bounce == k) & mask
                if m.any():
                    ix = np.nonzero(m)[0].astype(np.int32)          # item by item, each in its order
                    start = np.concatenate([[0], np.cumsum(np.bincount(item[m], minlength=la.items))])
                    # the buffers keep their host arrays alive (a CPU device reads them in place)
                    segments[(int(k), kind)] = (rt.to_device(ix), rt.to_device(start.astype(np.int32)))
                    count_of[(int(k), kind)] = int(m.sum())
        la.reference({**defines, "PROFILE_RAYS": 2}, prof_rays=rays, prof_index=index(la.items, first, room))
        replay_same = bool(np.array_equal(la.sums(), recorded_sums))
    no_rays = (rt.to_device(np.zeros(1, np.int32)), rt.to_device(np.zeros(la.items + 1, np.int32)))

    rounds = []
    for r in range(repeats + 1):
        got = {}
        for k, defs in steps:
            got[k] = la.reference(defs)
        got["whole"] = la.reference(defines) if tail else got[steps[-1][0]]
        if total:
            got["replay"] = la.reference({**defines, "PROFILE_RAYS": 2}, prof_rays=rays,
                                         prof_index=index(la.items, first, room))
            for key, (ix, start) in segments.items():
                got[key] = la.rays_alone(key[1], rays, ix, start)
            got["no rays"] = la.rays_alone("shadow", rays, *no_rays)
        if r:                       # the first round warms up
            rounds.append(got)
    clock = 1 if la.cpu else 0      # which of (wall, CPU) the parts are measured in

    def med(values):
        return statistics.median(values) if values else 0.0

    def mad(values):
        m = med(values)
        return med([abs(v - m) for v in values])

    labels = [k for k, _ in steps] + ([steps[-1][0] + 1] if tail else [])
    keys = [k for k, _ in steps] + (["whole"] if tail else [])
    whole = med([g["whole"][clock] for g in rounds])
    whole_wall = med([g["whole"][0] for g in rounds])
    samples = la.n * b
    entries = []
    for j, (k, key) in enumerate(zip(labels, keys)):
        part = [g[key][clock] - (g[keys[j - 1]][clock] if j else 0.0) for g in rounds]
        s = med(part)
        wall = med([g[key][0] for g in rounds])

        def alone(kind):
            return med([g[(k, kind)][clock] - g["no rays"][clock] for g in rounds]) if (k, kind) in segments else 0.0

        tc, ts = alone("closest"), alone("shadow")
        entries.append({
            "bounce": k if key != "whole" else f"{k}+",
            "ms": round(s * 1e3, 3), "spread_ms": round(mad(part) * 1e3, 3),
            "share": round(s / whole, 4) if whole > 0 else None,
            "traversal_closest_ms": round(tc * 1e3, 3), "traversal_shadow_ms": round(ts * 1e3, 3),
            "shading_ms": round((s - tc - ts) * 1e3, 3),
            "closest_rays": count_of.get((k, "closest"), 0), "shadow_rays": count_of.get((k, "shadow"), 0),
            "closest_rays_per_sample": round(count_of.get((k, "closest"), 0) / samples, 4),
            "shadow_rays_per_sample": round(count_of.get((k, "shadow"), 0) / samples, 4),
            # the rate of a frame with this many bounces (wall time, as the pass's own)
            "msamples_per_s": round(samples / wall / 1e6, 4) if wall > 0 else None,
        })
    traversal = med([sum(g[key][clock] - g["no rays"][clock] for key in segments) for g in rounds]) if segments else 0.0
    replay = med([g["replay"][clock] for g in rounds]) if total else None
    return {
        "clock": "cpu" if clock else "wall",
        "tile": ctx.tile_index + 1, "tiles": ctx.tile_count,
        "gbuffer_samples": la.n, "batch": b, "frame_batch": min(batch, ref["max_samples"]),
        "work_items": la.items, "samples": samples, "repeats": repeats, "depth": depth,
        "bounces": (ctx.plan.effects.bounces or "unbounded") if "BOUNCES" in defines else 1,
        "visibility": traced,
        "whole_ms": round(whole * 1e3, 3), "whole_spread_ms": round(mad([g["whole"][clock] for g in rounds]) * 1e3, 3),
        "whole_wall_ms": round(whole_wall * 1e3, 3),
        "msamples_per_s": round(samples / whole_wall / 1e6, 4) if whole_wall > 0 else None,
        "per_bounce": entries,
        "per_bounce_over_whole": round(sum(e["ms"] for e in entries) / 1e3 / whole, 4) if whole > 0 else None,
        "rays": total, "traversal_ms": round(traversal * 1e3, 3),
        "replay_ms": None if replay is None else round(replay * 1e3, 3),
        "replay_same_result": replay_same,
        "replay_and_traversal_over_whole":
            None if replay is None or whole <= 0 else round((replay + traversal) / whole, 4),
        "launches_ms": {_name(key): [[round(t * 1e3, 3) for t in g[key]] for g in rounds] for key in rounds[0]},
        "programs_built": len(rt.builds) - builds_before,
        "build_s": round(sum(x["seconds"] for x in rt.builds[builds_before:]), 3),
        "seconds": round(time.perf_counter() - t_start, 3),
    }
