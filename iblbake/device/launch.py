"""One launch and memory policy for every traced pass and bake (the reference's batches, the
irradiance probes' rays, the reflection captures' texels): how many work items a launch is given.

A GPU needs many resident threads to hide memory latency (an H200 holds 132 SMs x 2048 threads,
about 2^18), so a launch is given at least GPU_ITEMS work items where the work allows; a CPU
runtime's cores are filled by far fewer. A launch is given at most per_launch(rt) items: its
results are read back to the host per launch (16 bytes a ray: 16 MiB on a GPU, 1 MiB on a CPU),
and the progress bar moves once a launch. Random streams are numbered by probe, ray or sample,
never by launch, so the results do not depend on the split."""

from __future__ import annotations

GPU_ITEMS = 1 << 18


def per_launch(rt) -> int:
    """The most work items one launch is given on the runtime's device."""
    return 1 << (20 if rt.info.kind == "GPU" else 16)


def whole_units(rt, unit: int) -> int:
    """Work units of `unit` items each (a probe's rays, a texel's samples) per launch: as many
    whole units as per_launch allows, at least one."""
    return max(1, per_launch(rt) // max(unit, 1))


def sample_slices(rt, n: int, batch: int) -> int:
    """Work items per G-buffer sample for a batch of `batch` samples over n G-buffer samples: on a
    GPU enough for GPU_ITEMS in all (at most one per sample of the batch); 1 on a CPU, whose cores
    a frame's samples already fill."""
    if rt.info.kind != "GPU":
        return 1
    return max(1, min(batch, -(-GPU_ITEMS // max(n, 1))))
