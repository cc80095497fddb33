"""The probe grid (render/probes): where the probes of a scene's `probes` section stand before
relocation (Grid: origin, spacing, counts, RTXGI's probe order), and the scene bounds an automatic
grid overhangs by half a cell on every side."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from iblbake.errors import InputError
from iblbake.render.twin import probes as twin

DEFAULT_LONGEST = 8              # probes along the longest axis where counts and spacing are omitted


@dataclass(frozen=True)
class Grid:
    origin: tuple        # probe (0, 0, 0), before relocation
    spacing: tuple
    counts: tuple        # (nx, ny, nz)

    @property
    def count(self) -> int:
        return math.prod(self.counts)

    @property
    def unit(self) -> float:
        """The smallest spacing: the unit of the biases and distances given in spacing units."""
        return float(min(self.spacing))

    def positions(self) -> np.ndarray:
        """Every probe's grid position, by probe index (RTXGI's order)."""
        return np.asarray(self.origin) + twin.probe_coords(np.arange(self.count), self.counts) * np.asarray(self.spacing)


def apart(lo, hi, bounds) -> bool:
    """Whether the box lo..hi misses the box bounds (lo, hi) along some axis (a shared face meets):
    a probe box or a reflection probe's influence no surface of the scene lies in."""
    return bool(((np.asarray(hi) < bounds[0]) | (np.asarray(lo) > bounds[1])).any())


def scene_bounds(arrays) -> tuple | None:
    """(lo, hi) of the scene's spheres, finite planes and triangles; an infinite plane bounds the
    axis its normal lies along, where it does; None where nothing is bounded."""
    pts = []
    for s in arrays.spheres:
        c, r = s[0, :3].astype(np.float64), float(s[0, 3])
        pts += [c - r, c + r]
    infinite = []
    for pl in arrays.planes:
        p, t, b = pl[0, :3].astype(np.float64), pl[2, :3].astype(np.float64), pl[3, :3].astype(np.float64)
        hw, hd = float(pl[2, 3]), float(pl[3, 3])
        if math.isfinite(hw) and math.isfinite(hd):
            pts += [p + sx * hw * t + sz * hd * b for sx in (-1, 1) for sz in (-1, 1)]
        else:
            infinite.append((p, pl[1, :3]))
    if len(arrays.tris):
        v = arrays.tris[:, :3, :3].reshape(-1, 3).astype(np.float64)
        pts += [v.min(0), v.max(0)]
    if not pts:
        return None
    pts = np.array(pts)
    lo, hi = pts.min(0), pts.max(0)
    for p, nrm in infinite:
        axis = int(np.argmax(np.abs(nrm)))
        if abs(abs(float(nrm[axis])) - 1.0) < 1e-6:
            lo[axis], hi[axis] = min(lo[axis], p[axis]), max(hi[axis], p[axis])
    return lo, hi


MAX_PROBES = 1 << 20             # any grid: the buffers and atlases a device takes
AUTO_MAX_PROBES = 1 << 14        # an automatic grid's cap (~80 MiB of atlases at the default texels): coarser above
SCALE_RAYS = 64                  # rays from each coarse probe and the camera that measure the interior's scale
ENCLOSED = 0.5                   # the share of those rays meeting a front face that makes a point enclosed
INTERIOR_FRACTION = 0.5          # the automatic spacing: this share of...
INTERIOR_QUANTILE = 0.25         # ...this quantile of the enclosed points' free distances (the nearer quarter:
                                 # where the light changes fastest, by openings and objects)


def probe_bytes(settings: dict) -> int:
    """Bytes a probe takes in the volume's float4 buffers (irradiance and distance tiles with their
    borders, its data row): what a grid's count costs, said up front."""
    from iblbake.core.bases.probes import PROBE_BASES
    irr = PROBE_BASES[settings["irradiance"]].device_floats(settings)
    return 16 * (irr + (settings["distance_texels"] + 2) ** 2 + 1)


COUNT_TOLERANCE = 4e-7        # a few float32 roundings (2^-24 each) of the bounds and the step, in cells


def axis_counts(extent, step, plus: int) -> list:
    """Probes along each axis, Python ints (a tiny spacing gives a count no int64 holds, and a
    wrapped count passed the size check once): ceil(extent / step) + plus, or None where that is
    not finite (more probes than any grid holds). An extent a whole number of steps within float32's
    rounding counts that number: the bounds come from float32 vertices (2.4f / 0.3 = 8.0000003),
    and one cell more shifted the centred grid by half a cell, a layer of probes onto the floor and
    the ceiling, moved off them to the outside (a new user's room at spacing 0.3: ceiling 27x)."""
    out = []
    for e, s in zip(np.broadcast_to(extent, 3), np.broadcast_to(step, 3)):
        q = float(e) / float(s)
        if not math.isfinite(q):
            out.append(None)
            continue
        whole = math.floor(q)
        near = q - whole <= min(COUNT_TOLERANCE * max(q, 1.0), 1e-4)     # within rounding of `whole` steps
        out.append((whole if near else math.ceil(q)) + plus)
    return out


def check_count(n: list, settings: dict) -> None:
    """Refuses a grid over MAX_PROBES with its true count (Python ints: no wrap), naming the key
    that asked for it (spacing, else counts)."""
    if any(c is None for c in n) or math.prod(n) > MAX_PROBES:
        total = "more than 10^308" if any(c is None for c in n) else str(math.prod(n))
        shape = " x ".join("inf" if c is None else str(c) for c in n)
        key = next((f"probes.{k}" for k in ("spacing", "counts") if settings[k] is not None), "probes")
        raise InputError(f"{key}: asks {total} probes ({shape}); give fewer probes.counts or a larger "
                         f"probes.spacing (at most {MAX_PROBES} probes)")


def auto_step(t) -> float | None:
    """The spacing the interior's scale asks for, from SCALE_RAYS rays' signed distances t (points,
    rays; +inf a miss, < 0 a back face) traced from the coarse grid's probes and the camera: of the
    points enclosed (ENCLOSED of their rays meet a front face), INTERIOR_FRACTION of the median over
    them of their median ray length (a miss the longest). A corridor 2 wide gets cells of ~0.65, a
    few across its width (a grid by the longest axis had none); None where no point is enclosed (an
    open scene keeps the coarse grid)."""
    t = np.asarray(t, np.float64)
    front = (t >= 0) & np.isfinite(t)
    enclosed = (front.mean(1) >= ENCLOSED) & ((t < 0).mean(1) < 0.25)
    if not enclosed.any():
        return None
    free = np.median(np.where(t[enclosed] < 0, np.inf, t[enclosed]), axis=1)
    step = INTERIOR_FRACTION * float(np.quantile(free, INTERIOR_QUANTILE, method="lower"))
    # points that meet a surface with only half their rays (a floor below an open sky) have a
    # median ray that is a miss: where they are most of the enclosed points the scene is open
    return step if math.isfinite(step) else None


PHASE_FINER = 1.15     # an automatic grid's spacing along an axis may be this much finer where that clears its planes
FINER_COST = 2.0       # clearance (cells) a spacing finer by a share f costs: finer only where it clears 2f more
PHASE_PLANES = 16      # the largest planes across an axis that place its layers (a mesh may have hundreds)
PAIR_PLANES = 8        # ...and the largest of those whose distances propose the finer spacings
PLANE_MERGE = 1e-6     # of the scene's extent: surfaces nearer than this across an axis are one plane
BOUND_OFFSET = 0.3     # cells: a plane on the scene's bounds (seen from inside only) is best read by a layer
                       # this far in
PHASED_AXES = (1,)     # y (up): floors, slabs, ceilings; walls phased too moved a one-sided screen's probes
                       # (backface under city: frame 11% -> 20%) and l_room's (17.5% -> 20.5%)


def axis_planes(arrays, lo, hi) -> list:
    """Per axis, an array of (coordinate, area, side) rows: the scene's surfaces that lie across it
    (flat triangles, planes whose normal is that axis), merged within PLANE_MERGE of the extent, the
    PHASE_PLANES largest first: the floors, slabs, ceilings and walls an automatic grid's layers
    keep off. side: +1 on the bounds' lo, -1 on hi (seen from inside only), 0 inside. An infinite
    plane's area is the bounds' cross-section."""
    extent = np.asarray(hi, np.float64) - np.asarray(lo, np.float64)
    coords, areas = [[], [], []], [[], [], []]
    if len(arrays.tris):
        v = arrays.tris[:, :3, :3].astype(np.float64)
        area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
        for k in range(3):
            flat = np.ptp(v[:, :, k], axis=1) <= 1e-9 * max(float(np.abs(v).max()), 1e-30)
            coords[k].append(v[flat, 0, k])
            areas[k].append(area[flat])
    for pl in arrays.planes:
        nrm = pl[1, :3].astype(np.float64)
        k = int(np.argmax(np.abs(nrm)))
        if abs(abs(nrm[k]) - 1.0) < 1e-6:
            hw, hd = float(pl[2, 3]), float(pl[3, 3])
            finite = math.isfinite(hw) and math.isfinite(hd)
            coords[k].append([float(pl[0, k])])
            areas[k].append([4 * hw * hd if finite else math.prod(np.delete(extent, k))])
    out, near = [], PLANE_MERGE * max(float(extent.max()), 1e-30)
    for k in range(3):
        c, a = np.concatenate([[], *coords[k]]), np.concatenate([[], *areas[k]])
        order = np.argsort(c, kind="stable")
        c, a = c[order], a[order]
        starts = np.flatnonzero(np.diff(c, prepend=-np.inf) > near)
        rows = np.stack([c[starts], np.add.reduceat(a, starts)], 1) if len(c) else np.zeros((0, 2))
        rows = rows[rows[:, 1] > 0]
        side = np.where(rows[:, 0] <= lo[k] + near, 1.0, np.where(rows[:, 0] >= hi[k] - near, -1.0, 0.0))
        rows = np.concatenate([rows, side[:, None]], 1)
        out.append(rows[np.lexsort((rows[:, 0], -rows[:, 1]))][:PHASE_PLANES])
    return out


def tents(q, w, side) -> tuple:
    """Each plane's best layer phase (cells), the share of a cell from it to the plane's own phase
    (the worst: a layer on the plane), and how far the score falls there (0.5 w): a plane inside
    the scene (side 0), seen from both sides, is best read from half a cell off; one on the scene's
    bounds (side +1 at lo, -1 at hi), seen from inside only, from BOUND_OFFSET in."""
    t = (q + np.where(side == 0, 0.5, side * BOUND_OFFSET)) % 1.0
    return t, (q - t) % 1.0, 0.5 * w


def clearance(phase, q, w, side) -> np.ndarray:
    """The planes' least weighted clearance for each layer phase (cells, [0, 1)): a plane at phase
    q counts 0.5 with a layer where it is best read (tents), falling linearly to 0.5 - w/2 with a
    layer on it (w its area over the largest's: the largest falls to 0, a small one barely counts);
    inside the scene that is 0.5 - w (0.5 - d), d the plane's distance to its nearest layer."""
    t, fall, depth = tents(q, w, side)
    x = (np.asarray(phase, np.float64)[..., None] - t) % 1.0
    return (0.5 - np.where(x <= fall, depth / fall * x, depth / (1.0 - fall) * (1.0 - x))).min(-1)


def best_phase(q, w, side) -> tuple:
    """(phase, clearance): the layers' phase that maximises clearance(). Its optimum is a plane's
    best phase or where one plane's falling score meets another's rising one, so each is a
    candidate; ties (to 1e-6 of a cell) take the smaller phase."""
    t, fall, depth = tents(q, w, side)
    gap = (t[None, :] - t[:, None]) % 1.0
    gap = np.where(gap <= 0, 1.0, gap)
    down, up = depth / fall, depth / (1.0 - fall)          # slopes after and before each best phase
    cand = np.concatenate([t, ((t[:, None] + gap * up[None, :] / (down[:, None] + up[None, :])) % 1.0).ravel()])
    score = np.round(clearance(cand, q, w, side), 6)
    best = np.flatnonzero(score == score.max())
    i = best[np.argmin(np.round(cand[best], 6))]
    return float(cand[i]), float(score[i])


def phased_axis(lo: float, hi: float, step: float, planes, finer: bool = True) -> tuple:
    """(spacing, origin, count) along one axis of an automatic grid whose layers stand where the
    axis' planes (axis_planes rows) are best read, as near as they come: the phase of best_phase
    and, where it clears FINER_COST cells more per share finer, a spacing up to PHASE_FINER finer
    (the candidates: those that put two planes' best layers on one lattice). The
    first and last layers at least half a cell beyond lo and hi; the count a Python int."""
    c, w, side = planes[:, 0], planes[:, 1] / planes[:, 1].max(), planes[:, 2]
    steps = {step}
    best_at = np.where(side == 0, 0.5, side * BOUND_OFFSET)    # each plane's best layer, cells from it
    for i in range(min(len(c), PAIR_PLANES) if finer else 0):
        for j in range(i + 1, min(len(c), PAIR_PLANES)):
            # the spacings that put both planes' best layers on the lattice: span = (n + shift) s
            span, shift = c[j] - c[i], best_at[i] - best_at[j]
            span, shift = (span, shift) if span > 0 else (-span, -shift)
            first = math.ceil(span / step - shift - 1e-9)
            steps.update(span / (n + shift) for n in range(first, first + 4)
                         if n + shift > 0 and span / (n + shift) >= step / PHASE_FINER)
    best = None
    for s in sorted(steps, reverse=True):          # ties: the coarsest spacing
        phase, clear = best_phase(((c - lo) / s) % 1.0, w, side)
        gain = round(clear - FINER_COST * (step / s - 1.0), 6)
        if best is None or gain > best[0]:
            best = (gain, s, phase)
    _, s, phase = best
    e = (hi - lo) / s
    tol = min(COUNT_TOLERANCE * max(e, 1.0), 1e-4)
    first = math.floor(-0.5 - phase + tol)          # layers at lo + (phase + k) s
    last = math.ceil(e + 0.5 - phase - tol)
    return s, lo + (phase + first) * s, int(last - first + 1)


PLANE_CLEARANCE = 0.1    # of a cell: along the other axes, no layer of probes nearer a plane than this


def centred_axis(lo: float, hi: float, step: float, coords) -> tuple:
    """(spacing, origin, count) along an axis not phased: centred on the bounds; where a layer
    would stand within PLANE_CLEARANCE of a cell of a plane across it (a wall of no thickness at
    the scene's centre, an odd count: probes on it, moved off it by float32 hits that differ with
    the scene's scale), one probe more, which shifts the layers half a cell, where that clears more."""
    def clear(n):
        pos = (lo + hi) / 2 + (np.arange(n) - (n - 1) / 2) * step
        return float(np.abs(pos[:, None] - coords[None]).min()) / step if len(coords) else 0.5
    n = axis_counts(hi - lo, step, 2)[0]
    if clear(n) < PLANE_CLEARANCE and clear(n + 1) > clear(n):
        n += 1
    return step, (lo + hi) / 2 - (n - 1) * step / 2, n


def phased(lo, hi, step: float, planes: list) -> tuple:
    """(origin, spacing, counts) of an automatic grid of cells about `step` wide whose layers stand
    where the scene's planes across PHASED_AXES are best read (phased_axis), centred along the
    others (centred_axis); the finer spacings dropped where they would pass AUTO_MAX_PROBES."""
    for finer in (True, False):
        axes = []
        for k in range(3):
            if k in PHASED_AXES and len(planes[k]):
                axes.append(phased_axis(float(lo[k]), float(hi[k]), step, planes[k], finer))
            else:
                axes.append(centred_axis(float(lo[k]), float(hi[k]), step, planes[k][:, 0]))
        if math.prod(a[2] for a in axes) <= AUTO_MAX_PROBES:
            break
    spacing, origin, counts = zip(*axes)
    return origin, spacing, counts


def lattice(grid: Grid, arrays) -> dict:
    """What the report says of an automatic grid's lattice: its counts and spacing and, per axis of
    PHASED_AXES, its planes' least score (clearance(): 0.5 at best; None: not phased, no plane)."""
    lo, hi = scene_bounds(arrays)
    out = []
    for k, pl in enumerate(axis_planes(arrays, lo, hi)):
        q = ((pl[:, 0] - grid.origin[k]) / grid.spacing[k]) % 1.0
        score = clearance(0.0, q, pl[:, 1] / pl[:, 1].max(), pl[:, 2]) if len(pl) and k in PHASED_AXES else None
        out.append(None if score is None else round(float(score), 4))
    return {"counts": list(grid.counts), "spacing": [round(s, 6) for s in grid.spacing], "clearance": out}


def box_counts(extent, step) -> list:
    """A min/max box's cells along each axis at `step` (axis_counts): 2 at least where the box has
    an extent, 1 where it has none."""
    return [1 if e <= 0 else (c if c is None else max(c, 2)) for c, e in zip(axis_counts(extent, step, 0), extent)]


def grid_of(settings: dict, arrays, step_hint: float | None = None) -> Grid:
    """The probe grid a scene's `probes` section asks for (docs/scene.md). With min and max: the box
    cut into cells (counts along each axis, or cells about one spacing wide: `spacing`, else
    step_hint, else DEFAULT_LONGEST along its longest axis), a probe at each cell's centre, so that
    none stands on the box's faces (a box drawn on a room's walls left probes on the walls, seeing
    the sky through them). Automatic: cubic cells (N along the longest axis, or
    `spacing`, or step_hint: the scene's interior scale, auto_step) whose probes overhang the
    scene's bounds on every side by at least half a cell, so that every surface has probes on both
    of its sides (RTXGI's volumes enclose the scene), at most AUTO_MAX_PROBES (coarser above); from
    the interior's scale, the layers across y phased where its floors, slabs and ceilings are best
    read, y's cells up to 15% finer, no layer on a wall along x and z (phased: a floor read a layer
    0.83 cell above it, where a window's beam was 8x what it is at the floor)."""
    if (settings["min"] is None) != (settings["max"] is None):
        raise InputError("probes: give both min and max, or neither (auto: the scene's bounds)")
    counts = settings["counts"]
    if settings["min"] is not None:
        lo, hi = np.asarray(settings["min"], np.float64), np.asarray(settings["max"], np.float64)
        if np.any(hi < lo):
            raise InputError(f"probes.max {settings['max']} is below probes.min {settings['min']} on some axis; "
                               "give max >= min")
        extent = hi - lo
        if isinstance(counts, list):
            short = [k for k in range(3) if extent[k] > 0 and counts[k] < 2]
            if short:
                raise InputError(f"probes.counts {counts}: probes.min and probes.max differ along "
                                   f"{'xyz'[short[0]]}, so the box takes 2 cells there; give at least 2 there, or the "
                                   f"same min and max")
            n = [int(c) if extent[k] > 0 else 1 for k, c in enumerate(counts)]
        else:
            if counts is not None and counts < 2 and extent.max() > 0:
                raise InputError(f"probes.counts {counts}: the box takes 2 cells along its longest axis; "
                                   f"give at least 2")
            step = settings["spacing"] or max(float(extent.max()), 1e-6) / (counts or DEFAULT_LONGEST)
            n = box_counts(extent, step)
            if not (settings["spacing"] or counts) and step_hint is not None:
                # the interior's scale, as an automatic grid's (trial76: a box drawn on a room's walls took 8
                # cells along its longest axis, 0.5 where the room asked 0.35: its window wall x1.32), capped
                step = min(step, step_hint)
                while math.prod(n := box_counts(extent, step)) > AUTO_MAX_PROBES:
                    step *= 1.05
        check_count(n, settings)
        cells = np.asarray(n, np.float64)
        spacing = np.where(extent > 0, extent / cells, 1.0)
        origin = lo + np.where(extent > 0, 0.5 * spacing, 0.0)      # cell centres: inset half a cell
        return Grid(tuple(float(x) for x in origin), tuple(float(x) for x in spacing), tuple(n))
    b = scene_bounds(arrays)
    if b is None:
        raise InputError("probes: the scene has no bounded geometry for an automatic grid; "
                           "give probes.min and probes.max")
    lo, hi = b
    extent = hi - lo
    # an automatic grid overhangs the bounds on every side: its probes are N along the longest
    # axis (N - 2 cells over the bounds, half a cell beyond each end), so N >= 3 there, and
    # counts given per axis put probes on both sides of the scene along each (>= 2)
    if isinstance(counts, list):               # each axis its own spacing
        if min(counts) < 2:
            raise InputError(f"probes.counts {counts}: an automatic grid puts probes on both sides of the "
                               f"scene along each axis; give at least 2 per axis, or probes.min and probes.max")
        n = [int(c) for c in counts]
        step = np.where(extent > 0, extent / np.maximum(np.asarray(n) - 2, 0.5), max(float(extent.max()), 1e-6))
    else:
        longest = counts or DEFAULT_LONGEST
        if longest < 3:
            raise InputError(f"probes.counts {longest}: an automatic grid overhangs the scene by half a cell on "
                               f"every side, so it needs at least 3 probes along its longest axis; give 3 or "
                               f"more, or probes.min and probes.max")
        coarse = max(float(extent.max()), 1e-6) / (longest - 2)
        if settings["spacing"]:
            s = float(settings["spacing"])
        elif counts is None and step_hint is not None:
            s = min(coarse, step_hint)
            # the cap: coarser cells (a phased axis may take one probe more)
            while math.prod(axis_counts(extent, s, 3)) > AUTO_MAX_PROBES:
                s *= 1.05
            origin, spacing, n = phased(lo, hi, s, axis_planes(arrays, lo, hi))
            return Grid(tuple(float(x) for x in origin), tuple(float(x) for x in spacing), tuple(n))
        else:
            s = coarse
        step = np.full(3, s)
        n = axis_counts(extent, step, 2)
    check_count(n, settings)
    spacing = step
    origin = (lo + hi) / 2 - (np.asarray(n) - 1) * step / 2         # centred: at least half a cell over each face
    return Grid(tuple(float(x) for x in origin), tuple(float(x) for x in spacing), tuple(int(c) for c in n))
