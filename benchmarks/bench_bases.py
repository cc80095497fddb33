"""The directional bases' shoot-out (issue 45): for every registered basis and size
(iblbake/core/bases/) on every example panorama, the diffuse irradiance against the exact float64
cosine convolution of the panorama (bake/sh.py exact_irradiance: every texel, exact solid angles)
at 4096 Fibonacci normals, in luminance: relative RMSE and the largest relative error of a
normal (floor 1e-3 of the mean, as `iblbake sh`'s error block); bytes per probe (floats x 3
channels, fp16 and fp32, and Haar's 2-byte index per kept coefficient: core/bases probe_bytes);
projection time (the float64 twin, 1024 x 512, median of 3) and
evaluation time (the kernel header on the OpenCL device, ns per normal over 2^16 normals).

Prints a markdown table and writes the error-against-bytes plot (one curve per basis family) to
docs/images/bases_error_bytes.png (matplotlib, imported here only). Run: .venv/bin/python
benchmarks/bench_bases.py [--plot PATH] [--panoramas a,b,...] [--bases sh,sg,...] (a subset of the
bases: its rows alone, and the plot of them)."""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from iblbake.bake import sh as bake_sh
from iblbake.core import sh as core_sh
from iblbake.core.bases import BASES, probe_bytes
from iblbake.core.metrics import LUMINANCE
from iblbake.device import runtime as cl
from iblbake.io import images

ROOT = Path(__file__).resolve().parents[1]
NORMALS = 4096
EVAL_NORMALS = 1 << 16


def median_time(fn, repeat=3):
    fn()
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def errors(approx, exact):
    la, le = approx @ LUMINANCE, exact @ LUMINANCE
    floor = 1e-3 * max(float(le.mean()), 1e-300)
    rmse = float(np.sqrt(np.mean((la - le) ** 2)) / np.sqrt(np.mean(le ** 2)))
    return rmse, float((np.abs(la - le) / (le + floor)).max())


def eval_seconds(rt, name, opts, coeffs, normals_dev, out):
    """The kernel's evaluation of the basis at EVAL_NORMALS normals (median of 5)."""
    m = BASES[name]
    if m.HEADER is None:              # SH: the shade pass's sh_irradiance (kernels/sh.h)
        b = opts["sh_bands"]
        e = coeffs * core_sh.ahat(b)[:, None]
        packed = np.pad(e[:, :3], ((0, 0), (0, 1))).astype(np.float32)
        k = rt.kernel("selftest.cl", "t_sh_irradiance", {"SH_BANDS": b})
    else:
        packed = m.pack(coeffs, opts)
        k = rt.kernel("selftest.cl", "t_basis_irradiance", m.defines(opts))
    buf = rt.to_device(packed)

    def go():
        rt.run(k, (EVAL_NORMALS,), None, buf, normals_dev, out)
        rt.queue.finish()
    return median_time(go, 5)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--plot", default=str(ROOT / "docs" / "images" / "bases_error_bytes.png"))
    ap.add_argument("--panoramas", default="city,courtyard,forest,interior,night,studio,sunrise,sunset")
    ap.add_argument("--bases", default=",".join(BASES), help="the registered bases to measure (core/bases BASES)")
    args = ap.parse_args()
    rt = cl.Runtime()
    print(f"device: {rt.device_label}")
    names = args.panoramas.split(",")
    pans = {n: np.asarray(images.read_exr(ROOT / "examples" / "panoramas" / f"{n}.exr"))[..., :3].astype(np.float64)
            for n in names}
    normals = bake_sh.fibonacci_normals(NORMALS)
    exact = {n: bake_sh.exact_irradiance(img, normals) for n, img in pans.items()}
    rng = np.random.default_rng(0)
    ev = rng.normal(size=(EVAL_NORMALS, 3))
    ev /= np.linalg.norm(ev, axis=1, keepdims=True)
    ev_dev = rt.to_device(ev.astype(np.float32))
    out = rt.empty(EVAL_NORMALS * 3 * 4)
    rows = []
    for name in args.bases.split(","):
        m = BASES[name]
        for opts in m.variants():
            rmse, mx, proj = {}, {}, []
            coeffs = None
            for pn, img in pans.items():
                c = m.project(img, opts)
                rmse[pn], mx[pn] = errors(m.irradiance(c, normals, opts), exact[pn])
                coeffs = c if coeffs is None else coeffs
            proj = median_time(lambda: m.project(pans[names[0]], opts))
            ev_s = eval_seconds(rt, name, opts, coeffs, ev_dev, out)
            rows.append({"label": m.label(opts), "family": family(name, opts), "floats": m.floats(opts),
                         "bytes": (probe_bytes(name, opts, 2), probe_bytes(name, opts, 4)),
                         "rmse": rmse, "max": mx, "project_ms": proj * 1e3, "eval_ns": ev_s / EVAL_NORMALS * 1e9})
    print_table(rows, names)
    plot(rows, args.plot)


def family(name, opts):
    if name == "sh":
        return "SH" + ("" if opts["sh_window"] == "none" else f" {opts['sh_window']}")
    fit = opts.get("sg_fit", opts.get("ad_fit"))
    if fit:         # sg, ambient dice: a curve per fit (irradiance, radiance LS, radiance NNLS)
        return f"{BASES[name].TITLE} " + {"irradiance": "irradiance", "least_squares": "LS", "nnls": "NNLS"}[fit]
    return BASES[name].TITLE


def print_table(rows, names):
    head = ["basis", "floats/ch", "bytes fp16 (fp32)"] + [f"{n} rRMSE %" for n in names] + \
        ["mean rRMSE %", "worst max rel. %", "project ms", "eval ns/normal"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in rows:
        cells = [r["label"], str(r["floats"]), f"{r['bytes'][0]} ({r['bytes'][1]})"]
        cells += [f"{100 * r['rmse'][n]:.2f}" for n in names]
        cells += [f"{100 * np.mean(list(r['rmse'].values())):.2f}", f"{100 * max(r['max'].values()):.1f}",
                  f"{r['project_ms']:.1f}", f"{r['eval_ns']:.2f}"]
        print("| " + " | ".join(cells) + " |")


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    fams = list(dict.fromkeys(r["family"] for r in rows))
    for i, f in enumerate(fams):       # tab20: a colour each for more families than the default 10
        pts = sorted((r["bytes"][0], 100 * np.mean(list(r["rmse"].values()))) for r in rows if r["family"] == f)
        x, y = zip(*pts)
        ax.plot(x, y, "o-", label=f, color=plt.cm.tab20(i % 20))
    ax.set_xscale("log")
    ax.set_xlabel("bytes per probe (fp16 RGB; Haar: and its indices)")
    ax.set_ylabel("diffuse irradiance relative RMSE, % (mean of panoramas)")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Directional bases: diffuse error against bytes (8 panoramas)")
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"plot: {path}")


if __name__ == "__main__":
    main()
