"""Accuracy against time for the GGX-prefiltered chain and the DFG table (issue 3).

For a cubemap chain from a 1024x512 panorama (city by default: the hardest case, a 34,000 sun),
at each face size and method, prints the bake time (median of 3, kernels built and radiance
chain resident beforehand) and the relative RMSE of every level against a float64 brute-force
reference (every source texel, split into parts smaller than the lobe, exact solid angles)
evaluated at a random subset of texels per level (the whole level would cost ~1e11 weight
evaluations at face 256), and what packing that chain as KTX2 costs against its bake. Then the
DFG table's error against a 65,536-sample table.

    python benchmarks/bench_mips.py [--env city] [--sizes 128 256] [--levels 9] [--texels 96]
"""

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from iblbake.io import images, ktx2
from iblbake.bake import layouts
from iblbake.bake import mips as mipsbake

ROOT = Path(__file__).resolve().parents[1]
# cmft (its own command-line tool, measured on this kind of machine): radiance chain, cube face -> seconds on this machine's 2 threads; the
# issue's targets are a tenth of the face-256 time with every level under 1%, face 512 under 2 s
CMFT_SECONDS = {256: 4.2, 512: 61.0}
TARGET_SECONDS = {256: 0.42, 512: 2.0}


def median_time(fn, repeat=3):
    out = fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--env", default="city")
    ap.add_argument("--sizes", type=int, nargs="+", default=[128, 256])
    ap.add_argument("--levels", type=int, default=9)
    ap.add_argument("--samples", type=int, nargs="+", default=[16, 64, 256, 1024])
    ap.add_argument("--texels", type=int, default=96, help="reference texels per level")
    ap.add_argument("--no-dfg", action="store_true")
    args = ap.parse_args(argv)

    baker = mipsbake.Baker("opencl")
    print(f"device: {baker.device_label}")
    img, _ = images.read_panorama(ROOT / "examples" / "panoramas" / f"{args.env}.exr")
    t_chain, chain = median_time(lambda: baker.radiance_chain(img))
    print(f"panorama {args.env}.exr {img.shape[1]}x{img.shape[0]}; radiance chain ({len(chain)} levels): "
          f"{t_chain * 1e3:.1f} ms")
    src = img.astype(np.float64)

    for face in args.sizes:
        opts_base = dict(layout="cubemap", size=face, levels=args.levels, min_size=1)
        sizes = layouts.prefiltered_sizes(face, args.levels, 1)
        rough = layouts.level_roughness(args.levels)
        # reference at a random subset of texels of each level (what `iblbake mips --verify` measures)
        t0 = time.perf_counter()
        picks = mipsbake.verification_texels(src, "cubemap", sizes, rough, args.texels)
        t_ref = time.perf_counter() - t0
        print(f"\ncubemap face {face}, {args.levels} levels (r = k/{args.levels - 1}); brute-force reference at "
              f"{args.texels} texels per level took {t_ref:.0f} s")
        configs = [("auto (default)", dict(method="auto", samples=mipsbake.DEFAULT_SAMPLES))]
        configs += [("spectral", dict(method="spectral"))]
        configs += [(f"fis N={n}", dict(method="fis", samples=n)) for n in args.samples]
        configs += [(f"no-fis N={n}", dict(method="fis", samples=n, fis=False)) for n in args.samples[-2:]]
        if face <= 128 or baker.rt.info.kind == "GPU":
            configs.append(("convolve", dict(method="convolve")))
        print("| method | bake s (median of 3) | rel. RMSE per level (r = 0 .. 1) | worst level |")
        print("|---|---|---|---|")
        for label, kw in configs:
            opts = mipsbake.PrefilterOptions(**{**opts_base, **kw}).resolved(img.shape[0])
            t, (levels, methods) = median_time(lambda: baker.prefilter(chain, opts))
            errs = mipsbake.level_errors(levels, picks)
            how = "" if kw["method"] != "auto" else " [" + " ".join(m[0] + m.split("@")[-1] * ("@" in m) for m in methods) + "]"
            print(f"| {label}{how} | {t:.3f} | {' '.join(f'{e:.2%}' for e in errs)} | {max(errs):.2%} |")
            if kw["method"] == "auto":
                auto = (t, max(errs))
                auto_levels = levels
        if face in CMFT_SECONDS:
            t, worst = auto
            ok = t <= TARGET_SECONDS[face] and worst < 0.01
            print(f"\ndefault chain at face {face}: {t:.3f} s = 1/{CMFT_SECONDS[face] / t:.0f} of cmft's "
                  f"{CMFT_SECONDS[face]:g} s (target <= {TARGET_SECONDS[face]:g} s), worst level {worst:.2%} "
                  f"(target < 1%): {'met' if ok else 'NOT met'}")
        if sizes == [max(1, face >> k) for k in range(len(sizes))]:      # a mip chain: what KTX2 stores
            cube = [lv.reshape(6, sz, sz, 3) for lv, sz in zip(auto_levels, sizes)]
            rows = []
            for fmt in ktx2.FORMATS:
                tk, data = median_time(lambda: ktx2.cube_bytes(cube, fmt))
                rows.append(f"{fmt} {tk * 1e3:.0f} ms ({len(data) / 2**20:.1f} MiB, {100 * tk / auto[0]:.1f}% of the bake)")
            print(f"KTX2 export of the face-{face} chain (mips --ktx2; target <= 10% of the bake): " + ", ".join(rows))
    print("\n(auto: per level r = resample, s = spectral, cT = convolve at T texels per lobe scale, f = fis)")

    # cube-map input (a cross, strip, faces or KTX2 cube resampled to equirect by exact overlaps):
    # the target is face 1024 in 0.5 s on 2 cores
    from iblbake.bake import cube_resample
    rows = []
    for face in (256, 1024):
        faces = np.random.default_rng(0).random((6, face, face, 3), dtype=np.float32)
        t_face, _ = median_time(lambda: cube_resample.cube_to_equirect_cl(baker.rt, faces), repeat=5)
        rows.append(f"face {face} {t_face:.2f} s")
    t, _ = median_time(lambda: cube_resample.cube_to_equirect(np.random.default_rng(0).random((6, 64, 64, 3))),
                       repeat=1)
    print(f"\ncube-map input resampled to equirect (exact overlaps, {baker.device_label}, median of 5): "
          f"{', '.join(rows)}; the float64 twin (plain Python) at face 64 {t:.2f} s (target: face 1024 <= 0.5 s: "
          f"{'met' if t_face <= 0.5 else 'NOT met'})")

    if not args.no_dfg:
        gpu = baker.gpu
        ref = gpu.dfg(128, 65536)
        print("\nDFG 128x128 against 65,536 samples")
        print("| samples | bake ms (median of 3) | max abs error | RMS error |")
        print("|---|---|---|---|")
        for n in (64, 256, 1024, 4096):
            t, tab = median_time(lambda: gpu.dfg(128, n))
            print(f"| {n} | {t * 1e3:.1f} | {np.abs(tab - ref).max():.4f} | {np.sqrt(np.mean((tab - ref) ** 2)):.5f} |")


if __name__ == "__main__":
    sys.exit(main())
