"""The camera's samples as a ray source (kernels/paths/reference.cl; the reference pass,
render/passes/reference.py, declares its program, defines and batching): batches of samples per
G-buffer sample until the frame's relative standard error, measured from two independent
replicates, is below effects.reference.target_noise or max_samples are taken; each batch's sums
are added on the host in float64."""

from __future__ import annotations

import math

import numpy as np

from iblbake.core.metrics import luminance
from iblbake.render.paths.trace import Launch, Source


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


class CameraSamples(Source):
    """The G-buffer samples of a frame's tile (ctx: the frame's Context) through the reference pass
    `ref_pass` (its batching() and batch_args()). result(): (the mean estimate per G-buffer sample
    (n, 3), the pass's report)."""
    program = "paths/reference.cl"
    function = "reference"

    def __init__(self, ctx, ref_pass):
        self.ctx, self.ref_pass = ctx, ref_pass
        self.ref = ctx.scene.data["effects"]["reference"]
        rt, n = ctx.rt, ctx.table["n"]
        self.n = n
        self.hit = rt.read(ctx.table["gb_pos"], (n, 4))[:, 3] != -1.0
        self.acc, self.acc_odd = np.zeros((n, 3)), np.zeros(n)
        self.taken, self.noise = 0, math.inf
        self.batch, self.slices = ref_pass.batching(ctx)
        self.out = ctx.table["ref_batch"] if self.slices == 1 else rt.empty(16 * n * self.slices)  # a GPU: slices x n sums

    def launch(self, global_size, function, **args):
        self.ctx.launch(self.ref_pass, global_size, function, **args)

    def launches(self):
        while self.taken < self.ref["max_samples"]:
            b = min(self.batch, self.ref["max_samples"] - self.taken)
            size, args = self.ref_pass.batch_args(self.ctx, self.taken, b, self.slices, self.out)
            yield Launch(size[0], args, (self.taken, b))

    def accumulate(self, la: Launch) -> bool:
        ctx, ref, b = self.ctx, self.ref, la.part[1]
        r = ctx.rt.read(self.out, (self.n * min(self.slices, b), 4)).astype(np.float64).reshape(-1, self.n, 4).sum(0)
        self.acc += r[:, :3]
        self.acc_odd += r[:, 3]
        self.taken += b
        if ctx.progress:
            ctx.progress((ctx.tile_index + self.taken / ref["max_samples"]) / ctx.tile_count)
        if not self.hit.any():
            return True
        if self.taken >= 2 * self.batch and ctx.args[self.ref_pass.name]["replicates"] == 2:
            self.noise = reference_noise(luminance(self.acc[self.hit]), self.acc_odd[self.hit], self.taken)
            return self.noise <= ref["target_noise"]
        return False

    def result(self):
        ref, noise = self.ref, self.noise
        return self.acc / max(self.taken, 1), {
            "samples_per_pixel": self.taken, "relative_noise": None if not math.isfinite(noise) else round(noise, 6),
            "stopped": "target_noise" if noise <= ref["target_noise"] else "max_samples",
            "visibility": bool(ref["visibility"]), "bounces": self.ctx.plan.effects.bounces or "unbounded",
            "batch": self.batch, "work_items_per_sample": self.slices}
