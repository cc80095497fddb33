"""The angle functions of a path on a device, each against what it replaced: kernels/common.h
cossin_2pi (cospi and sinpi of 2t, whose argument reduction is exact) against cos and sin of the
float 2 pi t (a general argument reduction), the pair every warp of a path draws (the BSDF's
azimuth, the environment's, a light cone's); and equirect_uv_from_dir (atan2pi, acospi) against
atan2 and acos scaled by 1 / pi, what every escaped ray and chain lookup maps. Nanoseconds a call
(wall time over all cores; 2^20 calls, median of 7 after a warm-up, the random numbers' own cost
subtracted). docs/benchmarks.md "The environment's tables in the
cache" quotes it.

    .venv/bin/python benchmarks/bench_trig.py --devices pocl,intel-cpu
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

SOURCE = r"""
IBL_INLINE float uniform(int i) { return (pcg_hash((uint)i) >> 8) * (1.0f / 16777216.0f); }
__kernel void uniforms(const int n, __global float *out)
{
    float acc = 0.0f;
    for (int s = 0; s < n; ++s) acc += uniform(get_global_id(0) * n + s);
    out[get_global_id(0)] = acc;
}
__kernel void cossin_pi(const int n, __global float *out)
{
    float acc = 0.0f;
    for (int s = 0; s < n; ++s) {
        const float2 cs = cossin_2pi(uniform(get_global_id(0) * n + s));
        acc += cs.x + 1.3f * cs.y;
    }
    out[get_global_id(0)] = acc;
}
__kernel void uv_pi(const int n, __global float *out)
{
    float acc = 0.0f;
    for (int s = 0; s < n; ++s) {
        const int i = 3 * (get_global_id(0) * n + s);
        const float2 uv = equirect_uv_from_dir((float3)(uniform(i), uniform(i + 1), uniform(i + 2)) * 2.0f - 1.0f);
        acc += uv.x + 1.3f * uv.y;
    }
    out[get_global_id(0)] = acc;
}
__kernel void uv_atan2(const int n, __global float *out)     /* equirect_uv_from_dir before */
{
    float acc = 0.0f;
    for (int s = 0; s < n; ++s) {
        const int i = 3 * (get_global_id(0) * n + s);
        const float3 d = (float3)(uniform(i), uniform(i + 1), uniform(i + 2)) * 2.0f - 1.0f;
        float u = 0.5f - atan2(d.x, d.z) * (0.5f / IBL_PI);
        u = u - floor(u);
        acc += u + 1.3f * acos(clamp(d.y, -1.0f, 1.0f)) * (1.0f / IBL_PI);
    }
    out[get_global_id(0)] = acc;
}
__kernel void uniforms3(const int n, __global float *out)
{
    float acc = 0.0f;
    for (int s = 0; s < n; ++s) {
        const int i = 3 * (get_global_id(0) * n + s);
        acc += dot((float3)(uniform(i), uniform(i + 1), uniform(i + 2)) * 2.0f - 1.0f, (float3)(1.0f, 1.3f, 0.7f));
    }
    out[get_global_id(0)] = acc;
}
__kernel void cos_sin(const int n, __global float *out)
{
    float acc = 0.0f;
    for (int s = 0; s < n; ++s) {
        const float phi = 2.0f * IBL_PI * uniform(get_global_id(0) * n + s);
        acc += cos(phi) + 1.3f * sin(phi);
    }
    out[get_global_id(0)] = acc;
}
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", default=None, help="comma-separated --device specs; default the device iblbake picks")
    a = ap.parse_args()
    from iblbake.device.programs import kernel_source
    from iblbake.device.runtime import Runtime
    per_item, items = 64, (1 << 20) // 64
    for spec in (a.devices.split(",") if a.devices else [None]):
        rt = Runtime(spec)
        src = kernel_source(("common.h", "sampler.h")) + SOURCE
        prg = rt.cl.Program(rt.ctx, src).build(options=["-cl-std=CL1.2", *rt.device_options])
        ks = {k: rt.cl.Kernel(prg, k) for k in ("uniforms", "cossin_pi", "cos_sin", "uniforms3", "uv_pi", "uv_atan2")}
        out = rt.empty(items * 4)
        times = {k: [] for k in ks}
        for rep in range(8):
            for k, kern in ks.items():
                t0 = time.perf_counter()
                rt.run(kern, (items,), None, np.int32(per_item), out)
                rt.finish()
                if rep:
                    times[k].append(time.perf_counter() - t0)
        med = {k: statistics.median(v) for k, v in times.items()}
        ns = {k: (med[k] - med[base]) / (items * per_item) * 1e9
              for k, base in (("cossin_pi", "uniforms"), ("cos_sin", "uniforms"), ("uv_pi", "uniforms3"),
                              ("uv_atan2", "uniforms3"))}
        print(f"{rt.device_label[:40]:40s} cossin_2pi {ns['cossin_pi']:6.2f} ns  cos, sin {ns['cos_sin']:6.2f} ns "
              f"({ns['cos_sin'] / max(ns['cossin_pi'], 1e-3):.1f}x)  equirect_uv_from_dir {ns['uv_pi']:6.2f} ns  "
              f"atan2, acos {ns['uv_atan2']:6.2f} ns ({ns['uv_atan2'] / max(ns['uv_pi'], 1e-3):.1f}x)", flush=True)


if __name__ == "__main__":
    main()
