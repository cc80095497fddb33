"""The irradiance probe volume (DDGI: Majercik et al. 2019, JCGT 8(2); 2021, JCGT 10(2); NVIDIA's
RTXGI-DDGI 1.x): where the probes stand, what their rays bring back (the reference's paths,
kernels/probe_trace.cl), RTXGI's relocation and classification, the rays' projection into RTXGI's
atlases (octahedral irradiance or L2 SH, and the distance moments), and the files a bake is:
written, read back and validated here. The volume is baked once, offline, to its mean over every
ray (no hysteresis: nothing is temporal here). Sampling: kernels/probes.h, twin/probes.py.
Conventions: docs/conventions.md "Irradiance probes"."""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from iblbake.core import bases, sh
from iblbake.errors import IblbakeError, InputError
from iblbake.render.twin import probes as twin

FORMAT = "iblbake-probes"
VERSION = 1
ACTIVE, INACTIVE = 0, 1          # RTXGI_DDGI_PROBE_STATE_ACTIVE / _INACTIVE
FIXED_RAYS = 32                  # RTXGI_DDGI_NUM_FIXED_RAYS: the unrotated rays relocation reads
RELOCATION_PASSES = 4            # RTXGI moves probes a step a frame; a bake takes a few steps at once
MAX_OFFSET = 0.45                # of a cell, per axis (RTXGI: the ellipsoid x^2/s^2 + ... < 0.45^2)
BACKFACE_BLEND_LIMIT = 0.1       # a probe with this share of back-face rays blends no irradiance
MAX_DISTANCE = 1.5               # probeMaxRayDistance: 1.5 |spacing|, what a miss counts as
DEFAULT_LONGEST = 8              # probes along the longest axis where counts and spacing are omitted
# a directional basis (core/bases PROBES) stores each probe's radiance coefficients in its layout
FILES = {"octahedral": "irradiance.exr", "sh": "irradiance_sh.exr", **{n: f"basis_{n}.exr" for n in bases.PROBES}}


def basis_options(settings: dict) -> dict:
    """The options of the probes' basis: the probes section's keys of the same names as the
    basis's effects keys (probes.sg_lobes, probes.sg_fit), so a probe basis is set apart from the
    distant one."""
    return {k: settings[k] for k in bases.BASES[settings["irradiance"]].OPTIONS}


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


def spherical_fibonacci(n: int) -> np.ndarray:
    """n near-uniform directions (RTXGI's SphericalFibonacci: golden-ratio turns, equal-area rings)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = 2 * np.pi * np.mod(i * (np.sqrt(5) - 1) / 2, 1.0)
    r = np.sqrt(np.maximum(0, 1 - z * z))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


def random_rotation(seed: int) -> np.ndarray:
    """A uniformly random rotation (Arvo 1992, Graphics Gems III: RTXGI's ComputeRandomRotation)."""
    u1, u2, u3 = np.random.default_rng(seed).random(3)
    a, b = 2 * np.pi * u1, 2 * np.pi * u2
    rz = np.array([[np.cos(a), np.sin(a), 0], [-np.sin(a), np.cos(a), 0], [0, 0, 1]])
    v = np.array([np.cos(b) * np.sqrt(u3), np.sin(b) * np.sqrt(u3), np.sqrt(1 - u3)])
    return -(np.eye(3) - 2 * np.outer(v, v)) @ rz


def ray_directions(n: int, seed: int) -> np.ndarray:
    return spherical_fibonacci(n) @ random_rotation(seed).T


# ---------------------------------------------------------------------------------- tracing

def trace_defines(scene, bounces) -> dict:
    from iblbake.render.passes.base import geometry_defines
    from iblbake.render.passes.lights import Lights
    from iblbake.render.plan import effect_modes

    d = {**geometry_defines(scene), "BOUNCES": 0 if bounces == "unbounded" else bounces + 1}
    if Lights().runs(scene, effect_modes(scene)):
        d["PATH_LIGHTS"] = 1              # the lights light what the probes see (not the probes)
    return d


class Tracer:
    """Probe rays on the frame context's device, with its scene tables and panorama."""

    def __init__(self, ctx, settings: dict, back_faces_black: bool = True, skip_objects=()):
        from iblbake.render.passes.lights import frame_lights
        from iblbake.render.passes.reference import environment_args
        from iblbake.scene import pack

        rt = self.rt = ctx.rt
        self.ctx, self.settings, self.back_faces_black = ctx, settings, back_faces_black
        dist = ctx.bakes.load("env_cdf", ctx)[0]
        chain = ctx.bakes.load("radiance", ctx)[0]     # what an escaping probe ray reads (probe_trace.cl)
        self.defines = trace_defines(ctx.scene, settings["bounces"])
        recs = np.zeros((0, 4), np.float32)
        if "PATH_LIGHTS" in self.defines:
            recs = pack.light_records(frame_lights(ctx.scene, ctx.bakes.sun(ctx.scene.data["environment"])))
        skip = np.zeros(max(len(ctx.scene.data["objects"]), 1), np.int32)
        skip[list(skip_objects)] = 1
        self.args = {**environment_args(ctx, dist), "nlights": len(recs), **ctx.chain(chain),
                     "lights": rt.to_device(recs.reshape(-1, 4) if len(recs) else np.zeros((4, 4), np.float32)),
                     "skip_obj": rt.to_device(skip), "skip": int(bool(len(skip_objects)))}
        self.rays_traced = 0

    def trace(self, positions, dirs, shade: bool, progress=None, done=0.0, share=1.0, probe0=0, ray0=0):
        """(radiance (probes, rays, 3), signed distance (probes, rays), the object each ray met
        (probes, rays), -1 none) from every position; dirs (rays, 3), or (rays, 4) with each ray's
        share of the sphere in w (probe_trace.cl). probe0, ray0: the first probe's and ray's
        numbers (their random streams)."""
        rt, n, nrays = self.rt, len(positions), len(dirs)
        pos = rt.to_device(np.pad(np.asarray(positions, np.float32), ((probe0, 0), (0, 1))))
        dirs = np.asarray(dirs, np.float32)
        dir_buf = rt.to_device(dirs if dirs.shape[1] == 4 else np.pad(dirs, ((0, 0), (0, 1))))
        per_launch = max(1, (1 << (20 if rt.info.kind == "GPU" else 16)) // nrays)
        out = np.empty((n, nrays, 4), np.float32)
        obj = np.empty((n, nrays), np.int32)
        buf = rt.empty(16 * min(n, per_launch) * nrays)
        obj_buf = rt.empty(4 * min(n, per_launch) * nrays)
        for first in range(0, n, per_launch):
            count = min(per_launch, n - first)
            rt.launch("probe_trace.cl", "probe_trace", self.defines, (count * nrays,), self.ctx.table, **self.args,
                      probe_pos=pos, ray_dirs=dir_buf, nrays=nrays, first=probe0 + first, count=count, ray0=ray0,
                      ray_solid_angle=4 * np.pi / nrays,
                      seed=self.settings["seed"], shade=int(shade), back_faces_black=int(self.back_faces_black),
                      ray_out=buf, ray_obj=obj_buf)
            out[first:first + count] = rt.read(buf, (count * nrays, 4)).reshape(count, nrays, 4)
            obj[first:first + count] = rt.read(obj_buf, (count * nrays,), np.int32).reshape(count, nrays)
            if progress:
                progress(done + share * (first + count) / n)
        self.rays_traced += n * nrays
        return out[..., :3].astype(np.float64), out[..., 3].astype(np.float64), obj


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


def relocate(tracer: Tracer, grid: Grid, settings: dict, progress=None):
    """Probe offsets (world units) after RELOCATION_PASSES of RTXGI's ProbeRelocationCS on the
    FIXED_RAYS unrotated rays: a probe whose rays meet back faces more often than the threshold is
    inside geometry and moves out past the nearest one; one nearer a front face than
    min_frontface_distance moves towards the farthest (RTXGI steps one world unit there; here
    min(min_frontface_distance, half that distance)); one far from everything moves back
    towards its grid position. A move that would leave 45% of the cell is not made. Returns the
    offsets and inside_geometry() at the grid positions."""
    dirs = spherical_fibonacci(FIXED_RAYS)
    base = grid.positions()
    spacing = np.asarray(grid.spacing)
    min_front = settings["min_frontface_distance"] * grid.unit
    offset = np.zeros_like(base)
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
        tfar = np.where(back, -1.0, t)
        ib, i_near = tb.argmin(1), tf.argmin(1)
        rows = np.arange(len(t))
        near = tf[rows, i_near]
        # the farthest front face (a miss counts as farthest, as RTXGI's 1e27); among equals (every
        # miss) the one most opposite the nearest face
        farthest = tfar.max(1, keepdims=True)
        opposite = dirs @ dirs.T                                  # (rays, rays): cosines between rays
        i_far = np.where(tfar >= farthest, -opposite[i_near], -np.inf).argmax(1)
        far = tfar[rows, i_far]
        full = offset.copy()
        inside = (n_back > 0) & (n_back / FIXED_RAYS > settings["backface_threshold"])
        full[inside] += dirs[ib[inside]] * (tb[rows, ib][inside] + 0.5 * min_front)[:, None]
        close = ~inside & (near < min_front) & ((dirs[i_near] * dirs[i_far]).sum(1) <= 0)
        step = np.minimum(min_front, 0.5 * np.where(np.isfinite(far), far, np.inf))
        full[close] += dirs[i_far[close]] * step[close, None]
        free = ~inside & (near > min_front)
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


# ---------------------------------------------------------------------------------- projection

def with_borders(tiles: np.ndarray) -> np.ndarray:
    """Tiles (probes, n, n, c) with RTXGI's 1-texel octahedral border (ProbeBorderUpdateCS): each
    edge row and column the neighbouring interior one reversed, each corner the opposite interior
    corner, so that bilinear reads wrap across the octahedron's folds."""
    p, n = tiles.shape[:2]
    out = np.zeros((p, n + 2, n + 2, tiles.shape[3]), tiles.dtype)
    out[:, 1:-1, 1:-1] = tiles
    out[:, 0, 1:-1] = tiles[:, 0, ::-1]
    out[:, -1, 1:-1] = tiles[:, -1, ::-1]
    out[:, 1:-1, 0] = tiles[:, ::-1, 0]
    out[:, 1:-1, -1] = tiles[:, ::-1, -1]
    out[:, 0, 0], out[:, 0, -1] = tiles[:, -1, -1], tiles[:, -1, 0]
    out[:, -1, 0], out[:, -1, -1] = tiles[:, 0, -1], tiles[:, 0, 0]
    return out


def atlas(tiles: np.ndarray, counts) -> np.ndarray:
    """Bordered tiles (probes, t, t, c) laid out as RTXGI's atlas (DDGIGetProbeUV, y up)."""
    nx, ny, nz = counts
    t, c = tiles.shape[1], tiles.shape[3]
    # probe index gy nx nz + gz nx + gx: tiles as (gy, gz, gx); atlas rows gz, columns gy nx + gx
    return np.ascontiguousarray(tiles.reshape(ny, nz, nx, t, t, c).transpose(1, 3, 0, 2, 4, 5)
                                .reshape(nz * t, ny * nx * t, c))


def project(radiance, t, dirs, grid: Grid, settings: dict):
    """(irradiance, distance atlas) of every probe from its rays (DDGIProbeBlendingCS, to the mean
    over all rays). Irradiance at a texel's direction: pi times the cosine-weighted mean radiance
    of the rays that met no back face (RTXGI stores that over 2 pi and multiplies it back when
    sampling); a probe with BACKFACE_BLEND_LIMIT of back faces blends none. SH: the least-squares
    L2 fit of those rays' radiance (a field in the span, a uniform sky, is exact), convolved with
    the clamped cosine. Distance moments: weights cos^distance_exponent, the mean of min(|t|,
    1.5 |spacing|) and of its square over every ray (RTXGI halves both; the moments here are the
    means the Chebyshev test reads). A directional basis (core/bases PROBES): its own project_rays
    on the same rays, back-face rays black: (probes, floats, 3) radiance coefficients."""
    p, r = t.shape
    front = (t >= 0).astype(np.float64)
    blends = (1 - front).mean(1) < BACKFACE_BLEND_LIMIT
    lit = radiance * front[..., None]
    lit_rows = lit.transpose(0, 2, 1).reshape(p * 3, r)            # one GEMM for every probe and colour
    if settings["irradiance"] == "sh":
        y = sh.sh_basis(dirs, 3)                                    # (rays, 9)
        a = np.einsum("pr,rk,rj->pkj", front, y, y, optimize=True)
        b = (lit_rows @ y).reshape(p, 3, 9).transpose(0, 2, 1)
        a[~blends] = np.eye(9)
        coeffs = np.linalg.solve(a, b) * sh.ahat(3)[None, :, None]
        irr = np.where(blends[:, None, None], coeffs, 0.0)
    elif settings["irradiance"] in bases.PROBES:
        # the basis's own fit on the rays (an equal-area set: moments 4 pi / N sum L B), back faces black
        coeffs = bases.BASES[settings["irradiance"]].project_rays(lit, dirs, basis_options(settings))
        irr = np.where(blends[:, None, None], coeffs, 0.0)
    else:
        n = settings["irradiance_texels"]
        w = np.maximum(0.0, twin.texel_directions(n) @ dirs.T)      # (texels, rays)
        num = (lit_rows @ w.T).reshape(p, 3, n * n).transpose(0, 2, 1)
        den = front @ w.T
        with np.errstate(invalid="ignore", divide="ignore"):
            e = np.where(den[..., None] > 0, np.pi * num / np.where(den > 0, den, 1)[..., None], 0.0)
        e[~blends] = 0.0
        # irradiance is >= 0: the panorama's tiny negative texels (environment.negative: keep) reach a
        # few rays, and read back a negative texel would fail the volume's check
        irr = atlas(with_borders(np.maximum(e, 0.0).reshape(p, n, n, 3)), grid.counts)
    nd = settings["distance_texels"]
    wd = np.maximum(0.0, twin.texel_directions(nd) @ dirs.T) ** settings["distance_exponent"]
    d = np.minimum(np.abs(t), MAX_DISTANCE * float(np.linalg.norm(grid.spacing)))
    wsum = wd.sum(1)
    moments = np.stack([d @ wd.T, (d * d) @ wd.T], -1) / np.where(wsum > 0, wsum, 1)[None, :, None]
    dist = atlas(with_borders(moments.reshape(p, nd, nd, 2)), grid.counts)
    return irr, dist


# ---------------------------------------------------------------------------------- the bake

def bake(ctx, settings: dict, progress=None) -> dict:
    """The volume of ctx's scene (a render Context with its scene tables uploaded): a dict of the
    arrays (as load() returns) and a report."""
    t0 = time.perf_counter()
    arrays = ctx.arrays if ctx.arrays is not None else ctx.bakes.geometry(ctx.scene)
    try:
        grid = grid_of(settings, arrays)
    except IblbakeError as e:             # said as the scene's other errors are: naming its file
        raise type(e)(f"{ctx.scene.source}: {e}") from None
    tracer = Tracer(ctx, settings)
    if settings["relocation"]:
        offset, at_grid = relocate(tracer, grid, settings, progress)
    else:
        offset, at_grid = np.zeros((grid.count, 3)), None
    dirs = ray_directions(settings["rays"], settings["seed"])
    base = 0.2 if settings["relocation"] else 0.0
    radiance, t, obj = tracer.trace(grid.positions() + offset, dirs, True, progress, base, 1.0 - base)
    states = classify(t, dirs, grid, settings) if settings["classification"] else np.zeros(grid.count, int)
    from iblbake.scene import pack
    outside = outside_camera_rooms(grid.positions() + offset, arrays, pack.camera_vectors(ctx.scene.data["camera"])[0])
    states = np.where(outside, INACTIVE, states)
    irr, dist = project(radiance, t, dirs, grid, settings)
    data = np.concatenate([offset, states[:, None].astype(np.float64)], 1)
    inside, who = inside_geometry(t, obj, settings["backface_threshold"])
    if at_grid is not None:                       # inside at their grid positions: moved out, or not
        who = np.where(at_grid[0], at_grid[1], who)
        inside = inside | at_grid[0]
    objects = {}
    for o in who[inside]:
        objects[int(o)] = objects.get(int(o), 0) + 1
    report = {"probes": grid.count, "rays_per_probe": settings["rays"], "rays_traced": tracer.rays_traced,
              "inactive": int((states == INACTIVE).sum()), "relocated": int((np.abs(offset).sum(1) > 0).sum()),
              "inside_geometry": int(inside.sum()), "outside_camera_room": int(outside.sum()),
              "inside_objects": {str(k): v for k, v in sorted(objects.items(), key=lambda kv: -kv[1])},
              "seconds": round(time.perf_counter() - t0, 4)}
    return volume_dict(grid, settings, irr, dist, data, report)


INSIDE_WARN = 0.25      # the share of probes inside geometry (at their grid positions or after) that is said


MAX_ATLAS_SIDE = 16384       # texels: the largest 2D texture most GPUs take (Vulkan's and D3D12's limit)


def warnings(report: dict, scene_data: dict, volume: dict | None = None) -> list:
    """What a bake's report says a user should know: more than INSIDE_WARN of the probes were inside
    geometry (relocated out of it, or switched off), with the objects whose back faces they saw; an
    atlas wider or taller than MAX_ATLAS_SIDE (an engine cannot load it as one texture)."""
    from iblbake.scene.load import object_label

    out = []
    if volume is not None:
        nx, ny, nz = volume["counts"]
        for what, texels in (("irradiance", volume["irradiance_texels"]), ("distance", volume["distance_texels"])):
            if what == "irradiance" and volume["representation"] != "octahedral":
                continue
            w, h = (texels + 2) * nx * ny, (texels + 2) * nz
            if max(w, h) > MAX_ATLAS_SIDE:
                out.append(f"probes: the {what} atlas is {w} x {h} texels, over the {MAX_ATLAS_SIDE} most GPUs take "
                           f"in one texture; give fewer probes (probes.counts, probes.spacing) or texels")
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


SAMPLING_KEYS = ("visibility", "normal_bias", "view_bias")   # read when shading, not baked


def bake_settings(settings: dict) -> dict:
    """What of a scene's `probes` section the bake depends on (the sampling keys are not)."""
    return {k: v for k, v in settings.items() if k not in SAMPLING_KEYS}


def volume_dict(grid: Grid, settings: dict, irr, dist, data, report: dict) -> dict:
    """A baked volume: its grid, bake settings, arrays (irradiance: the octahedral atlas or (probes,
    9, 3) SH coefficients; distance: the moments' atlas; data: (probes, 4) offset in world units and
    state) and report."""
    return {"grid": grid, "counts": grid.counts, "origin": grid.origin, "spacing": grid.spacing,
            "representation": settings["irradiance"], "irradiance_texels": settings["irradiance_texels"],
            "distance_texels": settings["distance_texels"], "classification": settings["classification"],
            "settings": bake_settings(settings), "irradiance": irr, "distance": dist, "data": data, "report": report}


def sampled(volume: dict, settings: dict) -> dict:
    """The volume with a scene's sampling settings (visibility, biases in world units): what
    twin.irradiance and the shade pass read."""
    u = volume["grid"].unit
    return {**volume, "visibility": settings["visibility"], "normal_bias": settings["normal_bias"] * u,
            "view_bias": settings["view_bias"] * u}


# ---------------------------------------------------------------------------------- files

def manifest(volume: dict) -> dict:
    """The manifest of a sampled volume's files: the grid, the representation, how to sample it
    and every convention the files are read with, each probe's state."""
    g, s = volume["grid"], volume["settings"]
    states = volume["data"][:, 3].astype(int)
    return {
        "format": FORMAT, "version": VERSION,
        "grid": {"origin": list(g.origin), "spacing": list(g.spacing), "counts": list(g.counts),
                 "probe_position": "origin + (gx, gy, gz) * spacing + offset"},
        "representation": volume["representation"],
        "files": {"irradiance": FILES[volume["representation"]], "distance": "distance.exr",
                  "probe_data": "probe_data.exr"},
        "irradiance_texels": volume["irradiance_texels"], "distance_texels": volume["distance_texels"],
        "normal_bias": volume["normal_bias"], "view_bias": volume["view_bias"],
        "visibility": volume["visibility"], "classification": volume["classification"],
        "settings": {k: v for k, v in s.items()},
        "states": {"active": int((states == ACTIVE).sum()), "inactive": int((states == INACTIVE).sum())},
        "conventions": {
            "units": "irradiance E (W m^-2 for radiance in W m^-2 sr^-1), linear, float32; diffuse = albedo / pi * E",
            "probe_index": "gy * nx * nz + gz * nx + gx (RTXGI, right-handed, y up)",
            "atlas": "probe tile (n + 2) texels square, 1-texel octahedral border; tile column gx + gy * nx, "
                     "row gz; the file's first row at the top (v = 0)",
            "octahedral": "RTXGI DDGIGetOctahedralCoordinates on world directions: +z at the tile centre",
            "sh": "irradiance_sh.exr: row = probe index, column k = l (l + 1) + m, real orthonormal SH, z polar "
                  "axis, no Condon-Shortley phase, world frame",
            "distance": "R: mean of min(|t|, 1.5 |spacing|), G: mean of its square, weights cos^distance_exponent",
            "probe_data": "RGBA, texel (index % (nx * ny), index / (nx * ny)): offset in units of spacing, "
                          "A = state (0 active, 1 inactive), as RTXGI's probe data texture",
        },
        "report": volume["report"],
        **({"basis": basis_manifest(volume)} if volume["representation"] in bases.PROBES else {}),
    }


def basis_manifest(volume: dict) -> dict:
    """What a basis's file holds: the basis, its options and its layout (the basis module's)."""
    rep = volume["representation"]
    m = bases.BASES[rep]
    return {"name": rep, "title": m.TITLE, "options": basis_options(volume["settings"]), "floats": m.floats(
            basis_options(volume["settings"])),
            "layout": f"{FILES[rep]}: row = probe index, column k = coefficient k of the basis (RGB radiance "
                      f"coefficients, world frame; back-face rays black): " + m.__doc__.split("Layout:")[1].strip(),
            "irradiance": "docs/conventions.md 'Directional bases'; probes.glsl's probeOwnIrradiance evaluates it"}


def data_texture(data: np.ndarray, grid: Grid) -> np.ndarray:
    nx, ny, nz = grid.counts
    out = np.zeros((nz, nx * ny, 4), np.float32)
    i = np.arange(grid.count)
    out[i // (nx * ny), i % (nx * ny), :3] = data[:, :3] / np.asarray(grid.spacing)
    out[i // (nx * ny), i % (nx * ny), 3] = data[:, 3]
    return out


def save(volume: dict, folder: Path) -> list:
    """The volume's images into folder (atomically, each); the names written."""
    from iblbake.io import images

    folder = Path(folder)
    names = []
    irr = volume["irradiance"]
    name = FILES[volume["representation"]]
    images.write_exr(folder / name, np.asarray(irr, np.float32))
    names.append(name)
    images.write_exr(folder / "distance.exr", np.asarray(volume["distance"], np.float32), channels=("R", "G"))
    images.write_exr(folder / "probe_data.exr", data_texture(volume["data"], volume["grid"]),
                     channels=("R", "G", "B", "A"))
    return names + ["distance.exr", "probe_data.exr"]


def _bad(path, what: str):
    return IblbakeError(f"{path}: {what}; bake the probes again (iblbake probes, or delete the cache entry)")


def load(folder: Path, man: dict, manifest_name: str = "probes.json") -> dict:
    """A volume from its folder and manifest (manifest_name: how the folder calls it), every
    value checked: the manifest's types and ranges, the images' shapes against it, finite and
    non-negative values, states 0 or 1, offsets within 45% of a cell."""
    from iblbake.io import images

    folder = Path(folder)
    where = folder / manifest_name
    if not isinstance(man, dict) or man.get("format") != FORMAT or man.get("version") != VERSION:
        raise _bad(where, f"not an {FORMAT} v{VERSION} manifest")
    try:
        g = man["grid"]
        vecs = [g["origin"], g["spacing"], g["counts"]]
        if not all(isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                                for x in v) for v in vecs):
            raise ValueError("grid: origin, spacing and counts must be 3 numbers each")
        grid = Grid(tuple(float(x) for x in vecs[0]), tuple(float(x) for x in vecs[1]), tuple(int(x) for x in vecs[2]))
        rep, n, nd = man["representation"], man["irradiance_texels"], man["distance_texels"]
        settings = man["settings"]
        if not (isinstance(rep, str) and rep in FILES and all(isinstance(x, int) and not isinstance(x, bool)
                                                               for x in (n, nd))
                and isinstance(settings, dict) and isinstance(settings.get("classification"), bool)):
            raise ValueError("representation, texels or settings")
        if rep in bases.PROBES:
            for k, (choices, _default, _doc) in bases.BASES[rep].OPTIONS.items():
                if settings.get(k) not in choices:
                    raise ValueError(f"settings.{k}")
    except (KeyError, TypeError, ValueError) as e:
        raise _bad(where, f"manifest lacks or mangles {e}") from None
    if min(grid.counts) < 1 or grid.count > 1 << 20 or min(grid.spacing) <= 0 \
            or not all(math.isfinite(x) for x in grid.origin + grid.spacing) or not (2 <= n <= 64 and 2 <= nd <= 64):
        raise _bad(where, "its grid or texel counts are out of range")
    nx, ny, nz = grid.counts

    def read(name, shape):
        path = folder / name
        try:
            a = images.read_exr(path).astype(np.float64)
        except (OSError, IblbakeError, RuntimeError, ValueError) as e:
            raise _bad(path, f"cannot be read ({e})") from None
        if a.shape[:2] != shape[:2] or a.shape[2] < shape[2]:
            raise _bad(path, f"holds {a.shape[1]}x{a.shape[0]}x{a.shape[2]}, the manifest says "
                             f"{shape[1]}x{shape[0]}x{shape[2]}")
        a = a[..., :shape[2]]
        if not np.isfinite(a).all():
            raise _bad(path, "holds a value that is not finite")
        return a

    if rep == "sh":
        irr = read(FILES[rep], (grid.count, 9, 3))
    elif rep in bases.PROBES:
        m = bases.BASES[rep]
        opts = {k: settings[k] for k in m.OPTIONS}
        irr = read(FILES[rep], (grid.count, m.floats(opts), 3))
        try:                          # every probe's coefficients as one basis's columns
            m.validate(irr.transpose(1, 0, 2).reshape(irr.shape[1], -1), opts)
        except ValueError as e:
            raise _bad(folder / FILES[rep], str(e)) from None
    else:
        irr = read(FILES[rep], ((n + 2) * nz, (n + 2) * nx * ny, 3))
        if (irr < 0).any():
            raise _bad(folder / FILES[rep], "holds negative irradiance")
    dist = read("distance.exr", ((nd + 2) * nz, (nd + 2) * nx * ny, 2))
    if (dist < 0).any():
        raise _bad(folder / "distance.exr", "holds a negative distance moment")
    tex = read("probe_data.exr", (nz, nx * ny, 4))
    i = np.arange(grid.count)
    rows = tex[i // (nx * ny), i % (nx * ny)]
    if not np.isin(rows[:, 3], (ACTIVE, INACTIVE)).all() or (np.abs(rows[:, :3]) >= MAX_OFFSET + 1e-6).any():
        raise _bad(folder / "probe_data.exr", "holds a probe state other than 0 or 1, or an offset beyond 45% of a cell")
    data = np.concatenate([rows[:, :3] * np.asarray(grid.spacing), rows[:, 3:]], 1)
    settings.update(irradiance=rep, irradiance_texels=n, distance_texels=nd)
    return volume_dict(grid, settings, irr, dist, data, man.get("report", {}))


def read_manifest(path: Path) -> dict:
    try:
        man = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise _bad(path, f"cannot be read as JSON ({e})") from None
    if not isinstance(man, dict):
        raise _bad(path, "is not a JSON object")
    return man


# ---------------------------------------------------------------------------------- GLSL

SH_GLSL = ("0.28209479177387814", "0.4886025119029199 * d.y", "0.4886025119029199 * d.z", "0.4886025119029199 * d.x",
           "1.0925484305920792 * d.x * d.y", "1.0925484305920792 * d.y * d.z",
           "0.31539156525252005 * (3.0 * d.z * d.z - 1.0)", "1.0925484305920792 * d.x * d.z",
           "0.5462742152960396 * (d.x * d.x - d.y * d.y)")     # sh.h's basis at l <= 2, term by term


def basis_glsl(name: str, opts: dict) -> tuple:
    """(the basis's own GLSL function (core/bases glsl) with its coefficient array a variable
    instead of a constant, the lines of probeOwnIrradiance that fill it from the probe's row of the
    file and call it): one formula, the basis module's."""
    import re
    m = bases.BASES[name]
    k = m.floats(opts)
    src = m.glsl(np.zeros((k, 3)), opts)
    src, found = re.subn(rf"const vec3 {m.GLSL_COEFFS}\[{k}\] = vec3\[{k}\]\(.*?\n\);",
                         f"vec3 {m.GLSL_COEFFS}[{k}];     // the probe's coefficients (probeOwnIrradiance)", src,
                         flags=re.S)
    assert found == 1, name
    own = (f"    for (int k = 0; k < {k}; ++k) {m.GLSL_COEFFS}[k] = texelFetch(probeIrradianceAtlas, ivec2(k, index), "
           f"0).rgb;\n    return {m.GLSL_IRRADIANCE}(d);")
    return src, own


def glsl(volume: dict, man: dict) -> str:
    """A GLSL function sampling the written files as kernels/probes.h does (the hardware's bilinear
    filter in place of its reads), the volume's grid and settings baked in."""
    def vec(v):
        return "vec3(" + ", ".join(f"{x:.9g}" for x in v) + ")"

    nx, ny, nz = volume["counts"]
    rep = volume["representation"]
    sh_rep = rep == "sh"
    basis = "\n".join(f"    Y[{k}] = {e};" for k, e in enumerate(SH_GLSL))
    basis_src, own = "", ""
    if rep in bases.PROBES:
        basis_src, own = basis_glsl(rep, basis_options(volume["settings"]))
    return f"""// iblbake irradiance probes: {nx} x {ny} x {nz}, {volume['representation']} irradiance, RTXGI-DDGI layout
// (probes.json holds the conventions). Bind the files as 2D float textures, each with its first
// (top) row at t = 0, clamped to the edge:
//   probeIrradianceAtlas  {man['files']['irradiance']} ({'linear' if rep == 'octahedral' else 'nearest'} filtering)
//   probeDistanceAtlas    distance.exr (linear filtering)
//   probeDataTexture      probe_data.exr (nearest)
// diffuse = albedo / PI * mix(skyIrradiance(N), probeIrradiance(P, N, V), probeVolumeWeight(P)):
// world position, unit shading normal, unit vector towards the viewer; the sky's irradiance (say
// `iblbake sh --glsl`'s shIrradiance) takes over outside the volume.
#define PROBES_SH {int(sh_rep)}
#define PROBES_BASIS {int(bool(basis_src))}
#define PROBE_VISIBILITY {int(volume['visibility'])}
#define PROBE_CLASSIFICATION {int(volume['classification'])}
const ivec3 PROBE_COUNTS = ivec3({nx}, {ny}, {nz});
const vec3 PROBE_ORIGIN = {vec(volume['origin'])};
const vec3 PROBE_SPACING = {vec(volume['spacing'])};
const float PROBE_NORMAL_BIAS = {volume['normal_bias']:.9g};
const float PROBE_VIEW_BIAS = {volume['view_bias']:.9g};
const int PROBE_IRRADIANCE_TEXELS = {volume['irradiance_texels']};
const int PROBE_DISTANCE_TEXELS = {volume['distance_texels']};

uniform sampler2D probeIrradianceAtlas;
uniform sampler2D probeDistanceAtlas;
uniform sampler2D probeDataTexture;
{basis_src}
vec2 probeOctahedral(vec3 d) {{
    vec2 uv = d.xy / (abs(d.x) + abs(d.y) + abs(d.z));
    if (d.z < 0.0) uv = (1.0 - abs(uv.yx)) * vec2(uv.x >= 0.0 ? 1.0 : -1.0, uv.y >= 0.0 ? 1.0 : -1.0);
    return uv;
}}

vec2 probeUV(int index, vec2 oct, int n) {{
    int tile = n + 2;
    int col = index % PROBE_COUNTS.x + (index / (PROBE_COUNTS.x * PROBE_COUNTS.z)) * PROBE_COUNTS.x;
    int row = (index / PROBE_COUNTS.x) % PROBE_COUNTS.z;
    vec2 texel = vec2(float(col * tile), float(row * tile)) + 0.5 * float(tile) + oct * (0.5 * float(n));
    return texel / vec2(float(tile * PROBE_COUNTS.x * PROBE_COUNTS.y), float(tile * PROBE_COUNTS.z));
}}

vec3 probeOwnIrradiance(int index, vec3 d) {{
#if PROBES_SH
    float Y[9];
{basis}
    vec3 e = vec3(0.0);
    for (int k = 0; k < 9; ++k) e += texelFetch(probeIrradianceAtlas, ivec2(k, index), 0).rgb * Y[k];
    return max(e, vec3(0.0));
#elif PROBES_BASIS
{own}
#else
    return max(textureLod(probeIrradianceAtlas, probeUV(index, probeOctahedral(d), PROBE_IRRADIANCE_TEXELS), 0.0).rgb,
               vec3(0.0));
#endif
}}

float probeVolumeWeight(vec3 p) {{
    vec3 halfExtent = 0.5 * PROBE_SPACING * vec3(PROBE_COUNTS - 1);
    vec3 delta = abs(p - (PROBE_ORIGIN + halfExtent)) - halfExtent;
    vec3 w = 1.0 - clamp(delta / PROBE_SPACING, 0.0, 1.0);
    return w.x * w.y * w.z;
}}

vec3 probeIrradiance(vec3 p, vec3 n, vec3 v) {{
    vec3 biased = p + n * PROBE_NORMAL_BIAS + v * PROBE_VIEW_BIAS;
    vec3 g = (biased - PROBE_ORIGIN) / PROBE_SPACING;
    ivec3 base = clamp(ivec3(floor(g)), ivec3(0), PROBE_COUNTS - 1);
    vec3 alpha = clamp(g - vec3(base), 0.0, 1.0);
    vec3 sum = vec3(0.0);
    float wsum = 0.0;
    for (int i = 0; i < 8; ++i) {{
        ivec3 off = ivec3(i & 1, (i >> 1) & 1, (i >> 2) & 1);
        ivec3 c = clamp(base + off, ivec3(0), PROBE_COUNTS - 1);
        int index = c.y * PROBE_COUNTS.x * PROBE_COUNTS.z + c.z * PROBE_COUNTS.x + c.x;
        int planeWidth = PROBE_COUNTS.x * PROBE_COUNTS.y;
        vec4 data = texelFetch(probeDataTexture, ivec2(index % planeWidth, index / planeWidth), 0);
#if PROBE_CLASSIFICATION
        if (data.w != 0.0) continue;
#endif
        vec3 tri3 = mix(1.0 - alpha, alpha, vec3(off));
        vec3 e = probeOwnIrradiance(index, n);
#if PROBE_VISIBILITY
        vec3 pp = PROBE_ORIGIN + vec3(c) * PROBE_SPACING + data.xyz * PROBE_SPACING;
        vec3 tri = max(tri3, vec3(0.001));
        float wrap = 0.5 * (dot(normalize(pp - p), n) + 1.0);
        float w = wrap * wrap + 0.2;
        vec3 toProbe = pp - biased;
        float dist = length(toProbe);
        vec2 m = textureLod(probeDistanceAtlas, probeUV(index, probeOctahedral(-toProbe / dist), PROBE_DISTANCE_TEXELS),
                            0.0).rg;
        float cheb = 1.0;
        if (dist > m.x) {{
            float variance = abs(m.x * m.x - m.y), dv = dist - m.x;
            cheb = variance / (variance + dv * dv);
            cheb = cheb * cheb * cheb;
        }}
        w *= max(0.05, cheb);
        w = max(1e-6, w);
        if (w < 0.2) w *= w * w * (1.0 / (0.2 * 0.2));
        w *= tri.x * tri.y * tri.z;
        sum += w * sqrt(e);
#else
        float w = tri3.x * tri3.y * tri3.z;
        sum += w * e;
#endif
        wsum += w;
    }}
    if (!(wsum > 0.0)) return vec3(0.0);
#if PROBE_VISIBILITY
    vec3 s = sum / wsum;
    return s * s;
#else
    return sum / wsum;
#endif
}}
"""
