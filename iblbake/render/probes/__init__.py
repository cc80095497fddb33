"""The irradiance probe volume (DDGI: Majercik et al. 2019, JCGT 8(2); 2021, JCGT 10(2); NVIDIA's
RTXGI-DDGI 1.x), baked once, offline, to its mean over every ray (no hysteresis: nothing is
temporal here). One module per idea:

  grid.py        where the probes stand (Grid; an automatic grid from the scene's bounds)
  rays.py        the rays' directions (traced by the paths' Tracer, render/paths/tracer.py:
                 kernels/paths/probe_trace.cl, the reference's paths against the scene on the device)
  adaptive.py    more rays for the probes whose irradiance is noisy after the first pass
  relocation.py  RTXGI's relocation and classification, probes inside geometry or outside the
                 camera's room
  dilate.py      the off probes' irradiance filled from the active ones around them (Unity APV)
  project.py     the rays' projection into RTXGI's atlases (octahedral irradiance or L2 SH, the
                 distance moments) or a directional basis's coefficients
  volume.py      a baked volume as a frozen record (Volume, with its basis): bake settings, sampling
                 settings, a basis's options
  files.py       probes.json and the atlases: written, read back and validated
  glsl.py        probes.glsl, sampling the files as kernels/probes.h does

and here bake() (what the probes unit of render/units.py builds) with the warnings its report
gives. Every name of those modules a caller uses is importable from here. Sampling:
kernels/probes.h, twin/probes.py. Conventions: docs/conventions.md "Irradiance probes"."""

from __future__ import annotations

import math
import re
import time

import numpy as np

from iblbake.errors import IblbakeError, InputError
from iblbake.render.probes.adaptive import combined_values, more_rays, noise, ray_cap
from iblbake.render.probes.dilate import dilate, dilate_values
from iblbake.render.probes.files import (ENVIRONMENT_FILE, FILES, FORMAT, VERSION, data_texture,
                                         environment_entry, light_entries, load, manifest, read_manifest, save,
                                         sky_entry, write_environment)
from iblbake.render.probes.glsl import SH_GLSL, SPECULAR_TABLES, basis_glsl, glsl
from iblbake.render.probes.grid import (AUTO_MAX_PROBES, DEFAULT_LONGEST, MAX_PROBES, SCALE_RAYS, Grid, apart,
                                        auto_step, axis_counts, box_counts, grid_of, lattice, probe_bytes,
                                        scene_bounds)
from iblbake.render.probes.project import (BACKFACE_BLEND_LIMIT, MAX_DISTANCE, atlas, layout, probe_values, project,
                                           with_borders)
from iblbake.render.paths.tracer import Tracer, trace_defines
from iblbake.render.probes.rays import random_rotation, ray_directions, spherical_fibonacci
from iblbake.render.probes.relocation import (ACTIVE, FIXED_RAYS, INACTIVE, MAX_OFFSET, RELOCATION_PASSES, SURFACE_RAYS,
                                              behind_surfaces, beyond_bounds, classify, inside_geometry, off_surfaces,
                                              outside_camera_rooms, outside_sealed_room, relocate)
from iblbake.render.probes.volume import (SAMPLING_KEYS, Volume, bake_settings, basis_of, basis_options, sampled,
                                          volume_dict)

__all__ = ["ACTIVE", "AUTO_MAX_PROBES", "BACKFACE_BLEND_LIMIT", "CALIBRATION_PATHS", "DEFAULT_LONGEST",
           "ENVIRONMENT_FILE", "ESTIMATE_PATHS", "FILES", "FIXED_RAYS", "FORMAT", "INACTIVE", "INSIDE_WARN",
           "MAX_ATLAS_SIDE", "MAX_DISTANCE", "MAX_OFFSET", "MAX_PROBES", "OFF_SAID", "RELOCATION_PASSES",
           "SAMPLING_KEYS", "SCALE_RAYS", "SH_GLSL", "SPECULAR_TABLES", "SURFACE_RAYS", "VERSION", "Grid", "Tracer",
           "Volume", "atlas", "auto_step", "bake", "bake_settings", "basis_glsl", "basis_of", "basis_options",
           "behind_surfaces", "beyond_bounds", "box_outside", "classify", "combined_values", "data_texture", "dilate",
           "dilate_values", "duration_said", "environment_entry", "estimate", "estimate_said", "glsl", "grid_of",
           "inside_geometry", "layout", "light_entries", "load", "manifest", "more_rays", "noise", "off_surfaces",
           "outside_camera_rooms", "outside_sealed_room", "placement_warnings", "probe_bytes", "probe_values",
           "project", "random_rotation", "ray_cap", "ray_directions", "read_manifest", "relocate", "sampled", "save",
           "scaled_grid", "scene_bounds", "sky_entry", "spherical_fibonacci", "switch_off", "trace_defines",
           "trace_kept", "untraced", "volume_dict", "warnings", "with_borders", "write_environment"]


def scaled_grid(tracer, coarse: Grid, settings: dict, arrays, camera):
    """An automatic grid (or a min/max box's, cut alike) whose spacing is the scene's interior scale
    (grid.auto_step, from SCALE_RAYS rays from the coarse grid's probes and the camera), capped at
    AUTO_MAX_PROBES; and
    what the report says of it (the step the interior asked for, whether the cap coarsened it)."""
    whole = coarse if settings["min"] is None else grid_of({**settings, "min": None, "max": None}, arrays)
    # a box's spacing is the whole scene's interior scale: measured from the same points (its own
    # cells' centres measured a coarser one, 0.44 where the room asks 0.35)
    points = np.concatenate([whole.positions(), np.asarray(camera, np.float64)[None]])
    _, t, _ = tracer.trace(points, spherical_fibonacci(SCALE_RAYS), False)
    hint = auto_step(t)
    grid = grid_of(settings, arrays, hint)
    info = {"interior_step": None if hint is None else round(hint, 6)}
    if hint is not None:
        info["lattice"] = lattice(grid, arrays)
        info.update(cramped(t[-1], grid, arrays, automatic=True))
    if hint is not None and grid.unit > min(hint, coarse.unit) * 1.0001:
        step = min(hint, coarse.unit)
        if settings["min"] is None:
            lo, hi = scene_bounds(arrays)
            asked = axis_counts(hi - lo, step, 2)
        else:                                  # the box's cells at that step, as grid_of cuts them
            asked = box_counts(np.asarray(settings["max"], np.float64) - np.asarray(settings["min"], np.float64), step)
        info["capped"] = {"step": round(step, 6), "probes": math.prod(asked)}
    return grid, info


CAMERA_CELLS = 4       # a cell this many times the camera's free distance is said (a mesh left unscaled)


def cramped(t, grid: Grid, arrays, automatic: bool) -> dict:
    """{'camera_cramped': ...} where the grid's cells are over CAMERA_CELLS times the camera's free
    distance (half of its SCALE_RAYS rays, t, meet a front face within it), with the largest object
    (largest_object) and whether the grid was automatic; else {}."""
    free = float(np.median(np.where(np.asarray(t) < 0, np.inf, t)))
    if not free * CAMERA_CELLS < grid.unit:
        return {}
    return {"camera_cramped": {"free": round(free, 6), "cell": round(grid.unit, 6), "automatic": automatic,
                               **largest_object(arrays)}}


def largest_object(arrays) -> dict:
    """The object whose bounding box is the largest and its diagonal, and the largest diagonal of
    the others ({"object", "extent", "others"}; spheres and meshes: an unscaled mesh's mistake)."""
    ext = {}
    for s in arrays.spheres:
        o = int(s[1, 1:2].view(np.int32)[0])
        ext[o] = max(ext.get(o, 0.0), 2 * math.sqrt(3) * float(s[0, 3]))
    if len(arrays.tris):
        ids = arrays.tris[:, 1, 3].view(np.int32)
        v = arrays.tris[:, :3, :3].astype(np.float64)
        for o in np.unique(ids):
            w = v[ids == o].reshape(-1, 3)
            ext[int(o)] = float(np.linalg.norm(w.max(0) - w.min(0)))
    if not ext:
        return {}
    big = max(ext, key=ext.get)
    return {"object": big, "extent": round(ext[big], 6),
            "others": round(max((e for o, e in ext.items() if o != big), default=0.0), 6)}


def untraced(grid: Grid, arrays, camera) -> np.ndarray:
    """The probes off whatever their rays meet, neither relocated nor traced: those beyond the
    scene's bounds at their grid positions where the camera is within them (relocation.beyond_bounds;
    30-55% of an interior's grid, their rays 31-54% of its paths: the bake 4-9% faster, the frame the
    same, each probe traced keeping its number's random stream)."""
    return beyond_bounds(grid.positions(), scene_bounds(arrays), camera)


def trace_kept(tracer, positions, dirs, keep, progress, done: float, share: float):
    """The shaded rays (tracer.trace) of the probes numbered `keep`, each with its own random stream,
    as arrays over every probe, the others' rays misses (radiance 0, distance +inf, object -1); where
    every probe is kept, the trace's own arrays (no second set of them)."""
    if len(keep) == len(positions):
        return tracer.trace(positions, dirs, True, progress, done, share)
    rad, dist, met = tracer.trace(positions, dirs, True, progress, done, share, ids=keep)
    radiance = np.zeros((len(positions),) + rad.shape[1:])
    t, obj = np.full((len(positions), len(dirs)), np.inf), np.full((len(positions), len(dirs)), -1, met.dtype)
    radiance[keep], t[keep], obj[keep] = rad, dist, met
    return radiance, t, obj


def switch_off(tracer, grid: Grid, offset, t, dirs, obj, settings: dict, camera, skipped=None):
    """(each probe's state, how many each rule switched off, the probes outside the camera's room):
    classification (inside geometry; no surface within its cells), outside the camera's closed or
    sealed room, beyond the scene's bounds with the camera within them (relocation.beyond_bounds),
    behind a surface from what the camera sees near them or outside the room it sees
    (relocation.behind_surfaces). `skipped`: the probes not traced (beyond the bounds at their grid
    positions; their rays t, obj misses), off and counted beyond the bounds whatever else."""
    arrays = tracer.job.arrays
    skipped = np.zeros(grid.count, bool) if skipped is None else skipped
    states = classify(t, dirs, grid, settings) if settings["classification"] else np.zeros(grid.count, int)
    states = np.where(skipped, ACTIVE, states)           # no rays of theirs to classify: the rule below
    inside = (states == INACTIVE) & ((t < 0).mean(1) > settings["backface_threshold"])
    empty = (states == INACTIVE) & ~inside
    pos = grid.positions() + offset
    outside = outside_camera_rooms(pos, arrays, camera)
    outside[~skipped] |= outside_sealed_room(tracer, camera, obj[~skipped])     # the rule that reads their rays
    bounds = scene_bounds(arrays)          # where it stands, or where relocation moved it (off a wall: outwards)
    beyond = ((beyond_bounds(grid.positions(), bounds, camera) | beyond_bounds(pos, bounds, camera))
              & ~outside & (states != INACTIVE))
    live = (states != INACTIVE) & ~outside & ~beyond
    behind, apart = np.zeros(grid.count, bool), np.zeros(grid.count, bool)
    behind[live], apart[live] = behind_surfaces(tracer, pos[live], grid.spacing, camera)
    # still_inside_geometry: off at their last positions; the report's inside_geometry also counts
    # those relocation moved out (inside at their grid positions)
    off_by = {"still_inside_geometry": int(inside.sum()), "no_surface_near": int(empty.sum()),
              "outside_camera_room": int((outside & (states != INACTIVE)).sum()), "beyond_bounds": int(beyond.sum()),
              "behind_surfaces": int(behind.sum()), "outside_seen_room": int(apart.sum())}
    return np.where(outside | beyond | behind | apart, INACTIVE, states), off_by, outside


def bake(job, settings: dict, progress=None) -> dict:
    """The volume of a job's scene (render/units.py Job: the scene, a runtime and the bake store;
    the probes unit asks for it): a Volume of the arrays (as load() returns) and a report."""
    t0 = time.perf_counter()
    arrays = job.arrays
    from iblbake.scene import pack
    camera = pack.camera_vectors(job.scene.data["camera"])[0]
    try:
        grid = grid_of(settings, arrays)
    except IblbakeError as e:             # said as the scene's other errors are: its file and the key's line
        key = re.match(r"probes(\.\w+)?", str(e))
        line = job.scene.lines.get(key.group(0)) if key else None
        raise type(e)(f"{job.scene.source}:{line}: {e}" if line else f"{job.scene.source}: {e}") from None
    tracer = Tracer(job, settings)
    placement = {}
    if settings["counts"] is None and settings["spacing"] is None:     # the whole scene's or a box's
        grid, placement = scaled_grid(tracer, grid, settings, arrays, camera)      # within the cap: no error
    else:                                   # a grid given: its cells against the camera's surroundings too
        placement = cramped(tracer.trace(np.asarray(camera, np.float64)[None], spherical_fibonacci(SCALE_RAYS),
                                         False)[1][0], grid, arrays, automatic=False)
    from iblbake.render.paths.trace import describe
    rays, cap = settings["rays"], ray_cap(settings)   # the work's size said up front (a huge grid printed nothing)
    upto = f" (up to {cap} where noisy)" if cap > rays else ""
    skip = untraced(grid, arrays, camera)
    keep = np.flatnonzero(~skip)
    traced = len(keep)
    guess = estimate(tracer, grid, settings, keep)    # and for a large one, its time on this device
    apart = f"; {grid.count - traced:,} beyond the scene's bounds not traced" if traced < grid.count else ""
    shape = "x".join(map(str, grid.counts))
    describe(progress, f"{traced:,} probes x {rays} rays{upto} = {traced * rays:,} paths ({shape} grid, spacing "
                       f"{grid.unit:.4g}{apart}){estimate_said(guess)}")
    fits(job.scene.source, traced, rays)
    if settings["relocation"]:
        start = np.zeros((grid.count, 3))
        if len(keep):
            start[keep] = off_surfaces(tracer, grid.positions()[keep], grid.spacing)
        placement["on_surface"] = int(start.any(1).sum())        # moved off a surface they stood on
        offset, at_grid = relocate(tracer, grid, settings, progress, start, keep)
    else:
        offset, at_grid = np.zeros((grid.count, 3)), None
    dirs = ray_directions(settings["rays"], settings["seed"])
    base = 0.2 if settings["relocation"] else 0.0
    radiance, t, obj = trace_kept(tracer, grid.positions() + offset, dirs, keep, progress, base, 1.0 - base)
    states, off_by, outside = switch_off(tracer, grid, offset, t, dirs, obj, settings, camera, skip)
    counts, rounds, short = more_rays(tracer, grid.positions() + offset, states != INACTIVE, radiance, t, settings,
                                      progress)
    irr, dist = layout(*combined_values(radiance, t, rounds, grid.spacing, settings), grid, settings)
    irr = dilate(irr, states == INACTIVE, grid.counts, settings["irradiance"], settings["irradiance_texels"])
    data = np.concatenate([offset, states[:, None].astype(np.float64)], 1)
    inside, who = inside_geometry(t, obj, settings["backface_threshold"])
    if at_grid is not None:                       # inside at their grid positions: moved out, or not
        who = np.where(at_grid[0], at_grid[1], who)
        inside = inside | at_grid[0]
    objects = {}
    for o in who[inside]:
        objects[int(o)] = objects.get(int(o), 0) + 1
    report = {"probes": grid.count, **placement, "bytes": grid.count * probe_bytes(settings),
              "rays_per_probe": settings["rays"], "rays_traced": tracer.rays_traced,
              "more_rays": {str(n): int((counts == n).sum()) for n in np.unique(counts) if n > rays},
              **({"noisy_short_of_memory": short} if short else {}),
              "inactive": int((states == INACTIVE).sum()), "off_by": off_by,
              "relocated": int((np.abs(offset).sum(1) > 0).sum()),
              "inside_geometry": int(inside.sum()), "outside_camera_room": int(outside.sum()),
              "inside_objects": {str(k): v for k, v in sorted(objects.items(), key=lambda kv: -kv[1])},
              **box_outside(grid, scene_bounds(arrays)), **({"estimate": guess} if guess else {}),
              "seconds": round(time.perf_counter() - t0, 4)}
    return volume_dict(grid, settings, irr, dist, data, report)


ESTIMATE_PATHS = 1 << 24    # paths from which a bake's time is measured up front: 5-40 s of paths on 2 cores
CALIBRATION_PATHS = 1 << 16     # the paths timed for it, of probes spread over the grid (0.4-0.6 s on 2 shared cores)


def estimate(tracer, grid: Grid, settings: dict, traced=None) -> dict:
    """A large bake's time, measured before it starts (a new user's million-probe grid said its
    size in paths alone): CALIBRATION_PATHS of its own paths (rays in its directions from probes
    spread over those it traces, `traced`, their numbers (default all), at their grid positions),
    timed after a launch that builds the program, the rate extrapolated to its paths (and to its cap
    where noisy probes may take more). {} below ESTIMATE_PATHS. The calibration's rays are not
    counted as the bake's."""
    rays, cap = settings["rays"], ray_cap(settings)
    traced = np.arange(grid.count) if traced is None else np.asarray(traced)
    paths = len(traced) * rays
    if paths < ESTIMATE_PATHS:
        return {}
    per_probe = min(rays, 256)
    dirs = ray_directions(rays, settings["seed"])[:per_probe]
    spread = np.linspace(0, len(traced) - 1, max(1, CALIBRATION_PATHS // per_probe)).astype(np.int64)
    pos = grid.positions()[traced[spread]]
    counted = tracer.rays_traced
    tracer.trace(pos[:1], dirs, True)                 # the program built and the device warm
    t0 = time.perf_counter()
    tracer.trace(pos, dirs, True)
    rate = len(pos) * per_probe / max(time.perf_counter() - t0, 1e-9)
    tracer.rays_traced = counted
    return {"paths": paths, "paths_per_s": round(rate), "seconds": round(paths / rate, 1),
            **({"seconds_at_max_rays": round(len(traced) * cap / rate, 1)} if cap > rays else {})}


def duration_said(seconds: float) -> str:
    """'40 s', '12 min', '3.2 h': a time to the precision an estimate has."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.0f} min" if seconds < 5400 else f"{seconds / 3600:.2g} h"


def estimate_said(guess: dict) -> str:
    """The estimate (estimate()) as the up-front line's tail: ', about 12 min to trace (2.1M paths/s
    measured on this device; up to 1.5 h where noisy)'."""
    if not guess:
        return ""
    upto = f"; up to {duration_said(guess['seconds_at_max_rays'])} where noisy" if "seconds_at_max_rays" in guess else ""
    return (f", about {duration_said(guess['seconds'])} to trace ({guess['paths_per_s'] / 1e6:.2g}M paths/s measured "
            f"on this device{upto})")


PATH_BYTES = 20         # host memory a probe's ray takes: the trace's radiance and distance (4 float32), object met


def fits(source, count: int, rays: int) -> None:
    """An InputError before the work where the trace's results would not fit in this process's
    memory (451,656 probes x 65,536 rays asked 441 GiB and died of a MemoryError after relocation)."""
    from iblbake.io import memory
    need, free = count * rays * PATH_BYTES, memory.host_bytes_available()
    if free is not None and need > free:
        raise InputError(f"{source}: probes: {count:,} probes x {rays} rays need about {need / 2**30:.3g} GiB of "
                         f"memory for their results, more than the {max(free, 0) / 2**30:.3g} GiB this process may "
                         "still allocate; give fewer probes.rays or a coarser probes.spacing (or probes.min/max "
                         "around what the camera sees)")


def box_outside(grid: Grid, bounds) -> dict:
    """{'box_outside_bounds': {box, bounds}} where the grid's box and the scene's bounds do not
    meet (no surface within the box: no frame reads its probes), else {}."""
    if bounds is None:
        return {}
    pos, half = grid.positions(), np.asarray(grid.spacing) / 2        # the cells' box: probes.min/max
    box, (lo, hi) = (pos.min(0) - half, pos.max(0) + half), bounds
    if not apart(box[0], box[1], bounds):
        return {}
    plain = lambda v: [round(float(x), 6) for x in v]
    return {"box_outside_bounds": {"box": [plain(box[0]), plain(box[1])], "bounds": [plain(lo), plain(hi)]}}


INSIDE_WARN = 0.25      # the share of probes inside geometry (at their grid positions or after) that is said


MAX_ATLAS_SIDE = 16384       # texels: the largest 2D texture most GPUs take (Vulkan's and D3D12's limit)


OFF_SAID = 0.9          # the share of probes off (by any rule) that is said, with each rule's count: cells a
                        # quarter of the interior's free distance leave 75-80% of an open scene's probes in
                        # empty air, off by classification as RTXGI's design has it (backface, garden)
RULES = {"still_inside_geometry": "still inside geometry (relocation did not move them out)",
         "no_surface_near": "no surface within their cells (classification)",
         "outside_camera_room": "outside the camera's closed room",
         "beyond_bounds": "beyond the scene's bounds, the camera within them",
         "behind_surfaces": "behind a surface from every point the camera sees near them",
         "outside_seen_room": "outside the room the camera sees (behind a surface from every point it sees within "
                              "two cells, none in their own)"}


def placement_warnings(report: dict, scene_data: dict | None = None) -> list:
    """The grid's placement said: an automatic grid the AUTO_MAX_PROBES cap made coarser than the
    scene's interior asks (the count and bytes it would have taken), a grid whose cells are over
    CAMERA_CELLS times the camera's free distance (the space the camera is in finer than the cells;
    where an object spans 10 times any other, as one left unscaled does, that object named and
    nothing else said: the cap's and the rules' advice would be the wrong fix), a box wholly outside the
    scene's bounds (box_outside: that, not its probes off), else more than OFF_SAID of the
    probes within the scene's bounds off, by which rule (those beyond the bounds, off around an
    interior the camera is in, are counted in the report, not said)."""
    from iblbake.scene.load import object_label

    out = []
    cap = report.get("capped")
    if cap:
        box = (scene_data or {}).get("probes", {}).get("min") is not None
        out.append(f"probes: the scene's interior asks a spacing of {cap['step']:.4g} ({cap['probes']} probes, "
                   f"{cap['probes'] * report['bytes'] // max(report['probes'], 1) / 2**20:.0f} MiB); the automatic "
                   f"{'spacing' if box else 'grid'} is capped at {AUTO_MAX_PROBES} probes, so {report['probes']} "
                   f"probes ({report['bytes'] / 2**20:.0f} MiB) stand coarser; give probes.spacing"
                   f"{'' if box else ' (or probes.min/max around the part the camera sees)'} for the finer grid")
    tight = report.get("camera_cramped")
    if tight:
        big = tight.get("object")
        scaled = big is not None and 0 < 10 * tight["others"] <= tight["extent"]     # two objects at least
        grid = "automatic grid" if tight.get("automatic", True) else "probes' cells"
        said = f"probes: the camera's surroundings are finer than the {grid}: half its rays meet a surface within " \
               f"{tight['free']:.4g}, the cells are {tight['cell']:.4g}, so the probes cannot resolve the space the " \
               "camera is in"
        if not scaled:
            out.append(said + "; give a finer probes.spacing")
        else:                 # a scale mistake: the cap's and the rules' advice would be the wrong fix, not said
            kind = next((k for k in ("mesh", "sphere", "plane") if scene_data and k in scene_data["objects"][big]),
                        "mesh")
            fix = {"mesh": f"objects.{big}.mesh.scale", "sphere": f"objects.{big}.sphere's center and radius",
                   "plane": f"objects.{big}.plane's point and size"}[kind]
            label = f"objects.{big}" if scene_data is None else object_label(scene_data, big)
            return [f"{said}; {label} spans {tight['extent']:.4g}, {tight['extent'] / max(tight['others'], 1e-30):.0f} "
                    f"times any other object: left at another scale? (its {fix}; else give a finer probes.spacing)"]
    away = report.get("box_outside_bounds")
    if away:                  # its probes' rays meet no surface near: true of them, but no help said
        return out + [f"probes: the probe box {away['box'][0]}..{away['box'][1]} lies wholly outside the scene's "
                      f"bounds {away['bounds'][0]}..{away['bounds'][1]}: no surface is within it, so a frame reads "
                      "none of its probes (the panorama's SH instead); move probes.min/max over the part of the "
                      "scene the camera sees"]
    by = report.get("off_by", {})
    beyond = by.get("beyond_bounds", 0)        # the shell around an interior: off by design, not said
    n, off = report["probes"] - beyond, report.get("inactive", 0) - beyond
    if n > 0 and off > OFF_SAID * n:
        why = ", ".join(f"{by[k]} {text}" for k, text in RULES.items() if by.get(k) and k != "beyond_bounds")
        out.append(f"probes: {off} of the {n} probes within the scene's bounds ({100 * off / n:.0f}%) are off "
                   f"({why or 'classification'}); "
                   "the frame falls back to the nearest active probes, else the panorama's SH"
                   + ("; give more probes.rays (classification needs rays that meet a surface near the probe)"
                      if report.get("off_by", {}).get("no_surface_near", 0) > off / 2 else ""))
    return out


FEW_RAYS = 256          # a probe's rays under which its mean is said to be noisy


def warnings(report: dict, scene_data: dict, volume: dict | None = None) -> list:
    """What a bake's report says a user should know: more than INSIDE_WARN of the probes were inside
    geometry (relocated out of it, or switched off), with the objects whose back faces they saw; an
    atlas wider or taller than MAX_ATLAS_SIDE (an engine cannot load it as one texture); fewer than
    FEW_RAYS rays a probe."""
    from iblbake.scene.load import object_label

    out = []
    if volume is not None:
        nx, ny, nz = volume["counts"]
        for what, texels in (("irradiance", volume["irradiance_texels"]), ("distance", volume["distance_texels"])):
            if what == "irradiance" and not basis_of(volume).atlas:
                continue
            w, h = (texels + 2) * nx * ny, (texels + 2) * nz
            if max(w, h) > MAX_ATLAS_SIDE:
                out.append(f"probes: the {what} atlas is {w} x {h} texels, over the {MAX_ATLAS_SIDE} most GPUs take "
                           f"in one texture; give fewer probes (probes.counts, probes.spacing) or texels")
    out += placement_warnings(report, scene_data)
    if report.get("noisy_short_of_memory"):
        out.append(f"probes: {report['noisy_short_of_memory']} noisy probes took no more rays: their further rays "
                   "would not fit in this process's memory; give a lower probes.max_rays or fewer probes")
    section = scene_data.get("probes") or {}
    rays, most = section.get("rays"), section.get("max_rays")
    if rays is not None and most and section.get("target_noise") and most < 2 * rays:
        out.append(f"probes.max_rays {most} is under twice probes.rays {rays}: no noisy probe takes more rays (a "
                   f"noisy probe's rays double); give max_rays {2 * rays} or more, or omit it (8 x rays)")
    if rays is not None and rays < FEW_RAYS:
        out.append(f"probes.rays {rays}: each probe's light is a mean over {rays} paths, noisy where a sun or a lamp "
                   f"reaches the room (a sun through a window: the floor x0.43 at 16 rays, in a new user's room); "
                   f"give {FEW_RAYS} or more (the default 1024)"
                   + ("" if (scene_data.get("environment") or {}).get("sun") == "extract" else
                      ", or environment.sun: extract"))
    n, inside = report["probes"], report.get("inside_geometry", 0)
    if not n or inside <= INSIDE_WARN * n:
        return out
    objs = report.get("inside_objects", {})
    named = ", ".join(f"{object_label(scene_data, int(o))}: {c}" for o, c in list(objs.items())[:3]
                      if int(o) < len(scene_data["objects"]))
    forced = [int(o) for o in objs if int(o) < len(scene_data["objects"]) and scene_data["objects"][int(o)]["solid"] is True]
    if forced:       # the user made it a solid: the advice is to undo that, not to add solid: false
        advice = (f"{object_label(scene_data, forced[0])} is solid: true (an open mesh bounds a solid by its winding "
                  f"then); set objects.{forced[0]}.solid: auto where probes should see it from either side, or move "
                  "the grid (probes.min, probes.max)")
    else:
        advice = ("a double-sided surface is a front face to probes on either side: set objects.N.solid: false on a "
                  "closed shell they should see from within, or move the grid (probes.min, probes.max)")
    return out + [f"probes: {inside} of {n} probes ({100 * inside / n:.0f}%) are inside geometry (their rays meet the back "
                  f"faces of {named}{', ...' if len(objs) > 3 else ''}); {report['inactive']} probes are off; {advice}"]
