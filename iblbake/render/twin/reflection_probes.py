"""Local reflection probes (kernels/reflection_probes.h): each probe's fade, the parallax-corrected
direction and the blend with the distant chain. numpy twin, float64."""

from __future__ import annotations

import numpy as np

from iblbake.bake import radiance


def weight(st: dict, p):
    """Twin of rprobe_weight for points p (m, 3) and one probe's settings."""
    if st["shape"] == "box":
        lo, hi = np.asarray(st["min"], np.float64), np.asarray(st["max"], np.float64)
        half = 0.5 * (hi - lo)
        over = ((np.abs(p - 0.5 * (lo + hi)) - half) / half).max(-1)
    else:
        over = np.linalg.norm(p - np.asarray(st["position"]), axis=-1) / st["radius"] - 1
    fade = np.maximum(1 - over / st["blend"], 0.0) if st["blend"] > 0 else np.zeros_like(over)
    return np.where(over <= 0, 1.0, fade)


def direction(st: dict, p, r):
    """Twin of rprobe_direction: towards where p + t r leaves the proxy, from the probe."""
    d = exit_point(st, p, r) - np.asarray(st["position"], np.float64)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def exit_point(st: dict, p, r):
    """Twin of rprobe_exit: where p + t r leaves the probe's box or sphere."""
    pos = np.asarray(st["position"], np.float64)
    if st["shape"] == "box":
        lo, hi = np.asarray(st["min"], np.float64), np.asarray(st["max"], np.float64)
        far = np.where(r > 0, hi, lo)
        with np.errstate(divide="ignore", invalid="ignore"):
            tt = np.where(r != 0, (far - p) / np.where(r != 0, r, 1), np.inf)
        t = tt.min(-1)
    else:
        o = p - pos
        b = (o * r).sum(-1)
        c = (o * o).sum(-1) - st["radius"] ** 2
        t = -b + np.sqrt(np.maximum(b * b - c, 0.0))
    return p + np.maximum(t, 0.0)[:, None] * r


def blend(captured: list, p, r, lod, distant):
    """Twin of reflection_probes: captured [{settings, levels, coverage}], distant the scaled
    distant chain's radiance at (p, r) (m, 3), which also fills each capture's uncovered share."""
    acc = np.zeros_like(distant)
    wsum = np.zeros(len(p))
    for c in captured:
        st = c["settings"]
        w = weight(st, p)
        d = direction(st, p, r) if st["parallax"] else r
        cover = radiance.chain_lookup_twin(c["coverage"], d, lod)[:, :1]
        acc += w[:, None] * (radiance.chain_lookup_twin(c["levels"], d, lod) + (1 - cover) * distant)
        wsum += w
    over = wsum > 1
    out = acc + (1 - wsum)[:, None] * distant
    return np.where(over[:, None], acc / np.where(over, wsum, 1)[:, None], out)
