"""Reference: progressive Monte Carlo of the exact direct environment lighting, with visibility
(kernels/paths/reference.cl; twin: iblbake/render/twin/reference.py exact). Batches of samples per G-buffer
sample until the frame's relative standard error, measured from two independent replicates, is
below effects.reference.target_noise or max_samples are taken; the mean is added into `radiance`.
With target_noise 0 (a fixed budget) no error is estimated and the samples of a G-buffer sample
are one sequence instead of two replicates: 1.07-1.23x less variance at equal samples
(kernels/sampler.h sampler_replicate)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from iblbake.core import sampling
from iblbake.core.metrics import luminance
from iblbake.device.launch import queue_launch, sample_slices, wave_paths
from iblbake.render.device_scene import panorama_args
from iblbake.render.passes.base import Buffer, Pass, geometry_defines, mode_defines
from iblbake.render.passes.lights import Lights, frame_lights
from iblbake.scene import pack
from iblbake.scene.layout import FLOAT4S

# effects.reference.paths: auto's choice per device kind, measured (docs/benchmarks.md "Megakernel or
# wavefront"); a kind not measured keeps the megakernel
AUTO_PATHS = {"CPU": "megakernel", "GPU": "megakernel"}
_ZEROS = np.zeros(4, np.int32)


def reference_noise(lum_sum, odd_sum, taken: int) -> float:
    """Relative standard error of the reference frame, from its two independent replicates
    (even and odd sample numbers): the RMS over pixels of half their difference, divided by the
    mean pixel luminance."""
    n_odd = taken // 2
    n_even = taken - n_odd
    even = (lum_sum - odd_sum) / n_even
    odd = odd_sum / max(n_odd, 1)
    mean = (lum_sum / taken).mean()
    if mean <= 0:
        return 0.0
    return math.sqrt(np.mean((even - odd) ** 2) / 4.0) / mean


def environment_args(ctx, dist) -> dict:
    """The frame's panorama and its importance-sampling tables (dist) as reference.cl's arguments,
    uploaded once per runtime and panorama (render/device_scene.py panorama_args)."""
    return panorama_args(ctx.rt, ctx.bakes, ctx.image, dist)


@dataclass
class WaveBuffers:
    """The wavefront's per-wave buffers, kept across a frame's tiles while their size (key) holds."""
    key: tuple | None = None
    buffers: dict | None = None


class Reference(Pass):
    name = "reference"
    kernel = "paths/reference.cl"
    params = ("img", "w", "h", "marginal", "conditional", "guide", "env_norm", "seed", "replicates", "first", "batch",
              "slices", "lights", "nlights", "wave", "npaths", "count", "add", "wf_paths", "wf_shadow", "wf_queue",
              "wf_count")
    # the wavefront's stages (kernels/paths/wavefront.cl, effects.reference.paths)
    functions = ("wf_generate", "wf_extend", "wf_shade", "wf_shadow", "wf_accumulate")
    # radiance, and one batch's sums per sample read back (the host adds them up in float64)
    buffers = (Buffer("radiance"), Buffer("ref_batch"))
    host_sample_bytes = 32
    host_writes = ("radiance",)      # the mean, added on the host
    profiles = "paths"               # render/paths/profile.py
    keeps = WaveBuffers

    def runs(self, scene, fx):
        return "reference" in (fx.diffuse, fx.specular)

    def reads_bakes(self, scene, fx):
        return ["env_cdf"]

    def reads_environment(self, scene, fx):
        return True                   # the texels it samples

    def defines(self, scene, fx):
        d = mode_defines(fx)          # reference.cl computes only the reference terms
        if scene.data["effects"]["reference"]["visibility"]:
            d.update(VISIBILITY=1, **geometry_defines(scene))
        if fx.bounces != 1:
            d["BOUNCES"] = fx.bounces     # paths, only where light can pass between surfaces (plan.py)
            if Lights().runs(scene, fx):
                d["PATH_LIGHTS"] = 1      # the lights pass lights the first vertex, paths the others
            way = scene.data["effects"]["reference"]["paths"]
            if way == "wavefront" or (way == "auto" and "wavefront" in AUTO_PATHS.values()):
                d["WAVEFRONT"] = 1        # its stages compiled beside the megakernel
        return d

    def paths(self, ctx) -> str:
        """How this frame's paths run: megakernel or wavefront (effects.reference.paths; auto by
        the device's kind); the direct light alone (no BOUNCES) is the megakernel's."""
        defines = ctx.plan.defines[self.name]
        if "BOUNCES" not in defines or "WAVEFRONT" not in defines:
            return "megakernel"
        way = ctx.scene.data["effects"]["reference"]["paths"]
        return AUTO_PATHS.get(ctx.rt.info.kind, "megakernel") if way == "auto" else way

    def setup(self, ctx) -> dict:
        rt = ctx.rt
        out = environment_args(ctx, ctx.loaded["env_cdf"])
        recs = np.zeros((0, 4), np.float32)
        if "PATH_LIGHTS" in ctx.plan.defines[self.name]:
            recs = pack.light_records(frame_lights(ctx.scene, ctx.bakes.sun(ctx.scene.data["environment"])))
        out.update(lights=rt.to_device(recs.reshape(-1, 4) if len(recs) else np.zeros((4, 4), np.float32)),
                   nlights=len(recs),
                   replicates=sampling.reference_replicates(ctx.scene.data["effects"]["reference"]["target_noise"]))
        return out

    def batching(self, ctx) -> tuple:
        """(samples per G-buffer sample in a launch, work items per G-buffer sample) of this tile."""
        ref = ctx.scene.data["effects"]["reference"]
        batch = ref["batch"] or (256 if ctx.rt.info.kind == "GPU" else 32)
        batch += batch & 1                            # even: both replicates advance together
        return batch, sample_slices(ctx.rt, ctx.table["n"], batch)

    def batch_args(self, ctx, first: int, b: int, slices: int, out) -> tuple:
        """(global size, arguments) of the launch of samples first .. first + b - 1 (the path
        profile launches the same batches: render/paths/profile.py)."""
        n = ctx.table["n"]
        return (n * min(slices, b),), {**ctx.args[self.name], "seed": ctx.scene.data["effects"]["reference"]["seed"],
                                       "first": first, "batch": b, "slices": min(slices, b), "ref_batch": out}

    def profile(self, ctx, repeats):
        from iblbake.render.paths.profile import REPEATS, profile_reference
        return profile_reference(ctx, self, repeats=REPEATS if repeats is None else repeats)

    def run(self, ctx):
        ref = ctx.scene.data["effects"]["reference"]
        rt, t = ctx.rt, ctx.table
        n = t["n"]
        hit = rt.read(t["gb_pos"], (n, 4))[:, 3] != -1.0
        acc = np.zeros((n, 3))
        acc_odd = np.zeros(n)
        taken = 0
        noise = math.inf
        batch, slices = self.batching(ctx)
        paths = self.paths(ctx)
        if paths == "wavefront":
            slices = 1                                # one sum per G-buffer sample (wf_accumulate)
        out = t["ref_batch"] if slices == 1 else rt.empty(16 * n * slices)      # a GPU: slices x n sums
        while taken < ref["max_samples"]:
            b = min(batch, ref["max_samples"] - taken)
            if paths == "wavefront":
                self.wavefront(ctx, taken, b, out)
            else:
                size, args = self.batch_args(ctx, taken, b, slices, out)
                ctx.launch(self, size, **args)
            r = rt.read(out, (n * min(slices, b), 4)).astype(np.float64).reshape(-1, n, 4).sum(0)
            acc += r[:, :3]
            acc_odd += r[:, 3]
            taken += b
            if ctx.progress:
                ctx.progress((ctx.tile_index + taken / ref["max_samples"]) / ctx.tile_count)
            if not hit.any():
                break
            if taken >= 2 * batch and ctx.args[self.name]["replicates"] == 2:
                noise = reference_noise(luminance(acc[hit]), acc_odd[hit], taken)
                if noise <= ref["target_noise"]:
                    break
        # the mean joins what the other lighting passes added
        mean = np.zeros((n, 4), np.float32)
        mean[:, :3] = (acc / max(taken, 1)).astype(np.float32)
        radiance = rt.read(t["radiance"], (n, 4))
        rt.cl.enqueue_copy(rt.queue, t["radiance"], radiance + mean)
        return {"samples_per_pixel": taken,
                "relative_noise": None if not math.isfinite(noise) else round(noise, 6),
                "stopped": "target_noise" if noise <= ref["target_noise"] else "max_samples",
                "visibility": bool(ref["visibility"]), "bounces": ctx.plan.effects.bounces or "unbounded",
                "batch": batch, "work_items_per_sample": slices, "paths": paths}

    def wavefront(self, ctx, first: int, b: int, out):
        """Samples first .. first + b - 1 of every G-buffer sample as a wavefront of stages
        (kernels/paths/wavefront.cl; Laine, Karras and Aila 2013), into out as the megakernel writes
        ref_batch: waves of whole samples (k) over every G-buffer sample, at most wave_paths(rt)
        paths each; per wave generate, then extend, shade and shadow over the compacted queues the
        counters fill, until no path is alive, then the sums, added in the order of k."""
        rt, n = ctx.rt, ctx.table["n"]
        wave = max(1, min(b, wave_paths(rt) // max(n, 1)))
        npaths = n * wave
        nlights = ctx.args[self.name]["nlights"]
        key = (npaths, nlights)
        kept = self.kept(ctx)
        if kept.key != key:
            kept.key, kept.buffers = key, {"wf_paths": rt.empty(16 * FLOAT4S["PATH"] * npaths),
                                           "wf_shadow": rt.empty(16 * FLOAT4S["SHADOW"] * (1 + nlights) * npaths),
                                           "wf_queue": rt.empty(4 * 3 * npaths), "wf_count": rt.empty(16)}
        bufs = kept.buffers
        counts = np.zeros(4, np.int32)
        args = {**ctx.args[self.name], **bufs, "seed": ctx.scene.data["effects"]["reference"]["seed"],
                "npaths": npaths}

        def queued(fn, size, **extra):
            global_size, local_size = queue_launch(size)
            ctx.launch(self, global_size, fn, local_size=local_size, **args, **extra)

        def stage(fn, size, **extra):
            rt.cl.enqueue_copy(rt.queue, bufs["wf_count"], _ZEROS, is_blocking=False)
            if size:
                queued(fn, size, **extra)
            rt.cl.enqueue_copy(rt.queue, counts, bufs["wf_count"])      # blocking: the queues' lengths
            return counts.copy()

        for k0 in range(0, b, wave):
            kw = min(wave, b - k0)
            c = stage("wf_generate", n * kw, first=first + k0, wave=kw)
            while True:
                if c[2]:
                    queued("wf_shadow", int(c[2]), count=int(c[2]))
                if not c[0]:
                    break
                c = stage("wf_extend", int(c[0]), count=int(c[0]))
                c = stage("wf_shade", int(c[1]), count=int(c[1]))
            queued("wf_accumulate", n, first=first + k0, wave=kw, add=int(k0 > 0), ref_batch=out)
