"""The cached projection of the panorama onto the scene's directional basis (core/bases/), the
renderer's `basis` bake: float64 on the host (the twin itself), stored as coefficients.json in a
cache entry keyed by the input's content, the basis, its options, the read policies and the
basis code, and checked by the basis's own validate when read back."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

VERSION = 1


def code_hash(module) -> str:
    import hashlib
    import inspect

    from iblbake.core import sh as core_sh
    from iblbake.core.bases import common
    src = "".join(inspect.getsource(m) for m in (module, common, core_sh))
    return hashlib.sha256(src.encode()).hexdigest()[:16]


def bake(image, info, root, policies: dict, name: str, opts: dict, warn=None):
    """(coefficients (floats, C), manifest, cached) of basis `name` with `opts`."""
    from iblbake.bake import cache
    from iblbake.core.bases import BASES
    from iblbake.errors import IblbakeError
    from iblbake.io import reads
    from iblbake.io.atomic import write_json

    m = BASES[name]
    root = Path(root)
    key = f"basis-{name}-" + cache.content_key({"kind": "basis", "v": VERSION, "basis": name, "options": opts,
                                                 "input": info.sha256, "policies": policies, "code": code_hash(m)})

    def build(tmp: Path):
        t0 = time.perf_counter()
        c = m.project(np.asarray(image)[..., :3], opts)
        # rows of per-channel values in the order docs/conventions.md "Directional bases" gives
        write_json(tmp / "coefficients.json", {"basis": name, "options": opts, "coefficients": c.tolist()})
        return {"kind": "basis", "files": [{"name": "coefficients.json"}], "parameters": {"basis": name, **opts,
                **policies}, "input": info.to_json(), "project_s": round(time.perf_counter() - t0, 4)}

    def read(manifest):
        path = root / manifest["key"] / "coefficients.json"
        doc = json.loads(reads.read_text(path, reads.JSON_BYTES, "a cached basis document"))
        try:
            return m.validate(doc.get("coefficients"), opts)
        except (ValueError, TypeError) as e:
            raise IblbakeError(f"{path}: {e}") from None

    coeffs, manifest, cached = cache.get_checked(root, key, build, read, warn=warn)
    return coeffs, manifest, cached


FORMAT = "iblbake.basis"
FORMAT_VERSION = 1


def layout_text(name: str) -> str:
    """The basis module's "Layout:" paragraph: what its coefficient rows hold."""
    from iblbake.core.bases import BASES
    return " ".join(BASES[name].__doc__.split("Layout:")[1].split())


def document(coeffs, *, name: str, opts: dict, info, options: dict, timings: dict) -> dict:
    """The JSON document `iblbake basis` writes (format iblbake.basis, version 1): the basis, its
    options and layout, the radiance coefficients as rows (R, G, B[, index]) in the world frame,
    the bytes a probe of it takes, the input and the read options."""
    from iblbake.core import bases
    m = bases.BASES[name]
    c = np.asarray(coeffs, np.float64)
    return {"format": FORMAT, "format_version": FORMAT_VERSION, "basis": name, "title": m.TITLE,
            "label": m.label(opts), "options": opts, "floats": m.floats(opts),
            "bytes": {"fp16": bases.probe_bytes(name, opts, 2), "fp32": bases.probe_bytes(name, opts, 4)},
            "specular": name in bases.SPECULAR,
            "layout": layout_text(name), "frame": "world, +y up (docs/conventions.md 'Space and directions')",
            "irradiance": "docs/conventions.md 'Directional bases': E(n) = int L max(0, n.w) dw, clamped at 0",
            "coefficients": [[float(v) for v in row] for row in c],
            **(m.document_fields(opts) if hasattr(m, "document_fields") else {}),
            "input": info.to_json(), "options_read": options, "timings": timings}


def irradiance_error(image, name: str, opts: dict, coeffs, intensity: float = 1.0) -> dict:
    """The basis's irradiance against the exact irradiance at the 256 fixed normals, in luminance,
    as `iblbake sh`'s error block (bake/sh.py irradiance_error)."""
    from iblbake.bake import sh as shbake
    from iblbake.core import bases
    from iblbake.core.metrics import LUMINANCE, relative_rmse
    img = np.asarray(image)
    normals = shbake.fibonacci_normals()
    exact = shbake.exact_irradiance((img[..., :3] @ LUMINANCE.astype(img.dtype))[..., None], normals)[:, 0] * intensity
    approx = bases.BASES[name].irradiance(coeffs, normals, opts)[:, :3] @ LUMINANCE
    floor = 1e-3 * max(float(exact.mean()), 1e-300)
    return {"normals": len(normals), "metric": "luminance",
            "against": "sum over every texel of L max(0, n.d) dOmega, float64",
            "relative_rmse": relative_rmse(approx, exact),
            "max_relative_error": float((np.abs(approx - exact) / (exact + floor)).max())}
