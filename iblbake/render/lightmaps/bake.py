"""A lightmap's bake: its texels as one more ray source of the path tracer's one driver
(render/paths/trace.py), kernels/paths/lightmap_trace.cl: per texel `samples` paths, a square of
strata over the hemisphere of its shading normal (uniform in solid angle, each texel's strata
jittered by its own stream), and as many shadow rays drawn from the panorama's importance table,
the two weighed by the power heuristic where a path escapes (ray_weights: next-event estimation of
the panorama at the texel, as the camera's reference has it at every vertex), from its start point (the surface
point moved OFFSET texels into its triangle and lifted OFFSET texels along the geometric normal;
moved past a solid's back face its tangent rays meet where the move lands on that solid's front,
lightmap_nudge), whole texels per launch. Per texel, from the same rays (w each ray's share of the
hemisphere): its irradiance E(n) = sum w L cos (the
non-directional lightmap, kept always) and its coefficients in the scene's `lightmap.basis`
(bases.py: L1 SH, or any coefficient basis of the probes' registry fitted by its own code), and
where the frame reads `specular: lightmap` a second set fitted for the radiance (bases.py
project_specular: the lobe's).
A texel more than REJECT of whose rays meet the inside of a solid starts inside geometry: it is
dropped and dilated over (BakingLab's rejection). Dilation: every empty texel takes the mean of its
valid 8-neighbours, DILATE passes (across chart seams and the padding)."""

from __future__ import annotations

import math
import time

import numpy as np

from iblbake.core import conventions
from iblbake.core.sampling import power_heuristic
from iblbake.device.launch import whole_units
from iblbake.errors import InputError
from iblbake.render.lightmaps import bases
from iblbake.render.lightmaps import uv as uvs
from iblbake.render.lightmaps.bases import sh_irradiance  # noqa: F401  (the package's, read.py's)
from iblbake.render.paths.trace import Launch, Source, describe, trace

PROGRAM = "paths/lightmap_trace.cl"
OFFSET = 0.1          # the start point's lift along the geometric normal, in texels (BakingLab's bias)
REJECT = 0.1          # a texel whose rays meet a solid's inside more often than this is inside geometry
DILATE = 4            # dilation passes (PADDING texels between charts, and their seams)
BASES = bases.OWN       # what a bake of the default basis (sh_l1) can be read as; every choice: bases.NAMES
DEFAULT_BASIS = "sh_l1"  # a lightmap section's basis where it names none (the schema's default)
ACROSS_SAID = 8         # texels across the whole scene under which its density is said (another scale's unit,
                        # or far too coarse: trial75's 5 m room at 1 texel a unit, the floor x0.88)


def coarse_said(density: float, bounds) -> list:
    """The density said where the whole scene is under ACROSS_SAID texels across its largest extent
    (texels_per_unit is in the scene's units: a new user's room scaled by 0.01 took 0.32 texels a side
    at the default 8, the frame 84% off, nothing said)."""
    if bounds is None:
        return []
    extent = float(np.max(np.asarray(bounds[1], np.float64) - np.asarray(bounds[0], np.float64)))
    if not (0 < extent and density * extent < ACROSS_SAID):
        return []
    return [f"lightmap: {density:g} texels a unit give the whole scene {density * extent:.2g} texels across (its "
            f"bounds span {extent:.4g}): lightmap.texels_per_unit is in the scene's units; give about "
            f"{float(f'{64 / extent:.2g}'):g} (64 texels across it)"]


def frames(n):
    """An orthonormal tangent and bitangent per unit normal n (k, 3) (Duff et al. 2017)."""
    s = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (s + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1 + s * n[:, 0] ** 2 * a, s * b, -s * n[:, 0]], 1)
    bt = np.stack([b, s + n[:, 1] ** 2 * a, -n[:, 1]], 1)
    return t, bt


def importance_rays(uniform: int, dist) -> int:
    """How many shadow rays a texel draws from the panorama's importance table beside its `uniform`
    paths: one each, as the camera's reference samples the panorama at every path vertex; none
    where that table is flat (a uniform sky, or no light: uniform over the sphere, which the
    hemisphere's strata beat)."""
    return uniform if dist.pdf.max() > dist.pdf.min() * (1 + 1e-6) else 0


def hemisphere_dirs(normals, samples: int, texel0: np.ndarray, seed: int, dist=None, rotation: float = 0.0,
                    extra: int = 0):
    """(k, samples + extra, 3) world directions: a sqrt(samples)^2 grid of strata over the hemisphere
    (uniform in solid angle: cos = u, phi = 2 pi v) about each normal, jittered per texel and
    stratum by its texel number's stream; then `extra` directions drawn from the panorama's
    importance table dist (EnvironmentDistribution, turned by the scene's rotation_y) by the same
    stream (Latin hypercube samples), any side of the surface."""
    side = int(math.isqrt(samples))
    i, j = np.divmod(np.arange(samples), side)
    out = np.empty((len(normals), samples + extra, 3))
    u_env = np.empty((len(normals), extra, 4))
    t, b = frames(normals)
    for k, tex in enumerate(texel0):
        rng = np.random.default_rng([seed, int(tex)])
        u = (i + rng.random(samples)) / side
        v = (j + rng.random(samples)) / side
        r = np.sqrt(np.maximum(0.0, 1 - u * u))
        ph = 2 * math.pi * v
        out[k, :samples] = (r * np.cos(ph))[:, None] * t[k] + (r * np.sin(ph))[:, None] * b[k] + u[:, None] * normals[k]
        # a Latin hypercube over the table's four dimensions: rows and columns spread evenly (a
        # plain draw leaves a uniform sky's texel 25% off at 64 rays, its share above the horizon random)
        u_env[k] = (np.argsort(rng.random((4, extra)), 1).T + rng.random((extra, 4))) / max(extra, 1)
    if extra:
        d, _texel = dist.sample(u_env.reshape(-1, 4))
        out[:, samples:] = conventions.rotate_y(d, rotation).reshape(len(normals), extra, 3)
    return out


def device_shares(dirs, normals, uniform: int):
    """ray_dirs' w (k, s) for lightmap_trace.cl's paths and shadow rays to the panorama: a path's
    share of the hemisphere (2 pi / uniform); 1 a shadow ray (the panorama where it escapes,
    nothing where it meets a surface), 0 one behind the surface (not traced)."""
    w = np.full(dirs.shape[:2], 2 * math.pi / uniform)
    w[:, uniform:] = np.einsum("ksx,kx->ks", dirs[:, uniform:], normals) > 0
    return w


def ray_weights(dirs, t, uniform: int, dist, rotation: float):
    """Each ray's weight w (k, s), sum w L f estimating the integral of L f over the texel's
    hemisphere: the `uniform` paths 1 / (n pu) (pu = 1 / 2 pi), their escapes times the power
    heuristic against the importance rays' sampling of the panorama (Veach 1997, n samples of
    each); an importance ray that escapes (t = +inf) 1 / (n pe) times the heuristic against the
    paths' (0 where it met a surface: the paths bring that light, or behind the surface)."""
    w = np.zeros(dirs.shape[:2])
    w[:, :uniform] = 2 * math.pi / uniform
    extra = dirs.shape[1] - uniform
    if not extra:
        return w
    pe = dist.pdf_of(conventions.rotate_y(dirs, -rotation))
    pu = np.full_like(pe, 1 / (2 * math.pi))
    missed = np.isinf(t) & (t > 0)
    w[:, :uniform] *= np.where(missed[:, :uniform], power_heuristic(pu, pe)[:, :uniform], 1.0)
    pe_s = pe[:, uniform:]
    esc = missed[:, uniform:] & (pe_s > 0)
    w[:, uniform:] = np.where(esc, power_heuristic(pe, pu)[:, uniform:] / (extra * np.where(esc, pe_s, 1)), 0.0)
    return w


class LightmapTexels(Source):
    """The texels' rays (lightmap_trace.cl through a Tracer's scene, panorama and lights), whole
    texels per launch; kept per texel: E (k, 3), the coefficients of `basis` (bases.py) with its
    options (k, floats, 3) and its share of rays that met a solid's inside (k,); with `specular`,
    the basis's second set fitted for the radiance (bases.project_specular) in .spec. progress(the
    fraction traced)."""
    program, function = PROGRAM, "lightmap_trace"

    def __init__(self, tracer, start, normals, samples: int, seed: int, progress=None, basis: str = "sh_l1",
                 opts: dict | None = None, specular: bool = False):
        self.tracer, self.rt, self.samples, self.seed, self.progress = tracer, tracer.rt, samples, seed, progress
        self.basis, self.opts = basis, opts or {}
        self.normals, self.n = normals, len(start)
        self.uniform = samples
        self.extra = importance_rays(samples, tracer.dist)
        # rays a texel: paths, then shadow rays to the panorama. None to the analytic lights: their
        # direct light is the frame's (the lights pass, per pixel with its shadows) and an engine's
        # (lightmap.json's `lights`), as the probes leave it out; the paths' later vertices sample
        # them, so their bounce is in the texel's light
        self.samples = samples = self.uniform + self.extra
        self.pos = self.rt.to_device(np.pad(np.asarray(start, np.float32), ((0, 0), (0, 1))))
        self.per = whole_units(self.rt, samples)
        self.buf = self.rt.empty(16 * min(self.n, self.per) * samples)
        self.irradiance = np.zeros((self.n, 3))
        self.coeffs = np.zeros((self.n, bases.floats(basis, self.opts), 3))
        self.inside = np.zeros(self.n)
        self.spec = np.zeros((self.n, bases.floats(basis, bases.specular_options(basis, self.opts)), 3)) \
            if specular else None
        self.dirs = {}

    def launch(self, global_size, function, **args):
        t = self.tracer
        return self.rt.launch(PROGRAM, function, t.defines, global_size, t.table, **t.args, **args)

    def launches(self):
        for first in range(0, self.n, self.per):
            count = min(self.per, self.n - first)
            t, n = self.tracer, self.normals[first:first + count]
            texel = np.arange(first, first + count)
            d = hemisphere_dirs(n, self.uniform, texel, self.seed, t.dist, t.rotation, self.extra)
            self.dirs[first] = d
            rays = np.concatenate([d, device_shares(d, n, self.uniform)[..., None]], 2)
            dev = self.rt.to_device(rays.reshape(-1, 4).astype(np.float32))
            yield Launch(count * self.samples, {"texel_pos": self.pos, "ray_dirs": dev, "nrays": self.samples,
                                                "paths": self.uniform, "first": first,
                                                "count": count, "seed": self.tracer.settings["seed"],
                                                "ray_out": self.buf}, (first, count))

    def accumulate(self, la: Launch) -> bool:
        first, count = la.part
        out = self.rt.read(self.buf, (count * self.samples, 4)).reshape(count, self.samples, 4).astype(np.float64)
        d = self.dirs.pop(first)
        w = ray_weights(d, out[..., 3], self.uniform, self.tracer.dist, self.tracer.rotation)
        radiance, n = out[..., :3], self.normals[first:first + count]
        self.irradiance[first:first + count], self.coeffs[first:first + count], self.inside[first:first + count] = \
            project(radiance, out[..., 3], d, n, self.basis, self.opts, w, self.uniform)
        if self.spec is not None:
            self.spec[first:first + count] = bases.project_specular(self.basis, radiance, d, n, self.opts, w)
        if self.progress:
            self.progress((first + count) / self.n)
        return False

    def result(self):
        self.tracer.rays_traced += self.n * self.samples
        return self.irradiance, self.coeffs, self.inside


def project(radiance, t, dirs, normals, basis: str = "sh_l1", opts: dict | None = None, weights=None,
            uniform: int | None = None):
    """Per texel (E (k, 3), its coefficients in basis (k, floats, 3), the share of its uniform rays
    (the first `uniform`; None: all) that met a solid's inside) from its rays' radiance (k, s, 3),
    signed distance (k, s) and directions (k, s, 3) over the hemisphere of normals (k, 3), each
    ray's share of the hemisphere in weights (k, s) (None: uniform rays; bases.project)."""
    e, coeffs = bases.project(basis, radiance, dirs, normals, opts or {}, weights)
    return e, coeffs, (t[:, :uniform] < 0).mean(1)




def inset(tx: uvs.Texels, corners, texel_size: float):
    """The texels' points moved OFFSET texels towards their triangle's centroid (at most half way):
    a point on a chart's edge lies in the plane of the wall meeting it there, and its rays along that
    wall would start on it and pass through (a room's corner lit by the sky outside)."""
    to = corners[tx.triangle].mean(1) - tx.position
    dist = np.linalg.norm(to, axis=1, keepdims=True)
    step = np.minimum(OFFSET * texel_size, 0.5 * dist)
    return tx.position + np.divide(to * step, dist, out=np.zeros_like(to), where=dist > 0)


def nudge(tracer, tx: uvs.Texels, points, texel_size: float):
    """The texels' start points: `points` lifted OFFSET texels along the geometric normal, then moved
    past the nearest solid's back face that one of four tangent rays (half a texel's diagonal long)
    meets, where the first surface back along the move is that solid's front (lightmap_nudge's
    lands_on_front: not through a box's side into the zero-thickness wall it stands flush against,
    which put a texel behind the wall, lit by the sky outside)."""
    rt = tracer.rt
    lift = points + OFFSET * texel_size * tx.geometric
    reach = math.sqrt(0.5) * texel_size
    t, b = frames(tx.geometric)
    dirs = np.stack([t, -t, b, -b], 1).reshape(-1, 3)
    pos = np.concatenate([lift, np.full((len(lift), 1), reach)], 1).astype(np.float32)
    out = rt.empty(16 * len(lift))
    rt.launch(PROGRAM, "lightmap_nudge", tracer.defines, (len(lift),), tracer.table,
              texel_pos=rt.to_device(pos), nudge_dirs=rt.to_device(np.pad(dirs, ((0, 0), (0, 1))).astype(np.float32)),
              texel_nrm=rt.to_device(np.pad(tx.geometric, ((0, 0), (0, 1))).astype(np.float32)), count=len(lift),
              pos_out=out)
    moved = rt.read(out, (len(lift), 4))[:, :3].astype(np.float64)
    return moved, int((np.abs(moved - pos[:, :3]).sum(1) > 0).sum())


def _first_hits(o, d, arrays, reach):
    """(t, whether it is a solid's back face (scene.h probe_back_face), whether it is a solid's front
    face) of the nearest hit of each ray (o, d) within reach, any side (cull 0); inf where none. Two
    surfaces at one distance (a solid flush against a wall) count as neither face of a solid. The
    twin of lightmap_nudge's traces."""
    from iblbake.render.twin.gbuffer import _plane_t, _sphere_t, _triangle_t
    from iblbake.scene.layout import SURFACE_FLAGS

    ints = lambda a: int(np.asarray(a, np.float32).view(np.int32))
    best, back, front = np.full(len(o), np.inf), np.zeros(len(o), bool), np.zeros(len(o), bool)

    def take(t, ng, flags):
        nonlocal best, back, front
        s = (ng * d).sum(1)
        solid = bool(flags & SURFACE_FLAGS["solid"])
        b = np.asarray((s < 0 if flags & SURFACE_FLAGS["solid_flipped"] else s > 0) if solid else
                       (s > 0) & bool(flags & SURFACE_FLAGS["single_sided"]), bool)
        tie = np.isclose(t, best, rtol=1e-9, atol=1e-12) & (t < reach)
        back, front = np.where(tie, False, back), np.where(tie, False, front)
        closer = (t < best) & (t < reach) & ~tie
        best, back = np.where(closer, t, best), np.where(closer, b, back)
        front = np.where(closer, solid & ~b, front)
    for sp in arrays.spheres.astype(np.float64):
        t = _sphere_t(o, d, sp)
        ng = (o + np.where(np.isfinite(t), t, 0)[:, None] * d - sp[0, :3]) / sp[0, 3]
        take(t, ng, ints(sp[1, 2]))
    for pl in arrays.planes.astype(np.float64):
        take(_plane_t(o, d, pl), np.broadcast_to(pl[1, :3], o.shape), ints(pl[4, 0]))
    for tri in arrays.tris.astype(np.float64):
        ng = np.cross(tri[1, :3] - tri[0, :3], tri[2, :3] - tri[0, :3])
        take(_triangle_t(o, d, tri)[0], np.broadcast_to(ng, o.shape), ints(tri[2, 3]))
    return best, back, front


def nudge_twin(points, geometric, texel_size: float, arrays):
    """lightmap_nudge in float64: the start points and how many moved (the kernel's twin)."""
    lift = points + OFFSET * texel_size * geometric
    reach = math.sqrt(0.5) * texel_size
    t, b = frames(geometric)
    nearest, moved = np.full(len(lift), reach), lift.copy()
    for d in (t, -t, b, -b):
        with np.errstate(invalid="ignore", divide="ignore"):       # rays along a triangle's plane
            hit, back, _ = _first_hits(lift, d, arrays, reach)
            past = np.where(np.isfinite(hit), hit, 0) + 0.05 * reach
            land = lift + past[:, None] * d
            _, _, front = _first_hits(land, -d, arrays, past)            # lands_on_front
        take = back & (hit < nearest) & front
        nearest = np.where(take, hit, nearest)
        moved[take] = land[take] + 0.05 * reach * geometric[take]
    return moved, int((np.abs(moved - lift).sum(1) > 0).sum())


def dilate(atlas, valid, passes: int = DILATE):
    """Each empty texel (valid False) takes the mean of its valid 8-neighbours, `passes` times;
    atlas (h, w, ...) and valid (h, w) are returned filled (copies)."""
    a, v = atlas.copy(), valid.copy()
    h, w = v.shape
    for _ in range(passes):
        pa = np.pad(a * v.reshape(h, w, *([1] * (a.ndim - 2))), [(1, 1), (1, 1)] + [(0, 0)] * (a.ndim - 2))
        pv = np.pad(v.astype(np.float64), 1)
        s = sum(pa[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx)
        c = sum(pv[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx)
        fill = ~v & (c > 0)
        if not fill.any():
            break
        a[fill] = s[fill] / c[fill].reshape(-1, *([1] * (a.ndim - 2)))
        v = v | fill
    return a, v


def bytes_of(lay: uvs.Layout, basis: str, opts: dict | None = None) -> int:
    """The atlas' bytes as an engine holds it: fp16 RGBA per texel, one texture per RGB coefficient
    (one for the irradiance, four for L1 SH, nine for SG9)."""
    return lay.width * lay.height * 8 * bases.floats(basis, opts or {})


def triangles(sc):
    """The scene's triangles as the bake charts them (scene/geometry build_triangles, spheres meshed)."""
    from iblbake.scene import geometry, materials
    _records, offsets = materials.table(sc)
    counts = {oid: len(materials.file_materials(o["mesh"]["path"], f"{sc.source}: objects.{oid}.mesh"))
              for oid, o in enumerate(sc.data["objects"]) if materials.brings_materials(o)}
    return geometry.build_triangles(sc.data["objects"], offsets, sc.source, counts, True)


def check_sizes(sc, densities: dict) -> None:
    """Each density (texels per unit) of {density: what the message calls it} against the scene's
    lightmap.max_texels, as a bake checks it (uv.check_size) without packing: a study's rungs
    checked before anything renders."""
    surface = uvs.surface_area(sc, triangles(sc))
    for d, key in densities.items():
        uvs.check_size(sc, surface, d, sc.data["lightmap"]["max_texels"], key)


def bake(job, settings: dict, progress=None) -> dict:
    """The scene's lightmap (settings: the scene's lightmap section): the layout, the atlases
    {'irradiance': (h, w, 3), BASIS: (h, w, floats, 3), 'valid': (h, w) bool}, BASIS the section's
    `basis` (bases.py) under 'basis' with its options under 'options', and a report; with settings'
    `specular` (true where the frame reads `specular: lightmap`) the basis's second set fitted for
    the radiance, 'specular' (h, w, floats, 3), with its options under 'specular_options'."""
    from iblbake.render.paths.tracer import Tracer

    t0 = time.perf_counter()
    sc = job.scene
    basis = settings.get("basis", DEFAULT_BASIS)
    if basis not in bases.NAMES:
        raise InputError(f"lightmap.basis: {basis!r} is not a lightmap basis; give one of {', '.join(bases.NAMES)}")
    opts = bases.options(basis, settings)
    tris = triangles(sc)
    density = settings["texels_per_unit"]
    lay = uvs.layout(sc, tris, density, settings["max_texels"])
    tx = uvs.texels(lay)
    t_layout = time.perf_counter() - t0
    tracer = Tracer(job, {"bounces": settings["bounces"], "seed": settings["seed"]})
    start, moved = nudge(tracer, tx, inset(tx, lay.corners, 1.0 / density), 1.0 / density)
    samples = math.isqrt(settings["samples"]) ** 2          # whole strata
    specular = bool(settings.get("specular"))      # `effects.specular: lightmap` (units.py Lightmap.settings)
    if specular and basis not in bases.LOBED:
        raise InputError(f"lightmap.basis: {basis} carries no specular lobe; give one of {', '.join(bases.LOBED)} "
                         "for effects.specular: lightmap")
    texels = LightmapTexels(tracer, start, tx.normal, samples, settings["seed"], progress, basis, opts, specular)
    shadow = f" and {texels.extra} shadow rays to the panorama" if texels.extra else ""   # the report's rays_traced
    describe(progress, f"{len(tx.index):,} lightmap texels x {samples} paths{shadow} = "
                       f"{len(tx.index) * (samples + texels.extra):,} rays ({lay.width}x{lay.height} atlas, "
                       f"{density:g} texels a unit)")
    e, coeffs, inside = trace(texels)
    ok = inside <= REJECT
    h, w = lay.height, lay.width
    valid = np.zeros(h * w, bool)
    valid[tx.index[ok]] = True
    irr = np.zeros((h * w, 3))
    # irradiance is >= 0 (the frame clamps it too, kernels/lightmap.h lightmap_texel): the residual
    # panorama where a sun was extracted dips a hair below 0 where the fitted lobe overshoots (city:
    # 506 values, the least -0.0016), a dark texel's few paths land under 0 (trial77: -1e-5 at 16
    # samples), and read back a negative texel fails the bake's check
    irr[tx.index] = np.maximum(e, 0.0)
    atlas = np.zeros((h * w,) + coeffs.shape[1:])
    atlas[tx.index] = coeffs
    irr, filled = dilate(irr.reshape(h, w, 3), valid.reshape(h, w))
    atlas, _ = dilate(atlas.reshape(h, w, *coeffs.shape[1:]), valid.reshape(h, w))
    spec = {}
    if specular:
        sp = np.zeros((h * w,) + texels.spec.shape[1:])
        sp[tx.index] = texels.spec
        spec = {"specular": dilate(sp.reshape(h, w, *texels.spec.shape[1:]), valid.reshape(h, w))[0],
                "specular_options": bases.specular_options(basis, opts)}
    report = {"width": w, "height": h, "texels": len(tx.index), "texels_per_unit": density,
              "samples": samples, "importance_rays": texels.extra, "rays_traced": tracer.rays_traced, "moved": moved,
              "rejected_inside": int((~ok).sum()), "layout_s": round(t_layout, 4),
              "bytes": {**{b: bytes_of(lay, b, opts) for b in ("irradiance", basis)},
                        **({"specular": bytes_of(lay, basis, opts)} if specular else {})},
              "uv_sources": {str(k): v for k, v in lay.source.items()},
              "seconds": round(time.perf_counter() - t0, 4)}
    return {"layout": lay, "texels": tx, "irradiance": irr, basis: atlas if basis != "irradiance" else irr,
            "basis": basis, "options": opts, "valid": filled, "report": report, **spec}
