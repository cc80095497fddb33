"""The ray sources from points (kernels/paths/probe_trace.cl, bound by a Tracer: render/paths/tracer.py),
run by the one driver (render/paths/trace.py):
  PointRays  every direction from every position, a probe's rays in whole probes per launch; kept
             per position and ray (the irradiance probes' rays, their relocation's and the
             rooms' tests)
  TexelRays  `samples` rays per texel from one position, whole texels per launch; kept as each
             texel's mean (the reflection captures' texels; a lightmap's texels are rays of this
             kind from a position per texel)
A ray's random stream is its probe's and ray's number, never its launch's: the split changes nothing."""

from __future__ import annotations

import numpy as np

from iblbake.device.launch import whole_units
from iblbake.render.paths.trace import Launch, Source

PROGRAM = "paths/probe_trace.cl"      # the kernel of rays from points (bound by a Tracer)


class PointRays(Source):
    """Rays `dirs` ((rays, 3), or (rays, 4) with each ray's share of the sphere in w) from every
    position; result(): (radiance (positions, rays, 3), signed distance (positions, rays), the object
    each ray met, -1 none). shade False: distances only. probe0, ray0: the first position's and
    ray's numbers (their random streams). ids: the positions traced, by number (each keeps its
    number's stream; the results are theirs, in that order). progress(done + share * the fraction
    traced)."""
    program, function = PROGRAM, "probe_trace"

    def __init__(self, tracer, positions, dirs, shade: bool, progress=None, done=0.0, share=1.0, probe0=0, ray0=0,
                 ids=None):
        rt = self.rt = tracer.rt
        self.tracer, self.shade, self.probe0, self.ray0 = tracer, shade, probe0, ray0
        self.progress, self.done, self.share = progress, done, share
        self.n, self.nrays = n, nrays = len(positions) if ids is None else len(ids), len(dirs)
        self.pos = rt.to_device(np.pad(np.asarray(positions, np.float32), ((probe0, 0), (0, 1))))
        self.ids = rt.to_device(np.asarray([0] if ids is None or not len(ids) else ids, np.int32))
        self.by_ids = ids is not None
        dirs = np.asarray(dirs, np.float32)
        self.dirs = rt.to_device(dirs if dirs.shape[1] == 4 else np.pad(dirs, ((0, 0), (0, 1))))
        self.per = per = whole_units(rt, nrays)           # whole probes per launch (device/launch.py)
        self.out = np.empty((n, nrays, 4), np.float32)
        self.obj = np.empty((n, nrays), np.int32)
        self.buf = rt.empty(16 * min(n, per) * nrays)
        self.obj_buf = rt.empty(4 * min(n, per) * nrays)

    def launch(self, global_size, function, **args):
        self.tracer.launch(global_size, function, **args)

    def launches(self):
        t, nrays = self.tracer, self.nrays
        for first in range(0, self.n, self.per):
            count = min(self.per, self.n - first)
            yield Launch(count * nrays, {
                "probe_pos": self.pos, "probe_ids": self.ids, "by_ids": int(self.by_ids), "ray_dirs": self.dirs,
                "nrays": nrays, "first": first if self.by_ids else self.probe0 + first,
                "count": count, "ray0": self.ray0, "ray_solid_angle": 4 * np.pi / nrays, "seed": t.settings["seed"],
                "shade": int(self.shade), "back_faces_black": int(t.back_faces_black),
                "ray_out": self.buf, "ray_obj": self.obj_buf}, (first, count))

    def accumulate(self, la: Launch) -> bool:
        (first, count), rt, nrays = la.part, self.rt, self.nrays
        self.out[first:first + count] = rt.read(self.buf, (count * nrays, 4)).reshape(count, nrays, 4)
        self.obj[first:first + count] = rt.read(self.obj_buf, (count * nrays,), np.int32).reshape(count, nrays)
        if self.progress:
            self.progress(self.done + self.share * (first + count) / self.n)
        return False

    def result(self):
        self.tracer.rays_traced += self.n * self.nrays
        return self.out[..., :3].astype(np.float64), self.out[..., 3].astype(np.float64), self.obj


class TexelRays(Source):
    """`samples` rays per texel from `position` (dirs: (texels * samples, 4), a texel's samples
    together, w each ray's share of the sphere), whole texels per launch, the rays of texel range k
    numbered from its first ray (ray0) under probe number `index`. result(): ((texels, 7) per texel
    the mean over its rays of the radiance of those that met the scene (RGB), the share that did (A)
    and the radiance of those that escaped (RGB); {object: share of the sphere whose rays met its
    inside}; a texel's distance, the mean over its rays that met the scene of where they met it, 0
    where none did: depth()). progress(the fraction traced)."""
    program, function = PROGRAM, "probe_trace"

    def __init__(self, tracer, position, dirs, samples: int, index: int, progress=None):
        self.tracer, self.dirs, self.samples, self.index, self.progress = tracer, dirs, samples, index, progress
        self.pos = np.asarray([position], np.float64)
        self.per = whole_units(tracer.rt, samples) * samples          # whole texels per launch (device/launch.py)
        self.sums = np.zeros((len(dirs) // samples, 7))
        self.dist = np.zeros(len(dirs) // samples)
        self.inside = {}

    def launch(self, global_size, function, **args):
        self.tracer.launch(global_size, function, **args)

    def launches(self):
        for r0 in range(0, len(self.dirs), self.per):
            rays = PointRays(self.tracer, self.pos, self.dirs[r0:r0 + self.per], True, probe0=self.index, ray0=r0)
            for la in rays.launches():
                yield Launch(la.size, la.args, (r0, rays, la))

    def accumulate(self, la: Launch) -> bool:
        r0, rays, own = la.part
        rays.accumulate(own)
        rad, t, obj = rays.result()
        n, share = self.samples, self.dirs[r0:r0 + self.per, 3]
        met = np.isfinite(np.abs(t[0]))[:, None]
        rows = np.concatenate([np.where(met, rad[0], 0.0), met.astype(np.float64), np.where(met, 0.0, rad[0])], 1)
        texels = slice(r0 // n, (r0 + len(rad[0])) // n)
        self.sums[texels] = rows.reshape(-1, n, 7).mean(1)
        hits = met[:, 0].reshape(-1, n)
        self.dist[texels] = np.where(hits, np.abs(t[0]).reshape(-1, n), 0.0).sum(1) / np.maximum(hits.sum(1), 1)
        back = t[0] < 0                            # the inside of a solid (scene.h probe_back_face)
        for o in np.unique(obj[0][back]):
            self.inside[int(o)] = self.inside.get(int(o), 0.0) + float(share[back & (obj[0] == o)].sum()) / (4 * np.pi)
        if self.progress:
            self.progress(min(1.0, (r0 + self.per) / len(self.dirs)))
        return False

    def result(self):
        return self.sums, self.inside

    def depth(self):
        """(texels,) each texel's mean distance to where its rays met the scene, 0 where none did."""
        return self.dist
