"""The environment's importance sampling on a device: nanoseconds a draw of kernels/envmap.h
sample_env (the guide tables of the marginal and of each row, Chen and Asau 1974) with the
sampled texel's radiance and pdf read, as a path's light sample does, against the same source
with the marginal's search made whole (sample_env before the marginal's guide) and with both
searches whole (before any guide): the same texels, on the panoramas the path tracer is timed
on, benchmarks/mitsuba_paths.py's courtyard (2048 x 1024), and a panorama of random rows with a
sun. Each variant is timed after a warm-up launch, alternating, median of --repeats; the random
numbers' own cost (a kernel that draws them only) is subtracted.
docs/benchmarks.md "The environment's tables in the cache" quotes it.

    .venv/bin/python benchmarks/bench_env_sampling.py                 # the default device (PoCL)
    .venv/bin/python benchmarks/bench_env_sampling.py --devices pocl,intel-cpu
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import mitsuba_paths as mp  # noqa: E402  (its panorama)

# a sample's four uniforms from a hash of its number (the cost subtracted: kernel `uniforms`)
SOURCE = r"""
IBL_INLINE float4 u4(uint i)
{
    return (float4)(pcg_hash(4u * i) >> 8, pcg_hash(4u * i + 1u) >> 8, pcg_hash(4u * i + 2u) >> 8,
                    pcg_hash(4u * i + 3u) >> 8) * (1.0f / 16777216.0f);
}
#define BENCH_PARAMS __global const float4 *img, const int w, const int h, __global const float *marginal, \
    __global const float *conditional, __global const int *guide, const float2 env_norm, const int n, \
    __global float *out
__kernel void uniforms(BENCH_PARAMS)
{
    float acc = 0.0f;
    for (int s = 0; s < n; ++s) { const float4 u = u4(get_global_id(0) * n + s); acc += u.x + u.y + u.z + u.w; }
    out[get_global_id(0)] = acc;
}
__kernel void draw(BENCH_PARAMS)
{
    float acc = 0.0f;
    for (int s = 0; s < n; ++s) {
        int t;
        const float4 u = u4(get_global_id(0) * n + s);
        const float3 d = sample_env(marginal, conditional, guide, w, h, u, &t);
        acc += d.x * pdf_env(img[t].xyz, env_norm);
    }
    out[get_global_id(0)] = acc;
}
"""
# sample_env as it is, and with its guided searches replaced by whole ones (the same code otherwise)
MARGINAL = ("cdf_search(marginal, gmr[gm], gmr[gm + 1], u.x)", "cdf_search(marginal, 0, h - 1, u.x)")
ROW = ("cdf_search(conditional + j * (w + 1), gr[g], gr[g + 1], u.y)",
       "cdf_search(conditional + j * (w + 1), 0, w - 1, u.y)")
VARIANTS = {"guides": (), "row guide only": (MARGINAL,), "whole searches": (MARGINAL, ROW)}


def panoramas(tmp: Path) -> dict:
    from iblbake.io import images
    pano, _ = mp.panorama_pair(tmp)
    court = images.read_panorama(pano)[0][..., :3]
    rng = np.random.default_rng(1)
    rows = rng.gamma(0.3, size=court.shape).astype(np.float32)
    rows[300:302, 900:904] = 5e4
    h, w = court.shape[:2]
    return {f"courtyard {w}x{h}": court, f"random rows + sun {w}x{h}": rows}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", default=None, help="comma-separated --device specs; default the device iblbake picks")
    ap.add_argument("--samples", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=9)
    a = ap.parse_args()
    from iblbake.bake.radiance import to_rgba
    from iblbake.core.sampling import EnvironmentDistribution
    from iblbake.device.programs import kernel_source
    from iblbake.device.runtime import Runtime
    per_item = 64
    items = a.samples // per_item
    with tempfile.TemporaryDirectory() as tmp:
        panos = panoramas(Path(tmp))
    for spec in (a.devices.split(",") if a.devices else [None]):
        rt = Runtime(spec)
        src = kernel_source("envmap.h") + kernel_source("sampler.h", {"common.h", "inline.h", "layout.h"}) + SOURCE
        ks = {"uniforms": None}
        for v, edits in VARIANTS.items():
            text = src
            for old, new in edits:
                assert old in text, f"kernels/envmap.h changed: {old!r} not found"
                text = text.replace(old, new)
            prg = rt.cl.Program(rt.ctx, text).build(options=["-cl-std=CL1.2", *rt.device_options])
            ks[v] = rt.cl.Kernel(prg, "draw")
            ks["uniforms"] = ks["uniforms"] or rt.cl.Kernel(prg, "uniforms")
        out = rt.empty(items * 4)
        for name, img in panos.items():
            d = EnvironmentDistribution(img)
            args = [rt.to_device(to_rgba(img)), np.int32(d.width), np.int32(d.height), rt.to_device(d.marginal),
                    rt.to_device(d.conditional), rt.to_device(d.guide), d.norm, np.int32(per_item), out]
            times = {k: [] for k in ks}
            for rep in range(a.repeats + 1):
                for k, kern in ks.items():
                    t0 = time.perf_counter()
                    rt.run(kern, (items,), None, *args)
                    rt.finish()
                    if rep:                      # the first round warms up (PoCL specialises at first launch)
                        times[k].append(time.perf_counter() - t0)
            med = {k: statistics.median(v) for k, v in times.items()}
            ns = {v: (med[v] - med["uniforms"]) / (items * per_item) * 1e9 for v in VARIANTS}
            cols = "  ".join(f"{v} {ns[v]:5.1f} ns ({ns[v] / ns['guides']:.2f}x)" for v in VARIANTS)
            print(f"{rt.device_label[:24]:24s} {name:30s} {cols}  (a sample's wall time, all cores)", flush=True)


if __name__ == "__main__":
    main()
