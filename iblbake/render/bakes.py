"""The bake store: what the passes read, loaded once, each a unit of render/units.py: the
scene's (its geometry, panorama, sun and textures, the scene on the device: render/device_scene.py)
and every bake (sh, basis, radiance, prefiltered, dfg, env_cdf, probes, reflection_probes),
through the content-addressed cache, and kept in memory by content so that a caller rendering
many frames (a sheet) reads and uploads nothing twice."""

from __future__ import annotations

import dataclasses
import os
import time
from pathlib import Path

import numpy as np

from iblbake.bake import cache
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
    from iblbake.scene import bvh, geometry, gltf, pack, tangents
    return _code_hash((bvh, geometry, gltf, pack, tangents))


def _textures_code_hash() -> str:
    """The texture decoder's, pyramid builder's and glTF reader's source: cached pyramids are
    rebuilt when they change."""
    from iblbake.scene import gltf, materials, textures
    return _code_hash((gltf, materials, textures))


POLICY_KEYS = {"nonfinite": "environment.nonfinite:", "negative": "environment.negative:",
               "transfer": "environment.transfer:", "primaries": "environment.primaries:",
               "layout": "environment.layout:"}


def load_entry_arrays(entry: Path, names, what: str) -> tuple:
    """An entry's NAME.npy arrays, or an IblbakeError naming the entry (cache.get_checked then
    bakes it again)."""
    try:
        return tuple(np.load(entry / f"{n}.npy") for n in names)
    except (OSError, ValueError, EOFError) as e:
        raise IblbakeError(f"{entry}: unreadable {what} arrays ({e})") from None


def read_geometry_entry(entry: Path, report, attributes: bool) -> tuple:
    """A geometry entry's (triangles, bvh, bvh4, attributes, closed), checked as the kernels will
    index them (scene/bvh.py check_trees: no child, leaf or triangle out of range, no loop; every
    per-triangle array one row a triangle, the attributes' only where the kernels read them). An
    IblbakeError where the entry does not (cache.get_checked then builds it again)."""
    from iblbake.scene import bvh
    from iblbake.scene.layout import FLOAT4S

    tris, nodes, wide, attr, closed = load_entry_arrays(entry, ("triangles", "bvh", "bvh4", "attributes", "closed"),
                                                        "geometry")
    t = len(tris) if tris.ndim == 3 else -1
    per_triangle = (tris.dtype == np.float32 and tris.shape[1:] == (FLOAT4S["TRIANGLE"], 4)
                    and attr.dtype == np.float32 and attr.shape == (t if attributes else 0, FLOAT4S["TRIANGLE_ATTR"], 4)
                    and closed.dtype == np.int32 and closed.shape == (t, 2))
    if t < 0 or not per_triangle or not isinstance(report, dict):
        raise IblbakeError(f"{entry}: geometry arrays of the wrong type or shape")
    try:
        bvh.check_trees(nodes, wide, t, int(report.get("bvh4_nodes", 0)) if t else 0)
    except (ValueError, TypeError) as e:
        raise IblbakeError(f"{entry}: {e}") from None
    return tris, nodes, wide, attr, closed


def read_textures(entry: Path, order, maps: int) -> tuple:
    """A textures entry's arrays (texels, tex_levels, tex_info), checked as the kernels will index
    them: every map's slot a texture, every texture's levels listed, every level's texels held.
    An IblbakeError where the entry does not (cache.get_checked then bakes it again)."""
    texels, levels, info = load_entry_arrays(entry, ("texels", "tex_levels", "tex_info"), "texture")
    shapes_ok = (texels.dtype == np.float32 and texels.ndim == 2 and texels.shape[1] == 4
                 and levels.dtype == np.int32 and levels.ndim == 2 and levels.shape[1] == 4
                 and info.dtype == np.int32 and info.ndim == 2 and info.shape[1] == 4)
    if not shapes_ok:
        raise IblbakeError(f"{entry}: texture arrays of the wrong type or shape")
    if not (isinstance(order, list) and len(order) == maps
            and all(type(t) is int and 0 <= t < len(info) for t in order)):
        raise IblbakeError(f"{entry}: its map slots do not match the scene's {maps} maps")
    first, n = info[:, 0].astype(np.int64), info[:, 1].astype(np.int64)
    off, w, h = (levels[:, i].astype(np.int64) for i in range(3))
    if order and ((first < 0) | (n < 1) | (first + n > len(levels))).any():
        raise IblbakeError(f"{entry}: a texture's levels outside its level table")
    if order and ((off < 0) | (w < 1) | (h < 1) | (off + w * h > len(texels))).any():
        raise IblbakeError(f"{entry}: a level's texels outside the texel array")
    return texels, levels, info


class Bakes:
    """The bake cache folder plus an in-memory memo of loaded bakes, keyed by content."""

    def __init__(self, root: Path | None = None):
        self.root = Path(root) if root else cache.default_root()
        self._memo: dict = {}
        self.runtime = None          # the device a cube-map environment resamples on (render sets it)
        from iblbake.render.units import UNITS
        self.units: dict = UNITS     # name -> the bake's unit (render/units.py)
        self._meshes: dict = {}      # id(BVH array) -> (mesh entry key, BVH, triangle attributes) read back

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

    def input_hashes(self, sc) -> dict:
        """{path: content hash} of every file the scene reads but the scene file itself (what keys
        a sheet's cells and a study's reference). A missing or unreadable one (a mesh not made
        yet) is reported by the loaders, in render's words naming the key and the file; it was
        `internal error: FileNotFoundError`."""
        from iblbake.errors import InputError
        from iblbake.scene import load as scene_load, pack
        try:
            return {f: self.file_sha256(f) for f in scene_load.input_files(sc)[1:]}
        except OSError as e:
            pack.scene_arrays(sc)        # the mesh loaders' one-line error, where they have one
            raise InputError(f"{sc.source}: {e.filename}: cannot read ({e.strerror or e})") from None

    def _recall(self, key, make):
        """(value, whether this store already held it): a bake counts as cached when it was."""
        held = key in self._memo
        return self._get(key, make), held

    def held(self, kind: str) -> dict:
        """{key: value} of the bakes of `kind` this store holds in memory, in the order they were
        made (what a frame loaded, for tests and tools). A key names its kind: a tuple's first item
        ('dfg', 'prefiltered', 'reflection', 'device-scene', ...) or a string's part before its
        first '-' ('probes-HASH'); a unit's value is (result, cached, report fields)."""
        return {k: v for k, v in self._memo.items()
                if (k[0] if isinstance(k, tuple) else str(k).split("-", 1)[0]) == kind}

    def held_key(self, key):
        """The value this store holds in memory under `key` (a unit's: (result, cached, report
        fields)), or None: a bake that reuses another's result where it is already made."""
        return self._memo.get(key)

    def result(self, kind: str):
        """The result (its value's first item) of the first bake of `kind` held in memory (held)."""
        made = self.held(kind)
        if not made:
            raise KeyError(f"no bake of kind {kind!r} held in memory")
        return next(iter(made.values()))[0]

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
        return self._get(key + ("sun", env.get("sun_lights", 1)), lambda: self._extract(image, info, env))[:2]

    @staticmethod
    def _env_key(env: dict) -> tuple:
        """A panorama file's content as far as a read can tell (path, size, mtime), and its policies."""
        st = os.stat(env["path"])
        return ("env", env["path"], st.st_size, st.st_mtime_ns, env["nonfinite"], env["negative"], env["transfer"],
                env["primaries"], env["layout"])

    def _extract(self, image, info, env):
        import hashlib

        from iblbake.bake import sun as sunbake
        count = env.get("sun_lights", 1)
        key = f"{info.sha256}:sun-extract:{sunbake.PEAK}:{sunbake.SUN_SHARE}:{sunbake.THRESHOLD}:{sunbake.RING}"
        if count == 1:
            residual, found = sunbake.extract_lights(image, 1)
        else:                     # lamps too (bake/sun.py extract_lights)
            residual, found = sunbake.extract_lights(image, count, sunbake.LAMP_DIAMETER, sunbake.LAMP_SHARE)
            key += f":{count}:{sunbake.LAMP_DIAMETER}:{sunbake.LAMP_SHARE}"
        tag = hashlib.sha256(key.encode())
        return residual, dataclasses.replace(info, sha256=tag.hexdigest()), found

    def sun(self, env: dict) -> list:
        """The lights extracted from the scene's panorama (bake/sun.py: the sun, lamps where
        `sun_lights` > 1), brightest first; none without `sun: extract`."""
        if env.get("sun") != "extract":
            return []
        self.environment(env)
        return self._memo[self._env_key(env) + ("sun", env.get("sun_lights", 1))][2]

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
            return pack.scene_arrays(sc, pack.no_meshes())
        try:
            _records, offsets = materials.table(sc)
            parts = [{"object": oid, "sha256": self.file_sha256(o["mesh"]["path"]),
                      "beside": [self.file_sha256(f) for f in gltf_file.external_files(o["mesh"]["path"])],
                      "material": offsets[oid], "own": materials.brings_materials(o),
                      **{k: v for k, v in o["mesh"].items() if k != "path"}}
                     for oid, o in meshes]
        except (OSError, IblbakeError):   # a missing or unreadable mesh: the loader says so, in one line
            return pack.scene_arrays(sc)
        attributes = pack.needs_attributes(sc)
        key = "geometry-" + cache.content_key({"kind": "geometry", "v": 4, "meshes": parts,
                                               "attributes": attributes, "code": _geometry_code_hash()})

        def make():
            def build(tmp: Path):
                arr, nodes, wide, report, attr, closed = pack.mesh_arrays(sc)
                np.save(tmp / "triangles.npy", arr)
                np.save(tmp / "bvh.npy", nodes)
                np.save(tmp / "bvh4.npy", wide)
                np.save(tmp / "attributes.npy", attr)
                np.save(tmp / "closed.npy", closed)
                return {"kind": "geometry", "files": [{"name": n} for n in ("triangles.npy", "bvh.npy", "bvh4.npy",
                                                                          "attributes.npy", "closed.npy")],
                        "report": report}

            arrays, manifest, cached = cache.get_checked(
                self.root, key, build, lambda m: read_geometry_entry(self.root / m["key"], m.get("report"), attributes),
                warn=warn)
            arrays = (*arrays[:3], {**manifest["report"], "cached": cached}, *arrays[3:])
            self._meshes[id(arrays[1])] = (key, arrays[1], arrays[4])
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
        # the entry is keyed by the maps' content in order, not by which record holds them (a
        # plain material put before a textured one moves its index): its slots are listed in the
        # maps' order and given their records' indices here
        key = "textures-" + cache.content_key({"kind": "textures", "v": 2, "refs": [x[1:] for x in refs],
                                               "limit": scene_textures.max_texture_pixels(),
                                               "code": _textures_code_hash()})

        def read(manifest):
            order, report = manifest.get("slots"), manifest.get("report")
            if not isinstance(report, dict):
                raise IblbakeError(f"{self.root / manifest['key']}: a textures entry without its report")
            return read_textures(self.root / manifest["key"], order, len(refs)), order, report

        def make():
            def build(tmp: Path):
                ts, slots = materials.load_textures(records, sc.source)
                for name, a in zip(("texels", "tex_levels", "tex_info"), ts.arrays()):
                    np.save(tmp / f"{name}.npy", a)
                return {"kind": "textures", "files": [{"name": f"{n}.npy"} for n in ("texels", "tex_levels", "tex_info")],
                        "slots": [slots[(ri, kind)] for ri, kind, *_ in refs],
                        "report": {"textures": len(ts.textures), "texels": ts.texel_count(),
                                   "decode_and_mips_s": round(ts.upload_s, 4)}}

            (arrays, order, report), _manifest, cached = cache.get_checked(self.root, key, build, read, warn=warn)
            return arrays, order, {**report, "cached": cached, "device_bytes": int(arrays[0].nbytes)}

        (arrays, order, report), held = self._recall(key, make)
        slots = {(ri, kind): t for (ri, kind, *_), t in zip(refs, order)}
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

    def device_scene(self, rt, sc, warn=None, arrays=None, textures=None):
        """The scene's geometry, materials and textures on rt's device (render/device_scene.py
        DeviceScene), made once per runtime and content: the same tables for every frame of a
        series and for the bakes that trace the scene. `arrays` (geometry()) and `textures`
        (textures()' arrays and slots) where the caller has them. The triangles, BVH and attributes
        go up once per runtime and geometry, shared (on the host too) by scenes that differ in their
        materials: a sheet's cells keep one copy of a large mesh."""
        from iblbake.render import device_scene as dscene
        from iblbake.scene import materials, textures as scene_textures

        arrays = arrays if arrays is not None else self.geometry(sc, warn)
        records = arrays.records
        if textures is None and any(r["maps"] for r in records):
            textures = self.textures(sc, records, warn)[:2]
        tex, slots = textures if textures is not None else (None, {})
        sizes = scene_textures.sizes(tex[1], tex[2]) if slots else {}
        _mats, mat_maps = materials.device_arrays(records, slots, sizes)
        mesh = self._meshes.get(id(arrays.bvh))
        if mesh is not None and mesh[1] is arrays.bvh and mesh[2] is arrays.tri_attr:
            gkey = dscene.digest(arrays.tris, head=mesh[0])      # the BVH and attributes: the entry's
        else:
            gkey = dscene.digest(arrays.tris, arrays.bvh, arrays.tri_attr)
        # the texture arrays are this store's (textures()), held by its memo: their ids stay theirs
        tex_ids = f"{[id(a) for a in tex]}:{len(tex[2])}" if slots else "none"
        key = dscene.digest(arrays.spheres, arrays.planes, arrays.materials, mat_maps, head=f"{gkey}|{tex_ids}")

        def make():
            # the first scene's triangles, BVH and attributes (the same bytes) and their buffers
            held, geometry = self._get(("device-geometry", id(rt), gkey),
                                       lambda: (arrays, dscene.geometry_tables(rt, arrays)))
            if slots:
                devtex = self.device_textures(rt, tex)
            else:
                devtex = (rt.to_device(np.zeros((1, 4), np.float32)), rt.to_device(np.zeros((1, 4), np.int32)),
                          rt.to_device(np.zeros((1, 4), np.int32)))
            table = dscene.tables(rt, arrays, mat_maps, geometry, devtex, len(tex[2]) if slots else 0)
            shared = dataclasses.replace(arrays, tris=held.tris, bvh=held.bvh, bvh_wide=held.bvh_wide,
                                         tri_attr=held.tri_attr)
            return dscene.DeviceScene(shared, table, key)
        return self._get(("device-scene", id(rt), key), make)

    def load(self, name: str, job) -> tuple:
        """(value, cached, report fields) of bake `name` (its unit) for a Job (render/units.py),
        or for anything holding a scene and a runtime (a frame's context)."""
        from iblbake.render.units import Job
        return self.units[name].load(Job.of(job, self))


def load_all(job, names, report) -> dict:
    """Every named unit into job.loaded, in the order given (units.order: a unit after those it
    reads), each timed into its row of the frame's report (Unit.row; the sun and the device scene
    have none): the one place a frame's units and bakes are loaded and reported."""
    for name in names:
        t0 = time.perf_counter()
        value, cached, extra = job.bakes.load(name, job)
        row = job.bakes.units[name].row
        if row is not None:
            report.bake(row, time.perf_counter() - t0, cached, **extra)
        job.loaded[name] = value
    return job.loaded


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
