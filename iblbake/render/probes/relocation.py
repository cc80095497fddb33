"""Where the probes end up and which of them count (render/probes): RTXGI's relocation (a probe
moved out of geometry, or off a surface it nearly touches, within 45% of its cell) and
classification (a probe inside geometry or with no surface in its cells switched off), which
probes are inside geometry (for the bake's warnings), and the probes outside a closed room the
camera is in."""

from __future__ import annotations

import numpy as np

from iblbake.render.probes.grid import Grid
from iblbake.render.paths.tracer import Tracer
from iblbake.render.probes.rays import spherical_fibonacci

ACTIVE, INACTIVE = 0, 1          # RTXGI_DDGI_PROBE_STATE_ACTIVE / _INACTIVE
FIXED_RAYS = 32                  # RTXGI_DDGI_NUM_FIXED_RAYS: the unrotated rays relocation reads
RELOCATION_PASSES = 4            # RTXGI moves probes a step a frame; a bake takes a few steps at once
MAX_OFFSET = 0.45                # of a cell, per axis (RTXGI: the ellipsoid x^2/s^2 + ... < 0.45^2)
TIE = 1e-4                       # distances within this share of each other are equal (float32 hits)


def inside_geometry(t, obj, threshold: float):
    """(whether each probe is inside geometry: its rays meet back faces more often than the
    threshold; the object most of them meet, -1 for a probe that is not)."""
    back = t < 0
    inside = back.mean(1) > threshold
    who = np.full(len(t), -1)
    for p in np.nonzero(inside)[0]:
        ids, counts = np.unique(obj[p][back[p]], return_counts=True)
        who[p] = ids[counts.argmax()]
    return inside, who


ON_SURFACE = 1e-3               # of a cell: a probe nearer a surface than this along an axis stands on it
OFF_SURFACE = 0.25              # of a cell: how far such a probe is moved off it (at most half the free way)
SURFACE_RAYS = 12               # off_surfaces' rays a probe: two from either side along each axis


def off_surfaces(tracer: Tracer, positions, spacing) -> np.ndarray:
    """Offsets that move the probes standing on a surface off it, along the axis it crosses, to its
    freer side: OFF_SURFACE of a cell, at most half the way to the next surface. A probe on a
    surface of no thickness sees through it where its rays leave at a hair's angle, or not, as
    rounding falls (both sides of a wall or a slab, whichever its winding; relocation reads no
    back face there). Found by two rays along each axis from just behind the probe (a surface
    within ON_SURFACE of a cell of it, a plane tilted up to 60 degrees from the axis's normal too)."""
    pos = np.asarray(positions, np.float64)
    offset = np.zeros_like(pos)
    for k in range(3):
        eps = ON_SURFACE * float(spacing[k])
        d = np.eye(3)[k]
        hits, free = [], []
        for sign in (1.0, -1.0):
            _, t, _ = tracer.trace(pos - sign * eps * d, (sign * d)[None], False)
            hits.append(np.abs(t[:, 0]) < 2 * eps)
            _, t, _ = tracer.trace(pos + sign * eps * d, (sign * d)[None], False)
            free.append(np.abs(t[:, 0]))
        on = hits[0] & hits[1] & ~offset.any(1)
        sign = np.where(free[0] >= free[1], 1.0, -1.0)
        step = np.minimum(OFF_SURFACE * float(spacing[k]), 0.5 * np.maximum(free[0], free[1]))
        offset[on, k] = (sign * step)[on]
    return offset


def relocate(tracer: Tracer, grid: Grid, settings: dict, progress=None, start=None, keep=None):
    """Probe offsets (world units) after RELOCATION_PASSES of RTXGI's ProbeRelocationCS on the
    FIXED_RAYS unrotated rays: a probe whose rays meet back faces more often than the threshold is
    inside geometry and moves out past the nearest one; one nearer a front face than
    min_frontface_distance moves towards the farthest front face a ray met (RTXGI counts a miss as
    farthest: a probe beside thin_wall's dim sphere moved towards the opening's sky and lit the
    sphere as the opening does; RTXGI steps one world unit there; here
    min(min_frontface_distance, half that distance)); one far from everything moves back
    towards its grid position. First, a probe standing on a surface is moved off it (off_surfaces,
    or `start`: those offsets, found already). A move that would leave 45% of the cell is not made. Returns the
    offsets and inside_geometry() at the grid positions. keep: the probes relocated (their numbers),
    the others' offsets 0 (and not inside)."""
    every = np.arange(grid.count) if keep is None else np.asarray(keep)
    offset, at_grid = np.zeros((grid.count, 3)), (np.zeros(grid.count, bool), np.full(grid.count, -1))
    if not len(every):
        return offset, at_grid
    moved, at = _relocated(tracer, grid.positions()[every], np.asarray(grid.spacing), grid.unit, settings, progress,
                           None if start is None else np.asarray(start, np.float64)[every])
    offset[every] = moved
    if at is not None:
        at_grid[0][every], at_grid[1][every] = at
    return offset, (at_grid if at is not None else None)


def _relocated(tracer: Tracer, base, spacing, unit: float, settings: dict, progress, start):
    """relocate() of the probes at `base` (offsets, inside_geometry() at base or None)."""
    dirs = spherical_fibonacci(FIXED_RAYS)
    min_front = settings["min_frontface_distance"] * unit
    offset = off_surfaces(tracer, base, spacing) if start is None else np.array(start, np.float64)
    at_grid = None
    for k in range(RELOCATION_PASSES):
        _, t, obj = tracer.trace(base + offset, dirs, False, progress, 0.2 * k / RELOCATION_PASSES,
                                 0.2 / RELOCATION_PASSES)
        if at_grid is None:
            at_grid = inside_geometry(t, obj, settings["backface_threshold"])
        back = t < 0
        n_back = back.sum(1)
        tb = np.where(back, -t, np.inf)
        tf = np.where(back, np.inf, t)
        tfar = np.where(back | ~np.isfinite(t), -1.0, t)
        ib, i_near = tb.argmin(1), tf.argmin(1)
        rows = np.arange(len(t))
        near = tf[rows, i_near]
        # the farthest front face a ray met (not a miss, RTXGI's 1e27: that moved probes towards
        # the sky); among equals (within TIE: float32 hits that tie at one scale differ at another,
        # and the probe moved elsewhere) the one most opposite the nearest face
        farthest = tfar.max(1, keepdims=True)
        opposite = dirs @ dirs.T                                  # (rays, rays): cosines between rays
        i_far = np.where(tfar >= farthest * (1 - TIE), -opposite[i_near], -np.inf).argmax(1)
        far = tfar[rows, i_far]
        full = offset.copy()
        inside = (n_back > 0) & (n_back / FIXED_RAYS > settings["backface_threshold"])
        full[inside] += dirs[ib[inside]] * (tb[rows, ib][inside] + 0.5 * min_front)[:, None]
        # a probe moved back home stops where its nearest face is min_front away: a tie within
        # TIE is neither close nor free (float32 hits broke it one way or the other by scale,
        # and the probe oscillated to a different place)
        close = ~inside & (near < min_front * (1 - TIE)) & ((dirs[i_near] * dirs[i_far]).sum(1) <= 0)
        step = np.minimum(min_front, 0.5 * np.where(np.isfinite(far), far, np.inf))
        full[close] += dirs[i_far[close]] * step[close, None]
        free = ~inside & (near > min_front * (1 + TIE))
        length = np.linalg.norm(offset, axis=1)
        back_by = np.minimum(near - min_front, length)
        with np.errstate(invalid="ignore", divide="ignore"):
            home = np.where(length[:, None] > 0, -offset / np.where(length > 0, length, 1)[:, None], 0.0)
        full[free] += home[free] * back_by[free, None]
        ok = ((full / spacing) ** 2).sum(1) < MAX_OFFSET ** 2
        new = np.where(ok[:, None], full, offset)
        if np.array_equal(new, offset):
            break
        offset = new
    return offset, at_grid


def classify(t, dirs, grid: Grid, settings: dict) -> np.ndarray:
    """Probe states (RTXGI's ProbeClassificationCS on every ray): inactive inside geometry (back
    faces above the threshold) or where no ray meets a front face within the cells around it
    (no surface there samples it)."""
    back = t < 0
    inside = back.mean(1) > settings["backface_threshold"]
    with np.errstate(invalid="ignore"):
        reach = np.abs(dirs[None, :, :] * np.where(back | ~np.isfinite(t), np.inf, t)[..., None])
    near = (reach <= np.asarray(grid.spacing)).all(-1).any(1)
    return np.where(inside | ~near, INACTIVE, ACTIVE)


SEALED_RAYS = 4096              # rays from the camera that must all meet a surface for its room to be sealed
SEALED_POINTS = 256             # of the points they meet, those asked again, each with...
SEALED_POINT_RAYS = 256         # ...this many rays
SEALED_OPEN = 4                 # how many of those points must see the sky for the room to be open (a
                                # crack where planes meet may let a ray from one or two through)


def outside_sealed_room(tracer: Tracer, camera, obj) -> np.ndarray:
    """The probes outside a room that seals the camera in, whatever it is built of (planes of no
    thickness meeting at their edges, overlapping walls, meshes that are not closed): where none of
    SEALED_RAYS rays from the camera escapes to the panorama, and fewer than SEALED_OPEN of
    SEALED_POINTS of the points they meet see it (a window round a corner, which the camera does not
    see: an L-shaped room lit at the end of its other leg had every probe near the window off, the
    frame on the panorama's SH, 4-6x too bright), no light from outside reaches what it sees, and a
    probe any of whose rays (obj: the object each met, -1 none) escapes is outside (a new user's
    trial: six planes around a point light, the sky outside leaking onto the back wall at +24% of
    the reference, bright seams at the edges)."""
    escaped = (np.asarray(obj) < 0).any(1)
    if not escaped.any():                 # no probe sees the sky: nothing to ask the camera
        return escaped
    cam = np.asarray(camera, np.float64)
    dirs = spherical_fibonacci(SEALED_RAYS)
    _, t, seen = tracer.trace(cam[None], dirs, False)
    if not (seen >= 0).all():
        return np.zeros(len(obj), bool)
    step = SEALED_RAYS // SEALED_POINTS
    points = cam + dirs[::step] * (0.999 * np.abs(t[0, ::step]))[:, None]     # just before what they met
    _, _, again = tracer.trace(points, spherical_fibonacci(SEALED_POINT_RAYS), False)
    return escaped if (again < 0).any(1).sum() < SEALED_OPEN else np.zeros(len(obj), bool)


def beyond_bounds(positions, bounds, camera) -> np.ndarray:
    """The probes beyond the scene's bounds (grid.scene_bounds) where the camera is within them: what
    the camera sees faces inwards there, so they light nothing it sees, but beside a wall on the
    bounds, a surface of no thickness, they see the sky through it and leak it in at the edges where
    walls meet (the moments cannot tell a point a hair inside the wall from the wall). A new
    user's corridor, open at one end: its closed far end 11-15x too bright, bright seams along every
    edge. None where the camera is outside the bounds (what it sees may face outwards there; a
    camera merely within the bounds along one axis still sees, say, a sphere's underside, which
    the probes below it light)."""
    pos = np.asarray(positions, np.float64)
    if bounds is None:
        return np.zeros(len(pos), bool)
    lo, hi = (np.asarray(b, np.float64) for b in bounds)
    tol = 1e-6 * max(float((hi - lo).max()), 1e-9)
    cam = np.asarray(camera, np.float64)
    if np.any(cam < lo - tol) or np.any(cam > hi + tol):
        return np.zeros(len(pos), bool)
    return ((pos < lo - tol) | (pos > hi + tol)).any(1)


def outside_camera_rooms(positions, arrays, camera) -> np.ndarray:
    """The probes outside a closed part that encloses the camera (a room or a dome seen from
    within, docs/conventions.md "Sides"): no light they see reaches what the camera sees, and at
    the room's walls, surfaces of no thickness, they would leak the outside in (a new user's trial:
    a closed room lit at its edges, mean 0.035 where the reference is black, 0.44 with 3 probes)."""
    from iblbake.scene import geometry

    pos = np.asarray(positions, np.float64)
    out = np.zeros(len(pos), bool)
    cam = np.asarray(camera, np.float64)
    for s in arrays.spheres:
        c, r = s[0, :3].astype(np.float64), float(s[0, 3])
        if np.linalg.norm(cam - c) < r:
            out |= np.linalg.norm(pos - c, axis=1) >= r
    if arrays.tri_closed is not None and len(arrays.tris):
        v = arrays.tris[:, :3, :3].astype(np.float64)
        comp, sign = arrays.tri_closed[:, 0], arrays.tri_closed[:, 1]
        rooms = geometry.inside_closed(cam, v[:, 0], v[:, 1], v[:, 2], comp, sign)
        for c in rooms:
            sel = comp == c
            args = (v[sel, 0], v[sel, 1], v[sel, 2], comp[sel], sign[sel])
            out |= np.array([c not in geometry.inside_closed(q, *args) for q in pos])
    return out



CAMERA_RAYS = 1 << 14           # rays from the camera whose hits are the points it may see
SEEN_POINTS = 2                 # a probe is judged by the camera's points in its cells only where it has this many
SEEN_REACH = 2                  # cells: where a probe has fewer, it is judged by those within this many cells
SEGMENTS = 256                  # of those points, at most this many segments a probe
POINT_BACK = 0.01               # of the camera's distance: how far before its hit a point stands, so that it
                                # is off the surface by that share of the camera's own distance from the
                                # surface's plane at any angle (a new user's attic, the camera 0.07 below a
                                # roof it met at 1-5 degrees: a hair of 1e-3 cells along the ray left the
                                # points 1e-5 off it, and the segments of 24 probes above it passed)


def seen_points(tracer: Tracer, camera, spacing) -> np.ndarray:
    """The points the camera may see: the hits of CAMERA_RAYS rays from it, each POINT_BACK of its
    distance before the hit (at least 1e-3 of a cell), on the camera's side of the surface."""
    cam = np.asarray(camera, np.float64)
    dirs = spherical_fibonacci(CAMERA_RAYS)
    _, t, _ = tracer.trace(cam[None], dirs, False)
    t = np.abs(t[0])
    hit = np.isfinite(t)
    back = np.maximum(POINT_BACK * t[hit], 1e-3 * float(np.min(spacing)))
    return cam + dirs[hit] * (t[hit] - back)[:, None]


def _blocked(tracer: Tracer, p, points) -> bool:
    """Whether every segment from p to the points (at most SEGMENTS of them) meets a surface first."""
    near = points[::-(-len(points) // SEGMENTS) or 1]
    seg = near - p
    length = np.linalg.norm(seg, axis=1)
    _, t, _ = tracer.trace(p[None], seg / length[:, None], False)
    return bool((np.abs(t[0]) < length * (1 - 1e-4)).all())


def behind_surfaces(tracer: Tracer, positions, spacing, camera):
    """(the probes behind a surface, the probes outside the room the camera sees): on the far side
    of a surface from every point the camera sees (seen_points) within their cells (a box a cell
    each way: a segment from the probe to each such point meets a surface first), and, for those
    with fewer than SEEN_POINTS points there, from every point within SEEN_REACH cells. Such a probe
    lights nothing the camera sees but through that surface: a probe under a floor of no thickness
    (the sky below it) leaked into a sphere resting on the floor, the sphere's underside 2x too
    bright (thin_wall's dim sphere, x1.85 in all); probes in the sun above an attic's roof, which
    the camera sees at a grazing angle (a point or none in their cells), lit the top of a gable
    along the roof's edge up to 12x. A segment test, so it holds for quads of no thickness of either
    winding as for solids. A probe with fewer than SEEN_POINTS points within SEEN_REACH cells is kept."""
    pos = np.asarray(positions, np.float64)
    s = np.asarray(spacing, np.float64)
    pts = seen_points(tracer, camera, s)
    behind, apart = np.zeros(len(pos), bool), np.zeros(len(pos), bool)
    for i, p in enumerate(pos):          # one launch a probe: its segments to the points in its cells
        gap = np.abs(pts - p)
        near = pts[(gap < s).all(1)]
        if len(near) >= SEEN_POINTS:
            behind[i] = _blocked(tracer, p, near)
            continue
        near = pts[(gap < SEEN_REACH * s).all(1)]
        apart[i] = len(near) >= SEEN_POINTS and _blocked(tracer, p, near)
    return behind, apart
