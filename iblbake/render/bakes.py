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

def _code_hash(modules, extra: str = "") -> str:
    """The modules' source (and `extra`: a kernel's source hash): a cached bake is rebuilt when its
    code changes."""
    import hashlib
    import inspect
    return hashlib.sha256(("".join(inspect.getsource(m) for m in modules) + extra).encode()).hexdigest()[:16]


def _geometry_code_hash() -> str:
    """The mesh loader's and BVH builder's source: a cached BVH is rebuilt when they change."""
    from iblbake.scene import geometry, gltf, pack, tangents
    return _code_hash((geometry, gltf, pack, tangents))


def _textures_code_hash() -> str:
    """The texture decoder's, pyramid builder's and glTF reader's source: cached pyramids are
    rebuilt when they change."""
    from iblbake.scene import gltf, materials, textures
    return _code_hash((gltf, materials, textures))


def _probes_code_hash() -> str:
    """The probe bakers' and their tracing kernel's source: cached volumes and captures are rebaked
    when they change (every module of the render/probes package)."""
    import importlib
    import pkgutil

    from iblbake.core import bases
    from iblbake.core.bases import common
    from iblbake.device.runtime import source_hash
    from iblbake.render import probes, reflection_probes
    package = [importlib.import_module(f"{probes.__name__}.{m.name}")
               for m in sorted(pkgutil.iter_modules(probes.__path__), key=lambda m: m.name)]
    # the probe bases' fits too (core/bases project_rays)
    return _code_hash((probes, *package, reflection_probes, common, *(bases.BASES[n] for n in bases.PROBES)),
                      source_hash("probe_trace.cl"))


def _external(path) -> list:
    from iblbake.scene import gltf as gltf_file
    try:
        return gltf_file.external_files(path)
    except (OSError, IblbakeError):
        return []


def _map_refs(materials: dict) -> list:
    """The texture references (mappings with a path) anywhere in the scene's materials."""
    out = []

    def walk(v):
        if isinstance(v, dict):
            if isinstance(v.get("path"), str):
                out.append(v)
            for x in v.values():
                walk(x)
    walk(materials)
    return out


POLICY_KEYS = {"nonfinite": "environment.nonfinite:", "negative": "environment.negative:",
               "transfer": "environment.transfer:", "primaries": "environment.primaries:",
               "layout": "environment.layout:"}


class Bakes:
    """The bake cache folder plus an in-memory memo of loaded bakes, keyed by content."""

    def __init__(self, root: Path | None = None):
        self.root = Path(root) if root else cache.default_root()
        self._memo: dict = {}
        self.runtime = None          # the device a cube-map environment resamples on (render sets it)

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

    def file_sha256(self, path) -> str:
        """A file's content hash, computed once per (path, size, mtime) in this store: the cells of
        a sheet and the rungs of a study key on the same panorama and meshes, over and over."""
        st = os.stat(path)
        return self._get(("sha256", str(path), st.st_size, st.st_mtime_ns), lambda: images.file_sha256(path))

    def _recall(self, key, make):
        """(value, whether this store already held it): a bake counts as cached when it was."""
        held = key in self._memo
        return self._get(key, make), held

    def environment(self, env: dict):
        """(image, info), read once per file content (path, size, mtime) and policies. With
        `sun: extract`, the panorama without its sun, its info's hash that of what is left (every
        bake keys on it)."""
        key = self._env_key(env)
        from iblbake.bake import inputs
        image, info = self._get(key, lambda: inputs.read_environment(
            env["path"], layout=env["layout"], runtime=self.runtime, nonfinite=env["nonfinite"], negative=env["negative"],
            transfer=env["transfer"], primaries=env["primaries"], names=POLICY_KEYS))
        if env.get("sun") != "extract":
            return image, info
        return self._get(key + ("sun",), lambda: self._extract(image, info))[:2]

    @staticmethod
    def _env_key(env: dict) -> tuple:
        """A panorama file's content as far as a read can tell (path, size, mtime), and its policies."""
        st = os.stat(env["path"])
        return ("env", env["path"], st.st_size, st.st_mtime_ns, env["nonfinite"], env["negative"], env["transfer"],
                env["primaries"], env["layout"])

    def _extract(self, image, info):
        import dataclasses
        import hashlib

        from iblbake.bake import sun as sunbake
        residual, found = sunbake.extract(image)
        tag = hashlib.sha256(f"{info.sha256}:sun-extract:{sunbake.PEAK}:{sunbake.THRESHOLD}:{sunbake.RING}".encode())
        return residual, dataclasses.replace(info, sha256=tag.hexdigest()), found

    def sun(self, env: dict):
        """The extracted sun of the scene's panorama (bake/sun.py), or None."""
        if env.get("sun") != "extract":
            return None
        self.environment(env)
        return self._memo[self._env_key(env) + ("sun",)][2]

    def geometry(self, sc, warn=None):
        """The scene's device records; its meshes' triangles, BVH and triangle attributes from the
        cache, keyed by each mesh file's content (a .gltf's buffers and images too), transform,
        normals mode, material offset and object index (a 1.3M-triangle PLY: seconds to load and
        build, a fraction of a second to read back)."""
        from iblbake.scene import gltf as gltf_file
        from iblbake.scene import materials, pack

        objs = sc.data["objects"]
        meshes = [(oid, o) for oid, o in enumerate(objs) if "mesh" in o]
        if not meshes:
            return pack.scene_arrays(sc, (np.zeros((0, 6, 4), np.float32), np.zeros((0, 8), np.float32),
                                          {"meshes": [], "triangles": 0, "load_s": 0.0},
                                          np.zeros((0, 7, 4), np.float32), np.zeros((0, 2), np.int32)))
        try:
            _records, offsets = materials.table(sc)
            parts = [{"object": oid, "sha256": self.file_sha256(o["mesh"]["path"]),
                      "beside": [self.file_sha256(f) for f in gltf_file.external_files(o["mesh"]["path"])],
                      "material": offsets[oid], "own": materials.brings_materials(o),
                      **{k: v for k, v in o["mesh"].items() if k != "path"}}
                     for oid, o in meshes]
        except (OSError, IblbakeError):   # a missing or unreadable mesh: the loader says so, in one line
            return pack.scene_arrays(sc)
        key = "geometry-" + cache.content_key({"kind": "geometry", "v": 3, "meshes": parts,
                                               "attributes": pack.needs_attributes(sc), "code": _geometry_code_hash()})

        def make():
            def build(tmp: Path):
                arr, nodes, report, attr, closed = pack.mesh_arrays(sc)
                np.save(tmp / "triangles.npy", arr)
                np.save(tmp / "bvh.npy", nodes)
                np.save(tmp / "attributes.npy", attr)
                np.save(tmp / "closed.npy", closed)
                return {"kind": "geometry", "files": [{"name": n} for n in ("triangles.npy", "bvh.npy",
                                                                          "attributes.npy", "closed.npy")],
                        "report": report}

            manifest, cached = cache.get_or_build(self.root, key, build, warn=warn)
            entry = self.root / manifest["key"]
            arrays = (np.load(entry / "triangles.npy"), np.load(entry / "bvh.npy"),
                      {**manifest["report"], "cached": cached}, np.load(entry / "attributes.npy"),
                      np.load(entry / "closed.npy"))
            return arrays

        meshes_arrays = self._get(("geometry", key), make)
        return pack.scene_arrays(sc, meshes_arrays)

    def textures(self, sc, records, warn=None):
        """(device arrays (texels, tex_levels, tex_info), {(record, map kind): texture index},
        report) of the records' maps: decoded and filtered once per content, kept in the bake cache
        (a warm render reads the pyramids back) and in this store (a sheet's cells share them)."""
        from iblbake.scene import materials, textures as scene_textures

        refs = [(ri, kind, materials.texture_key(ref, kind), self._source_sha(ref["source"]))
                for ri, r in enumerate(records) for kind, ref in r["maps"].items()]
        key = "textures-" + cache.content_key({"kind": "textures", "v": 1, "refs": [x[1:] for x in refs],
                                               "limit": scene_textures.max_texture_pixels(),
                                               "code": _textures_code_hash()})

        def make():
            def build(tmp: Path):
                ts, slots = materials.load_textures(records, sc.source)
                for name, a in zip(("texels", "tex_levels", "tex_info"), ts.arrays()):
                    np.save(tmp / f"{name}.npy", a)
                return {"kind": "textures", "files": [{"name": f"{n}.npy"} for n in ("texels", "tex_levels", "tex_info")],
                        "slots": [[ri, kind, slots[(ri, kind)]] for ri, kind, *_ in refs],
                        "report": {"textures": len(ts.textures), "texels": ts.texel_count(),
                                   "decode_and_mips_s": round(ts.upload_s, 4)}}

            manifest, cached = cache.get_or_build(self.root, key, build, warn=warn)
            entry = self.root / manifest["key"]
            arrays = tuple(np.load(entry / f"{n}.npy") for n in ("texels", "tex_levels", "tex_info"))
            slots = {(ri, kind): t for ri, kind, t in manifest["slots"]}
            return arrays, slots, {**manifest["report"], "cached": cached, "device_bytes": int(arrays[0].nbytes)}

        (arrays, slots, report), held = self._recall(key, make)
        return arrays, slots, {**report, "cached": report["cached"] or held}

    def device_textures(self, rt, arrays) -> tuple:
        """The texture arrays on the device, uploaded once per runtime (a sheet's cells, a study's
        rungs and a benchmark's frames share them)."""
        return self.on_device(rt, arrays, lambda: tuple(rt.to_device(a) for a in arrays))

    def on_device(self, rt, arrays, upload):
        """upload()'s device buffers of the host arrays, made once per runtime and arrays (kept
        alive by the memo, so their ids stay theirs)."""
        return self._get(("on-device", id(rt), tuple(id(a) for a in arrays)), lambda: (arrays, upload()))[1]

    def _source_sha(self, source) -> str:
        return self.file_sha256(source[1]) + (f":{source[2]}" if source[0] == "gltf" else "")

    def chain(self, rt, levels) -> dict:
        """The device tables of a chain of levels (chain_table), uploaded once per runtime."""
        return self._get(("chain", id(rt), tuple(id(lv) for lv in levels)), lambda: chain_table(rt, levels))

    def load(self, name: str, ctx) -> tuple:
        """(value, cached, report fields) of bake `name` for the context's scene."""
        return getattr(self, f"_{name}")(ctx)

    def _policies(self, env):
        return images.read_policies(env["nonfinite"], env["negative"], env["transfer"], env["primaries"], env["layout"])

    def _sh(self, ctx):
        fx, env = ctx.scene.data["effects"], ctx.scene.data["environment"]
        image, info = self.environment(env)
        bands, window = fx["sh_bands"], fx["sh_window"]
        key = ("sh", info.sha256, bands, window, env["nonfinite"], env["negative"])
        (coeffs, manifest, cached), hit = self._recall(key, lambda: bake_sh.bake_irradiance(
            ctx.rt, image, info, self.root, self._policies(env), bands, window, warn=ctx.warn))
        return coeffs, cached or hit, {"bands": bands, "entry": str(self.root / manifest["key"])}

    def _basis(self, ctx):
        """The panorama projected onto the scene's directional basis (bake/bases.py)."""
        from iblbake.bake import bases as bake_bases
        from iblbake.core import bases

        fx, env = ctx.scene.data["effects"], ctx.scene.data["environment"]
        image, info = self.environment(env)
        name = bases.frame_basis(fx)              # the diffuse basis, else the specular one
        opts = bases.options_of(name, fx)
        key = ("basis", info.sha256, name, tuple(sorted(opts.items())), env["nonfinite"], env["negative"])
        (coeffs, manifest, cached), hit = self._recall(key, lambda: bake_bases.bake(
            image, info, self.root, self._policies(env), name, opts, warn=ctx.warn))
        return coeffs, cached or hit, {"basis": name, **opts, "floats": bases.BASES[name].floats(opts),
                                       "entry": str(self.root / manifest["key"])}

    def _baker(self, ctx):
        return self._get(("baker", id(ctx.rt)), lambda: mipsbake.Baker("opencl", rt=ctx.rt))

    def _radiance(self, ctx):
        env = ctx.scene.data["environment"]
        image, info = self.environment(env)
        key = ("radiance", info.sha256, env["nonfinite"], env["negative"])

        def make():
            manifest, cached, levels = mipsbake.bake_radiance(self._baker(ctx), image, info, self.root,
                                                              self._policies(env), warn=ctx.warn)
            return (levels if levels is not None else mipsbake.load_chain(self.root, manifest)), manifest, cached

        (chain, manifest, cached), hit = self._recall(key, make)
        return chain, cached or hit, {"levels": len(chain), "entry": str(self.root / manifest["key"])}

    def _prefiltered(self, ctx):
        p, env = ctx.scene.data["effects"]["prefilter"], ctx.scene.data["environment"]
        image, info = self.environment(env)
        rkey = ("radiance", info.sha256, env["nonfinite"], env["negative"])
        baker = self._baker(ctx)
        # the radiance chain in memory only: no radiance entry of its own
        return self.prefilter(ctx, image, info, p["size"] or layouts.default_base_size("equirect", info.height),
                              lambda: self._memo[rkey][0] if rkey in self._memo else baker.radiance_chain(image))

    def prefilter(self, ctx, image, info, base: int, chain_levels):
        """(levels, cached, report fields) of a panorama's prefiltered chain as the scene's
        effects.prefilter asks, `base` rows at level 0; chain_levels() its radiance chain."""
        p, env = ctx.scene.data["effects"]["prefilter"], ctx.scene.data["environment"]
        opts = mipsbake.PrefilterOptions("equirect", base, p["levels"], p["min_size"], p["method"], p["samples"],
                                         p["lod_bias"], True, level_sizes=p["level_sizes"]).resolved(info.height)
        opts["method_name"] = "effects.prefilter.method:"
        key = ("prefiltered", info.sha256, env["nonfinite"], env["negative"],
               tuple(sorted((k, str(v)) for k, v in opts.items())))
        baker = self._baker(ctx)

        def make():
            pm, cached = mipsbake.bake_prefiltered(baker, chain_levels, info, self.root, self._policies(env),
                                                   opts, warn=ctx.warn)
            levels = mipsbake.load_chain(self.root, pm)
            return levels, pm, cached

        (levels, pm, cached), hit = self._recall(key, make)
        extra = {"levels": len(levels), "methods": [f["method"] for f in pm["files"]],
                 "entry": str(self.root / pm["key"])}
        if "verify" in pm:            # what `mips --verify` measured and stored in the entry's manifest
            extra["verified_relative_rmse"] = pm["verify"]["relative_rmse"]
        return levels, cached or hit, extra

    def _dfg(self, ctx):
        p = ctx.scene.data["effects"]["prefilter"]
        key = ("dfg", p["dfg_size"], p["dfg_samples"])

        def make():
            dm, cached = mipsbake.bake_dfg(self._baker(ctx), self.root, p["dfg_size"], p["dfg_samples"], False,
                                           warn=ctx.warn)
            return images.read_exr(self.root / dm["key"] / "dfg.exr")[..., :2], dm, cached

        (table, dm, cached), hit = self._recall(key, make)
        return table, cached or hit, {"size": p["dfg_size"], "entry": str(self.root / dm["key"])}

    def _env_cdf(self, ctx):
        env = ctx.scene.data["environment"]
        image, info = self.environment(env)
        key = ("env_cdf", info.sha256, env["nonfinite"], env["negative"])
        dist, hit = self._recall(key, lambda: sampling.EnvironmentDistribution(image))
        return dist, hit, {}

    def _probes(self, ctx):
        """The scene's irradiance probe volume (render/probes), baked by tracing the scene on
        ctx's device, keyed by everything its rays see: the geometry and materials (their files'
        content), the lights, the panorama's content and frame, the bake settings and the code."""
        from iblbake.render import probes

        settings = ctx.scene.data["probes"]
        key = "probes-" + cache.content_key({"kind": "probes", "v": probes.VERSION, **self._light_transport(ctx),
                                             "settings": probes.bake_settings(settings),
                                             "code": _probes_code_hash()})

        def make():
            def build(tmp: Path):
                vol = probes.bake(ctx, settings, progress=ctx.progress)
                names = probes.save(vol, tmp)
                man = probes.manifest(probes.sampled(vol, settings))
                return {"kind": "probes", "files": [{"name": n} for n in names], "probes": man}

            manifest, cached = cache.get_or_build(self.root, key, build, warn=ctx.warn)
            entry = self.root / manifest["key"]
            return probes.load(entry, manifest.get("probes"), cache.MANIFEST), manifest, cached

        (vol, manifest, cached), hit = self._recall(key, make)
        rep = manifest["probes"]["report"]
        for w in probes.warnings(rep, ctx.scene.data, vol):    # said for a cached volume too
            ctx.warn(w)
        return vol, cached or hit, {"probes": rep["probes"], "rays_traced": rep["rays_traced"],
                                    "bake_s": rep["seconds"], "inactive": rep["inactive"],
                                    "relocated": rep["relocated"], "inside_geometry": rep.get("inside_geometry", 0),
                                    "outside_camera_room": rep.get("outside_camera_room", 0),
                                    "entry": str(self.root / manifest["key"])}

    def _reflection_probes(self, ctx):
        """Each reflection probe's capture (render/reflection_probes.py: the scene traced from its
        position, cached by content as the irradiance probes are) and its prefiltered chain."""
        import hashlib

        from iblbake.io.images import ImageInfo
        from iblbake.render import reflection_probes as rp

        transport = self._light_transport(ctx)
        out, cached_all, rays = [], True, 0
        for k, settings in enumerate(ctx.scene.data["reflection_probes"]):
            key = "reflection-" + cache.content_key({"kind": "reflection", "v": 2, "index": k, **transport,
                                                     "settings": settings, "code": _probes_code_hash()})

            def make(settings=settings, k=k, key=key):
                def build(tmp: Path):
                    image, report = rp.capture(rp.tracer(ctx, settings), k, settings, ctx.progress)
                    images.write_exr(tmp / "capture.exr", image, channels=("R", "G", "B", "A"))
                    return {"kind": "reflection", "files": [{"name": "capture.exr"}], "probe": settings,
                            "report": report}

                manifest, cached = cache.get_or_build(self.root, key, build, warn=ctx.warn)
                report = manifest.get("report")
                if not isinstance(report, dict) or not isinstance(report.get("inside"), dict):
                    raise IblbakeError(f"{self.root / manifest['key']}: a reflection capture without its report; "
                                       "delete the cache entry to bake it again")
                path = self.root / manifest["key"] / "capture.exr"
                image = images.read_exr(path)
                size = settings["size"]
                if image.shape != (size, 2 * size, 4) or not np.isfinite(image).all() or (image < 0).any() \
                        or (image[..., 3] > 1).any():
                    raise IblbakeError(f"{path}: not a {2 * size}x{size} RGBA capture of finite, non-negative "
                                       f"radiance and coverage; delete the cache entry to bake it again")
                return np.ascontiguousarray(image, np.float32), cached, report

            image, cached, report = self._get(("reflection", key), make)
            for w in rp.warnings(k, report, ctx.scene.data):     # said for a cached capture too
                ctx.warn(w)
            traced = not cached
            baker = self._baker(ctx)
            chains = []
            for part, img in (("radiance", image[..., :3]), ("coverage", np.repeat(image[..., 3:], 3, -1))):
                img = np.ascontiguousarray(img)
                info = ImageInfo(f"reflection probe {k} {part}", img.shape[1], img.shape[0], ("R", "G", "B"),
                                 "float32", hashlib.sha256(img.tobytes()).hexdigest())
                levels, pre_cached, _extra = self.prefilter(ctx, img, info, img.shape[0],
                                                            lambda img=img: baker.radiance_chain(img))
                chains.append(levels)
                cached = cached and pre_cached
            levels, coverage = chains
            out.append({"settings": settings, "levels": levels, "coverage": coverage, "capture": image})
            cached_all = cached_all and cached
            rays += 2 * settings["size"] ** 2 * settings["samples"] if traced else 0
        return out, cached_all, {"probes": len(out), "rays_traced": rays}

    def _light_transport(self, ctx) -> dict:
        """What light leaving the panorama meets before it reaches a probe: the objects,
        materials, lights and every file they read (by content), the panorama (by content) and its
        frame, and which surfaces bound solids (`solid: auto` decides by the camera's position)."""
        from iblbake.scene import pack

        sc = ctx.scene
        d = sc.data
        env = d["environment"]
        _image, info = self.environment(env)
        files = [self.file_sha256(f) for o in d["objects"] if "mesh" in o
                 for f in (o["mesh"]["path"], *_external(o["mesh"]["path"]))]
        files += [self.file_sha256(m["path"]) for m in _map_refs(d["materials"])]
        return {"environment": info.sha256, "frame": {k: env[k] for k in ("rotation_y", "intensity", "sun", "nonfinite",
                                                                         "negative")},
                "objects": d["objects"], "materials": d["materials"], "lights": d["lights"], "files": files,
                "solids": pack.solids_digest(ctx.arrays if ctx.arrays is not None else self.geometry(sc, ctx.warn))}


def load_all(ctx, names) -> dict:
    """Every named bake into ctx.loaded, in order (a later bake may read an earlier one), timed
    into the context's report."""
    for name in names:
        t0 = time.perf_counter()
        value, cached, extra = ctx.bakes.load(name, ctx)
        ctx.report.bake(name, time.perf_counter() - t0, cached, **extra)
        ctx.loaded[name] = value
    return ctx.loaded


def chain_table(rt, levels) -> dict:
    """One buffer of levels back to back (RGB, 3 floats a texel) and the offset/size tables
    chain_lookup reads, as the named kernel arguments chain, off, lw, lh, nlev. Levels that
    already lie back to back in one float32 array (a chain read from the cache or baked on the
    device) or a single contiguous level go up as they are: on this CPU fresh memory costs 0.45
    ms/MB, and a render's prefiltered chain is 34 MB."""
    sizes = [lvl.shape[:2] for lvl in levels]
    offs = np.concatenate([[0], np.cumsum([h * w for h, w in sizes])]).astype(np.int64)
    data = back_to_back(levels, offs)
    if data is None:
        data = np.concatenate([np.asarray(lvl[..., :3], np.float32).reshape(-1) for lvl in levels])
    off, lw, lh = (rt.to_device(np.asarray(x, np.int32)) for x in (offs[:-1], [w for _, w in sizes],
                                                                  [h for h, _ in sizes]))
    return {"chain": rt.to_device(data), "off": off, "lw": lw, "lh": lh, "nlev": len(levels)}


def back_to_back(levels, offs):
    """The flat float32 array the levels (h, w, 3) are consecutive views of, from their first
    texel to their last, or None where they are not."""
    first = levels[0]
    base = first if first.base is None else first.base
    if not (isinstance(base, np.ndarray) and base.dtype == np.float32 and base.flags.c_contiguous):
        return None
    start = first.__array_interface__["data"][0]
    if start != base.__array_interface__["data"][0] or base.size < 3 * int(offs[-1]):
        return None
    for lvl, o in zip(levels, offs[:-1]):
        if not (lvl.dtype == np.float32 and lvl.ndim == 3 and lvl.shape[2] == 3 and lvl.flags.c_contiguous
                and (lvl is base or lvl.base is base) and lvl.__array_interface__["data"][0] == start + 12 * int(o)):
            return None
    return base.reshape(-1)[:3 * int(offs[-1])]
