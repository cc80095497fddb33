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
        return int(np.prod(self.counts))

    @property
    def unit(self) -> float:
        """The smallest spacing: the unit of the biases and distances given in spacing units."""
        return float(min(self.spacing))

    def positions(self) -> np.ndarray:
        """Every probe's grid position, by probe index (RTXGI's order)."""
        return np.asarray(self.origin) + twin.probe_coords(np.arange(self.count), self.counts) * np.asarray(self.spacing)


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


def grid_of(settings: dict, arrays) -> Grid:
    """The probe grid a scene's `probes` section asks for (docs/scene.md): probes at min and at max
    (counts along each axis, or one spacing apart), or automatically cubic cells (N along the
    longest axis, or `spacing`) whose probes overhang the scene's bounds on every side by at least
    half a cell, so that every surface has probes on both of its sides: the outer probes of a
    wall or floor on the bounds see its outer face (RTXGI's volumes enclose the scene)."""
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
            n = np.asarray(counts, int)
            short = [k for k in range(3) if extent[k] > 0 and n[k] < 2]
            if short:
                raise InputError(f"probes.counts {counts}: probes.min and probes.max differ along "
                                   f"{'xyz'[short[0]]}, so a probe at each takes 2; give at least 2 there, or the "
                                   f"same min and max")
        else:
            if counts is not None and counts < 2 and extent.max() > 0:
                raise InputError(f"probes.counts {counts}: probes at min and at max take 2 along the longest axis; "
                                   f"give at least 2")
            step = settings["spacing"] or max(float(extent.max()), 1e-6) / max((counts or DEFAULT_LONGEST) - 1, 1)
            n = np.round(extent / step).astype(int) + 1
        n = np.where(extent > 0, np.maximum(n, 2), 1)
        spacing = np.where(n > 1, extent / np.maximum(n - 1, 1), 1.0)
        origin = lo
    else:
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
            n = np.asarray(counts, int)
            step = np.where(extent > 0, extent / np.maximum(n - 2, 0.5), max(float(extent.max()), 1e-6))
        else:
            longest = counts or DEFAULT_LONGEST
            if longest < 3:
                raise InputError(f"probes.counts {longest}: an automatic grid overhangs the scene by half a cell on "
                                   f"every side, so it needs at least 3 probes along its longest axis; give 3 or "
                                   f"more, or probes.min and probes.max")
            step = np.full(3, settings["spacing"] or max(float(extent.max()), 1e-6) / (longest - 2))
            n = np.ceil(extent / step - 1e-9).astype(int) + 2
        spacing = step
        origin = (lo + hi) / 2 - (n - 1) * step / 2         # centred: at least half a cell over each face
    if n.prod() > 1 << 20:
        raise InputError(f"probes: {int(n.prod())} probes ({' x '.join(map(str, n))}); "
                           "give fewer counts or a larger spacing (at most 1048576)")
    return Grid(tuple(float(x) for x in origin), tuple(float(x) for x in spacing), tuple(int(c) for c in n))
