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

    manifest, cached = cache.get_or_build(root, key, build, warn=warn)
    path = root / manifest["key"] / "coefficients.json"
    doc = json.loads(reads.read_text(path, reads.JSON_BYTES, "a cached basis document"))
    try:
        coeffs = m.validate(doc.get("coefficients"), opts)
    except (ValueError, TypeError) as e:
        raise IblbakeError(f"{path}: {e}; delete the cache entry to bake it again") from None
    return coeffs, manifest, cached
