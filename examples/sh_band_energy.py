"""Bake SH for every panorama in a folder and plot each one's energy per band: how much of its
lighting lies above the 9 coefficients engines keep (a sharp sun spreads over every band; an
overcast sky stays in the first two).

    python examples/sh_band_energy.py examples/panoramas -o bands.png [--bands 8]

A notebook-sized use of the library (docs/api.md): load_panorama, sh, numpy.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

import iblbake

SUFFIXES = (".exr", ".hdr", ".pfm", ".tif", ".tiff")
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])          # Rec.709


def band_energy(coeffs: iblbake.SH) -> np.ndarray:
    """(bands,) each band's share of the radiance's energy: sum over m of L_lm^2 of the
    luminance (orthonormal SH: the squared norm over the sphere, Parseval), divided by the sum."""
    lum = coeffs.radiance @ LUMINANCE
    energy = np.array([np.sum(lum[l * l:(l + 1) ** 2] ** 2) for l in range(coeffs.bands)])
    return energy / energy.sum()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("-o", "--output", type=Path, default=Path("sh_band_energy.png"))
    ap.add_argument("--bands", type=int, default=8)
    args = ap.parse_args(argv)
    paths = sorted(p for p in args.folder.iterdir() if p.suffix.lower() in SUFFIXES)
    if not paths:
        print(f"{args.folder}: no panoramas ({', '.join(SUFFIXES)})", file=sys.stderr)
        return 1
    shares = {}
    for path in paths:
        try:
            coeffs = iblbake.sh(iblbake.load_panorama(path), bands=args.bands, error=False)
        except iblbake.Error as e:
            print(f"Error: {e}", file=sys.stderr)
            return 1
        shares[path.stem] = band_energy(coeffs)
        above = shares[path.stem][3:].sum()
        print(f"{path.stem}: {100 * above:.2f}% of the energy above band 2")

    import matplotlib                      # only here: the library never imports it
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for name, share in shares.items():
        ax.semilogy(range(args.bands), np.maximum(share, 1e-12), marker="o", label=name)
    ax.axvline(2.5, color="0.6", linestyle="--", linewidth=1)
    ax.text(2.6, 0.5, "engines keep l <= 2", color="0.4", transform=ax.get_xaxis_transform())
    ax.set_xlabel("band l")
    ax.set_ylabel("share of the luminance energy")
    ax.set_title("SH band energy per panorama")
    ax.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(args.output, dpi=100)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
