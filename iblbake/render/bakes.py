"""What the passes read, loaded once: the panorama and its bakes (sh, radiance, prefiltered, dfg,
env_cdf), through the content-addressed cache, and kept in memory by content so that a caller
rendering many frames (a sheet) reads and uploads nothing twice."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from iblbake.bake import cache, layouts
from iblbake.bake import mips as mipsbake
from iblbake.bake import sh as bake_sh
from iblbake.core import sampling
from iblbake.errors import IblbakeError
from iblbake.io import images

POLICY_KEYS = {"nonfinite": "environment.nonfinite:", "negative": "environment.negative:"}


class Bakes:
    """The bake cache folder plus an in-memory memo of loaded bakes, keyed by content."""

    def __init__(self, root: Path | None = None):
        self.root = Path(root) if root else cache.default_root()
        self._memo: dict = {}

    def _get(self, key, make):
        for attempt in range(3):
            if key in self._memo:
                break
            try:
                self._memo[key] = make()
            except (IblbakeError, OSError) as e:
                # a prune in another process took the entry between its check and this read: the
                # next check finds it gone and bakes it again (an error naming no cache file is real)
                if attempt == 2 or str(self.root) not in str(e):
                    raise
        return self._memo[key]

    def environment(self, env: dict):
        """(image, info), read once per file content (path, size, mtime) and policies."""
        st = os.stat(env["path"])
        key = ("env", env["path"], st.st_size, st.st_mtime_ns, env["nonfinite"], env["negative"])
        return self._get(key, lambda: images.read_panorama(env["path"], nonfinite=env["nonfinite"],
                                                           negative=env["negative"], names=POLICY_KEYS))

    def chain(self, rt, levels) -> dict:
        """The device tables of a chain of levels (chain_table), uploaded once per runtime."""
        return self._get(("chain", id(rt), tuple(id(lv) for lv in levels)), lambda: chain_table(rt, levels))

    def load(self, name: str, ctx) -> tuple:
        """(value, cached, report fields) of bake `name` for the context's scene."""
        return getattr(self, f"_{name}")(ctx)

    def _policies(self, env):
        return {"nonfinite": env["nonfinite"], "negative": env["negative"]}

    def _sh(self, ctx):
        fx, env = ctx.scene.data["effects"], ctx.scene.data["environment"]
        image, info = self.environment(env)
        bands, window = fx["sh_bands"], fx["sh_window"]
        key = ("sh", info.sha256, bands, window, env["nonfinite"], env["negative"])
        hit = key in self._memo
        coeffs, manifest, cached = self._get(key, lambda: bake_sh.bake_irradiance(
            ctx.rt, image, info, self.root, self._policies(env), bands, window, warn=ctx.warn))
        return coeffs, cached or hit, {"bands": bands, "entry": str(self.root / manifest["key"])}

    def _baker(self, ctx):
        return self._get(("baker", id(ctx.rt)), lambda: mipsbake.Baker("opencl", rt=ctx.rt))

    def _radiance(self, ctx):
        env = ctx.scene.data["environment"]
        image, info = self.environment(env)
        key = ("radiance", info.sha256, env["nonfinite"], env["negative"])
        hit = key in self._memo

        def make():
            manifest, cached, levels = mipsbake.bake_radiance(self._baker(ctx), image, info, self.root,
                                                              self._policies(env), warn=ctx.warn)
            return (levels if levels is not None else mipsbake.load_chain(self.root, manifest)), manifest, cached

        chain, manifest, cached = self._get(key, make)
        return chain, cached or hit, {"levels": len(chain), "entry": str(self.root / manifest["key"])}

    def _prefiltered(self, ctx):
        p, env = ctx.scene.data["effects"]["prefilter"], ctx.scene.data["environment"]
        image, info = self.environment(env)
        opts = mipsbake.PrefilterOptions("equirect", p["size"], p["levels"], layouts.MIN_LEVEL_SIZE, p["method"],
                                         p["samples"], p["lod_bias"], True).resolved(info.height)
        opts["method_name"] = "effects.prefilter.method:"
        key = ("prefiltered", info.sha256, env["nonfinite"], env["negative"],
               tuple(sorted((k, str(v)) for k, v in opts.items())))
        hit = key in self._memo
        baker = self._baker(ctx)

        def chain_levels():       # the radiance chain in memory only: no radiance entry of its own
            rkey = ("radiance", info.sha256, env["nonfinite"], env["negative"])
            return self._memo[rkey][0] if rkey in self._memo else baker.radiance_chain(image)

        def make():
            pm, cached = mipsbake.bake_prefiltered(baker, chain_levels, info, self.root, self._policies(env),
                                                   opts, warn=ctx.warn)
            levels = [images.read_exr(self.root / pm["key"] / f["name"])[..., :3] for f in pm["files"]]
            return levels, pm, cached

        levels, pm, cached = self._get(key, make)
        return levels, cached or hit, {"levels": len(levels), "methods": [f["method"] for f in pm["files"]],
                                       "entry": str(self.root / pm["key"])}

    def _dfg(self, ctx):
        p = ctx.scene.data["effects"]["prefilter"]
        key = ("dfg", p["dfg_size"], p["dfg_samples"])
        hit = key in self._memo

        def make():
            dm, cached = mipsbake.bake_dfg(self._baker(ctx), self.root, p["dfg_size"], p["dfg_samples"], False,
                                           warn=ctx.warn)
            return images.read_exr(self.root / dm["key"] / "dfg.exr")[..., :2], dm, cached

        table, dm, cached = self._get(key, make)
        return table, cached or hit, {"size": p["dfg_size"], "entry": str(self.root / dm["key"])}

    def _env_cdf(self, ctx):
        env = ctx.scene.data["environment"]
        image, info = self.environment(env)
        key = ("env_cdf", info.sha256, env["nonfinite"], env["negative"])
        hit = key in self._memo
        return self._get(key, lambda: sampling.EnvironmentDistribution(image)), hit, {}


def load_all(ctx, names) -> dict:
    """Every named bake, timed into the context's report."""
    out = {}
    for name in names:
        t0 = time.perf_counter()
        value, cached, extra = ctx.bakes.load(name, ctx)
        ctx.report.bake(name, time.perf_counter() - t0, cached, **extra)
        out[name] = value
    return out


def chain_table(rt, levels) -> dict:
    """One buffer of levels back to back (RGBA) and the offset/size tables chain_lookup reads,
    as the named kernel arguments chain, off, lw, lh, nlev."""
    from iblbake.bake.radiance import to_rgba

    offs, lws, lhs, parts = [], [], [], []
    o = 0
    for lvl in levels:
        h, w = lvl.shape[:2]
        offs.append(o)
        lws.append(w)
        lhs.append(h)
        parts.append(to_rgba(lvl).reshape(-1, 4))
        o += w * h
    data = np.concatenate(parts).astype(np.float32)
    off, lw, lh = (rt.to_device(np.asarray(x, np.int32)) for x in (offs, lws, lhs))
    return {"chain": rt.to_device(data), "off": off, "lw": lw, "lh": lh, "nlev": len(levels)}
