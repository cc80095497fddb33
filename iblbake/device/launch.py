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

# PoCL (3.1), given no local size, makes a launch as few work groups as it can (one of up to 4096
# items), and its pthread device runs a group on one core: the reference's 3072 paths of a 64x48
# frame ran on one of two cores. Paths differ in length (the sky's pixels end at once, a mirror's
# go on), so a path kernel's launch is split into many small groups that the cores take as they
# free (measured, docs/benchmarks.md "Work groups on PoCL": the reference 1.8-2x faster at 64x48).
# Large launches keep 4096-item groups. Only the path kernels, where it was measured (split alike,
# the shade pass once showed a NaN pixel: an unwritten probe value, kernels/probes.h, since fixed).
CPU_GROUPS_PER_CORE = 64
MAX_GROUP = 4096

SPLIT_KERNELS = ("reference", "probe_trace")


def per_launch(rt) -> int:
    """The most work items one launch is given on the runtime's device."""
    return 1 << (20 if rt.info.kind == "GPU" else 16)


def cpu_group(items: int, cores: int) -> int:
    """The work-group size of a one-dimensional launch of `items` on a PoCL device of `cores`
    cores: the largest divisor of items (OpenCL 1.2 needs one) that leaves CPU_GROUPS_PER_CORE
    groups a core, at most MAX_GROUP."""
    bound = max(1, min(MAX_GROUP, items // (CPU_GROUPS_PER_CORE * max(cores, 1))))
    return next(d for d in range(bound, 0, -1) if items % d == 0)


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


# Registers a path-tracing work item may hold on an NVIDIA GPU. Unbounded, NVIDIA's compiler gives
# the reference kernel 141-155 of them (no spills): one 256-item work group per multiprocessor,
# 8 of its 64 warps resident, too few to hide a path's memory latency. Capped at 64 it spills 0.6-1
# KB a work item to L1 and keeps 3-4 times the warps: on an H200 the open box's reference (128x96,
# 8192 spp) 0.50-0.53 s -> 0.35 s, the knot's 1.32 s -> 1.09-1.10 s (docs/benchmarks.md
# "Registers on the H200"); 48 was within noise of 64, 32 slower on the knot. With the while-while
# traversal (kernels/scene.h) 48 beats 64 on the meshes: the knot's reference 1.01-1.12x, the
# textured torus's 1.05-1.06x with leaves of 2 (docs/benchmarks.md "While-while on the GPU").
PATH_REGISTERS = 48
PATH_PROGRAMS = ("paths/reference.cl", "paths/probe_trace.cl")


def build_options(info, name) -> list:
    """Build options a program needs on one device beyond its defines: the register cap for the
    programs holding the paths on an NVIDIA GPU (name: a kernel file, or a tuple of those built
    as one program)."""
    files = name if isinstance(name, tuple) else (name,)
    if PATH_REGISTERS and info.kind == "GPU" and "NVIDIA" in info.platform.upper() and set(files) & set(PATH_PROGRAMS):
        return [f"-cl-nv-maxrregcount={PATH_REGISTERS}"]
    return []
