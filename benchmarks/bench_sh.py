"""SH projection speed: OpenCL vs the numpy backend, and bandwidth vs a plain numpy.sum.

Prints, measured in one run (medians of 9): decode time of the example panorama, the projection
time per size and band count, its effective bandwidth (bytes of the float32 RGB image / time)
next to numpy.sum over the same array, and the OpenCL/numpy speed ratio.
Targets (issue 2): OpenCL at bands=3 reaches >= 50% of numpy.sum's bandwidth at 4096x2048;
bands=8 costs < 3x bands=3.
"""

import statistics
import sys
import time
from pathlib import Path

import numpy as np

from iblbake.device import runtime as cl
from iblbake.io import images
from iblbake.core import sh
from iblbake.bake import sh as shbake


def median_time(fn, repeat=9):
    fn()  # warm-up: kernel build, caches
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main():
    rt = cl.Runtime()
    print(f"device: {rt.device_label}")
    src = Path(__file__).resolve().parents[1] / "examples" / "panoramas" / "city.exr"
    if src.exists():
        t = median_time(lambda: images.read_panorama(src), 3)
        print(f"decode city.exr 1024x512 (OpenImageIO, validation, sha256): {t * 1e3:.1f} ms (excluded below)")
    rng = np.random.default_rng(0)
    rows = []
    for w, h in ((1024, 512), (2048, 1024), (4096, 2048)):
        img = (rng.random((h, w, 3), dtype=np.float32) * 4).astype(np.float32)
        nbytes = img.nbytes
        for bands in (3, 8):
            # Paired runs: each OpenCL projection beside a numpy.sum of the same array, so both
            # see the same machine state; the ratio is the median of the pairs.
            shbake.project(img, bands, "opencl", rt)
            img.sum()
            t_cl, t_sum = [], []
            for _ in range(9):
                t0 = time.perf_counter()
                img.sum()
                t_sum.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                shbake.project(img, bands, "opencl", rt)
                t_cl.append(time.perf_counter() - t0)
            t_np = median_time(lambda: sh.project(img, bands), 3)
            tc, ts = statistics.median(t_cl), statistics.median(t_sum)
            pair = statistics.median(s_ / c_ for s_, c_ in zip(t_sum, t_cl))
            rows.append((w, h, bands, tc, t_np, nbytes / tc / 1e9, nbytes / ts / 1e9, t_np / tc, pair))
    print()
    print("| size | bands | OpenCL ms | numpy ms | OpenCL GB/s | numpy.sum GB/s | OpenCL / sum bandwidth (paired) | speed-up vs numpy |")
    print("|---|---|---|---|---|---|---|---|")
    for w, h, b, tc, tn, bw, bws, ratio, pair in rows:
        print(f"| {w}x{h} | {b} | {tc * 1e3:.1f} | {tn * 1e3:.1f} | {bw:.2f} | {bws:.2f} | {pair:.0%} | {ratio:.1f}x |")
    big = {r[2]: r for r in rows if r[0] == 4096}
    print()
    print(f"4096x2048: bands=3 at {big[3][8]:.0%} of numpy.sum bandwidth (median of paired runs; target >= 50%); "
          f"bands=8 costs {big[8][3] / big[3][3]:.2f}x bands=3 (target < 3x)")


if __name__ == "__main__":
    sys.exit(main())
