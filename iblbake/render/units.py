"""The bakes, each a declared unit, and the scene's own units that a frame places before them (its
geometry, panorama, sun, textures and the scene on the device): its name, the units it reads, its
cache-key inputs (key: the bake store's memo key, which holds every input the value depends on;
the content-addressed cache entry is keyed by the same inputs), how it is built (baked, or read
back from the cache) and how its value is loaded with its report fields (a frame's report has a
row for each unit it loads, but the sun and the device scene).

A unit is asked for its value with a Job: a scene, a runtime, the bake store, warn and progress,
the values it has loaded (a frame's: the scene on the device among them, render/device_scene.py);
nothing of a frame is needed, so a bake that traces the scene (the irradiance probes, the
reflection captures) runs from the scene alone. The order bakes are loaded in follows from what
they read: order() is a topological order of the declared reads, ties in UNITS' order. A unit
reads another through job.read(name) when it builds, so a value found in the memo or the cache
loads nothing it was made from.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iblbake.errors import IblbakeError


def _nothing(_message):
    return None


@dataclass(eq=False)
class Job:
    """What a unit is asked with. `loaded`: the values this job has loaded, by unit name (a frame
    loads its scene's units and bakes into one: render/frame.py); a unit's reads come from it first.
    `scene_on_device`: the scene's DeviceScene where the caller has it (loaded as `device_scene`),
    else made on first use (Bakes.device_scene: once per runtime and content)."""

    scene: object
    rt: object
    bakes: object
    warn: object = _nothing
    progress: object = None
    scene_on_device: object = None
    loaded: dict = field(default_factory=dict)

    @classmethod
    def of(cls, ctx, bakes=None) -> "Job":
        """The job of anything holding a scene and a runtime (a frame's Context, a test's)."""
        if isinstance(ctx, Job):
            return ctx
        loaded = getattr(ctx, "loaded", None)
        return cls(ctx.scene, ctx.rt, bakes if bakes is not None else ctx.bakes, getattr(ctx, "warn", None) or _nothing,
                   getattr(ctx, "progress", None), getattr(ctx, "device_scene", None), {} if loaded is None else loaded)

    def read(self, name: str):
        """The value of unit `name` (a unit's declared read): this job's, else through the store's memo."""
        if name in self.loaded:
            return self.loaded[name]
        return self.bakes.load(name, self)[0]

    @property
    def device_scene(self):
        if self.scene_on_device is None:
            self.scene_on_device = self.loaded.get("device_scene") or self.bakes.device_scene(
                self.rt, self.scene, self.warn)
        return self.scene_on_device

    @property
    def arrays(self):
        """The scene's host records (scene/pack.py): the device scene's, else the geometry alone
        (nothing goes up to the device for a key)."""
        on_device = self.scene_on_device or self.loaded.get("device_scene")
        if on_device is not None:
            return on_device.arrays
        return self.bakes.geometry(self.scene, self.warn)

    @property
    def environment(self) -> dict:
        return self.scene.data["environment"]

    def panorama(self):
        """(image, info) of the scene's panorama (Bakes.environment: read once per content)."""
        return self.bakes.environment(self.environment)


class Unit:
    """A bake: `name`, the bakes it `reads`; key(job) the memo key holding its inputs, build(job,
    key) what it makes (once per key in a store), result() its (value, cached, report fields).
    `row`: the name of its row in a frame's report (None: it has none)."""

    name = ""
    reads: tuple = ()

    @property
    def row(self) -> str | None:
        return self.name

    def key(self, job):
        raise NotImplementedError

    def build(self, job, key):
        raise NotImplementedError

    def result(self, job, made, held: bool) -> tuple:
        value, _manifest, cached = made
        return value, cached or held, {}

    def load(self, job) -> tuple:
        """(value, cached, report fields): from the store's memo, else built."""
        key = self.key(job)
        made, held = job.bakes._recall(key, lambda: self.build(job, key))
        return self.result(job, made, held)


# The scene's units: what every frame places before its bakes. Each keeps its own memo in the
# bake store (render/bakes.py: geometry by mesh content, the panorama by file content and
# policies, textures by map content, the device scene by runtime and content).

class Geometry(Unit):
    """The scene's device records, its meshes' triangles and BVH from the cache (Bakes.geometry)."""
    name = "geometry"

    def load(self, job):
        arrays = job.bakes.geometry(job.scene, job.warn)
        extra = dict(arrays.geometry_report)
        return arrays, extra.pop("cached", False), extra


class Panorama(Unit):
    """(image, background image) of the scene's panorama (Bakes.environment): the background shows
    the sky as it is, an extracted sun visible in it. Its read warnings are said here."""
    name = "panorama"
    row = "read_environment"

    def load(self, job):
        env = job.environment
        image, info = job.bakes.environment(env)
        background = job.bakes.environment({**env, "sun": "none"})[0] if env["sun"] == "extract" else image
        for w in info.warnings:
            job.warn(w)
        return (image, background), False, {"path": info.path, "size": [info.width, info.height]}


class Sun(Unit):
    """The sun extracted from the panorama (environment.sun: extract; bake/sun.py), or None."""
    name = "sun"
    reads = ("panorama",)
    row = None

    def load(self, job):
        return job.bakes.sun(job.environment), False, {}


class Textures(Unit):
    """((texels, levels, info) arrays, {(record, map kind): texture}) of the scene's material maps
    (Bakes.textures)."""
    name = "textures"
    reads = ("geometry",)

    def load(self, job):
        tex, slots, extra = job.bakes.textures(job.scene, job.read("geometry").records, job.warn)
        extra = dict(extra)
        return (tex, slots), extra.pop("cached"), extra


class DeviceScene(Unit):
    """The scene's geometry, materials and textures on the job's device (Bakes.device_scene)."""
    name = "device_scene"
    reads = ("geometry", "textures")
    row = None

    def load(self, job):
        arrays = job.read("geometry")
        textures = job.read("textures") if any(r["maps"] for r in arrays.records) else None
        return job.bakes.device_scene(job.rt, job.scene, job.warn, arrays=arrays, textures=textures), False, {}


def policies(env: dict) -> dict:
    from iblbake.io import images
    return images.read_policies(env["nonfinite"], env["negative"], env["transfer"], env["primaries"], env["layout"])


def source(job, info=None) -> tuple:
    """What a bake of an image holds from it, for memo keys: the image's content (the panorama's,
    or `info`'s) and the read policies that change its pixels."""
    env = job.environment
    return ((info or job.panorama()[1]).sha256, env["nonfinite"], env["negative"])


def baker(job):
    """The mip baker on the job's runtime (one per runtime in a store)."""
    from iblbake.bake import mips as mipsbake
    return job.bakes._get(("baker", id(job.rt)), lambda: mipsbake.Baker("opencl", rt=job.rt))


class SH(Unit):
    """The panorama's irradiance SH (bake/sh.py)."""
    name = "sh"

    def key(self, job):
        fx = job.scene.data["effects"]
        return ("sh", *source(job), fx["sh_bands"], fx["sh_window"])

    def build(self, job, key):
        from iblbake.bake import sh as bake_sh
        fx, env = job.scene.data["effects"], job.environment
        image, info = job.panorama()
        return bake_sh.bake_irradiance(job.rt, image, info, job.bakes.root, policies(env), fx["sh_bands"],
                                       fx["sh_window"], warn=job.warn)

    def result(self, job, made, held):
        coeffs, manifest, cached = made
        return coeffs, cached or held, {"bands": job.scene.data["effects"]["sh_bands"],
                                        "entry": str(job.bakes.root / manifest["key"])}


class Basis(Unit):
    """The panorama projected onto the scene's directional basis (bake/bases.py)."""
    name = "basis"

    @staticmethod
    def _basis(job):
        from iblbake.core import bases
        fx = job.scene.data["effects"]
        name = bases.frame_basis(fx)              # the diffuse basis, else the specular one
        return name, bases.options_of(name, fx)

    def key(self, job):
        name, opts = self._basis(job)
        return ("basis", *source(job), name, tuple(sorted(opts.items())))

    def build(self, job, key):
        from iblbake.bake import bases as bake_bases
        image, info = job.panorama()
        name, opts = self._basis(job)
        return bake_bases.bake(image, info, job.bakes.root, policies(job.environment), name, opts, warn=job.warn)

    def result(self, job, made, held):
        from iblbake.core import bases
        coeffs, manifest, cached = made
        name, opts = self._basis(job)
        return coeffs, cached or held, {"basis": name, **opts, "floats": bases.BASES[name].floats(opts),
                                        "entry": str(job.bakes.root / manifest["key"])}


class Radiance(Unit):
    """The panorama's radiance mip chain (bake/mips.py)."""
    name = "radiance"

    def key(self, job):
        return ("radiance", *source(job))

    def build(self, job, key):
        from iblbake.bake import mips as mipsbake
        image, info = job.panorama()
        manifest, cached, levels = mipsbake.bake_radiance(baker(job), image, info, job.bakes.root,
                                                          policies(job.environment), warn=job.warn)
        return (levels if levels is not None else mipsbake.load_chain(job.bakes.root, manifest)), manifest, cached

    def result(self, job, made, held):
        chain, manifest, cached = made
        return chain, cached or held, {"levels": len(chain), "entry": str(job.bakes.root / manifest["key"])}


def prefilter_key(job, info, base: int) -> tuple:
    """(memo key, PrefilterOptions resolved) of a chain prefiltered as the scene's effects.prefilter
    asks, `base` rows at level 0, from the image `info` describes."""
    from iblbake.bake import mips as mipsbake
    p = job.scene.data["effects"]["prefilter"]
    opts = mipsbake.PrefilterOptions("equirect", base, p["levels"], p["min_size"], p["method"], p["samples"],
                                     p["lod_bias"], True, level_sizes=p["level_sizes"]).resolved(info.height)
    opts["method_name"] = "effects.prefilter.method:"
    return ("prefiltered", *source(job, info), tuple(sorted((k, str(v)) for k, v in opts.items()))), opts


def prefilter(job, image, info, base: int, chain_levels) -> tuple:
    """(levels, cached, report fields) of an image's prefiltered chain as the scene's
    effects.prefilter asks, `base` rows at level 0; chain_levels() its radiance chain (the
    panorama's, or a reflection capture's)."""
    from iblbake.bake import mips as mipsbake
    key, opts = prefilter_key(job, info, base)
    bk, root = baker(job), job.bakes.root

    def make():
        pm, cached = mipsbake.bake_prefiltered(bk, chain_levels, info, root, policies(job.environment), opts,
                                               warn=job.warn)
        return mipsbake.load_chain(root, pm), pm, cached

    (levels, pm, cached), hit = job.bakes._recall(key, make)
    extra = {"levels": len(levels), "methods": [f["method"] for f in pm["files"]], "entry": str(root / pm["key"]),
             "fp16_bytes": int(sum(3 * 2 * lv.shape[0] * lv.shape[1] for lv in levels))}   # an engine's copy
    if "verify" in pm:            # what `mips --verify` measured and stored in the entry's manifest
        extra["verified_relative_rmse"] = pm["verify"]["relative_rmse"]
    return levels, cached or hit, extra


class Prefiltered(Unit):
    """The panorama's GGX-prefiltered chain (bake/mips.py), from its radiance chain: the radiance
    unit's where the store holds it (planned before it: UNITS' order), else made in memory (no
    radiance entry of its own)."""
    name = "prefiltered"

    def _base(self, job, info):
        from iblbake.bake import layouts
        return job.scene.data["effects"]["prefilter"]["size"] or layouts.default_base_size("equirect", info.height)

    def key(self, job):
        return prefilter_key(job, job.panorama()[1], self._base(job, job.panorama()[1]))[0]

    def load(self, job):
        image, info = job.panorama()
        rkey = Radiance().key(job)
        bk = baker(job)

        def radiance():
            held = job.bakes.held_key(rkey)
            return held[0] if held is not None else bk.radiance_chain(image)
        return prefilter(job, image, info, self._base(job, info), radiance)


class DFG(Unit):
    """The split sum's DFG table (bake/mips.py)."""
    name = "dfg"

    def key(self, job):
        p = job.scene.data["effects"]["prefilter"]
        return ("dfg", p["dfg_size"], p["dfg_samples"])

    def build(self, job, key):
        from iblbake.bake import mips as mipsbake
        from iblbake.io import images
        p = job.scene.data["effects"]["prefilter"]
        dm, cached = mipsbake.bake_dfg(baker(job), job.bakes.root, p["dfg_size"], p["dfg_samples"], False,
                                       warn=job.warn)
        return images.read_exr(job.bakes.root / dm["key"] / "dfg.exr")[..., :2], dm, cached

    def result(self, job, made, held):
        table, dm, cached = made
        return table, cached or held, {"size": job.scene.data["effects"]["prefilter"]["dfg_size"],
                                       "entry": str(job.bakes.root / dm["key"])}


class EnvCDF(Unit):
    """The panorama's importance-sampling tables (core/sampling.py), in memory."""
    name = "env_cdf"

    def key(self, job):
        return ("env_cdf", *source(job))

    def build(self, job, key):
        from iblbake.core import sampling
        return sampling.EnvironmentDistribution(job.panorama()[0])

    def result(self, job, made, held):
        return made, held, {}


def probes_code_hash() -> str:
    """The probe bakers' and their tracing kernel's source: cached volumes and captures are rebaked
    when they change. Every module of render/probes, the captures', the device scene's (the
    tracer's defines, lights and panorama), the panorama's sampling tables' (core/sampling) and
    the probe bases' fits (core/bases project_rays)."""
    import importlib
    import pkgutil

    from iblbake.core import sampling
    from iblbake.core.bases import common
    from iblbake.core.bases import probes as probe_bases
    from iblbake.device.programs import source_hash
    from iblbake.render import device_scene, probes, reflection_probes
    from iblbake.render.bakes import _code_hash
    package = [importlib.import_module(f"{probes.__name__}.{m.name}")
               for m in sorted(pkgutil.iter_modules(probes.__path__), key=lambda m: m.name)]
    return _code_hash((probes, *package, reflection_probes, device_scene, sampling, common,
                       probe_bases, *(b.m for b in probe_bases.PROBE_BASES.values() if b.directional)),
                      source_hash("paths/probe_trace.cl"))


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


def light_transport(job) -> dict:
    """What light leaving the panorama meets before it reaches a probe: the objects, materials,
    lights and every file they read (by content), the panorama (by content) and its frame, and
    which surfaces bound solids (`solid: auto` decides by the camera's position)."""
    from iblbake.scene import pack

    d, bakes = job.scene.data, job.bakes
    solids = pack.solids_digest(job.arrays)        # the geometry first: a mesh it cannot read is said
    env = d["environment"]
    _image, info = job.panorama()
    files = [bakes.file_sha256(f) for o in d["objects"] if "mesh" in o
             for f in (o["mesh"]["path"], *_external(o["mesh"]["path"]))]
    files += [bakes.file_sha256(m["path"]) for m in _map_refs(d["materials"])]
    # the extracted lights light every vertex of the paths (sun_lights, sun_shadows: their count and disks)
    return {"environment": info.sha256, "frame": {k: env.get(k) for k in ("rotation_y", "intensity", "sun", "sun_lights",
                                                                         "sun_shadows", "nonfinite", "negative")},
            "objects": d["objects"], "materials": d["materials"], "lights": d["lights"], "files": files,
            "solids": solids}


class Probes(Unit):
    """The scene's irradiance probe volume (render/probes), baked by tracing the scene on the job's
    device, keyed by everything its rays see: the geometry and materials (their files' content),
    the lights, the panorama's content and frame, the camera (the rules that switch probes off follow
    what it sees), the bake settings and the code."""
    name = "probes"
    reads = ("env_cdf", "radiance")          # the tracer's (render/paths/tracer.py)

    def key(self, job):
        from iblbake.bake import cache
        from iblbake.render import probes
        # the camera too: which probes are off follows what it sees (its room, the bounds it stands
        # in, the points it sees behind surfaces: render/probes/relocation.py)
        return "probes-" + cache.content_key({"kind": "probes", "v": probes.VERSION, **light_transport(job),
                                              "camera": job.scene.data["camera"],
                                              "settings": probes.bake_settings(job.scene.data["probes"]),
                                              "code": probes_code_hash()})

    def build(self, job, key):
        from iblbake.bake import cache
        from iblbake.render import probes
        settings, root = job.scene.data["probes"], job.bakes.root

        def build(tmp: Path):
            vol = probes.bake(job, settings, progress=job.progress)
            names = probes.save(vol, tmp)
            man = probes.manifest(probes.sampled(vol, settings))
            return {"kind": "probes", "files": [{"name": n} for n in names], "probes": man}

        return cache.get_checked(root, key, build, lambda m: probes.load(root / m["key"], m.get("probes"),
                                                                         cache.MANIFEST), warn=job.warn)

    def result(self, job, made, held):
        from iblbake.render import probes
        vol, manifest, cached = made
        rep = manifest["probes"]["report"]
        for w in probes.warnings(rep, job.scene.data, vol):    # said for a cached volume too
            job.warn(w)
        return vol, cached or held, {"probes": rep["probes"], "rays_traced": rep["rays_traced"],
                                     "bake_s": rep["seconds"], "inactive": rep["inactive"],
                                     "relocated": rep["relocated"], "inside_geometry": rep.get("inside_geometry", 0),
                                     "outside_camera_room": rep.get("outside_camera_room", 0),
                                     **{k: rep[k] for k in ("off_by", "on_surface", "interior_step", "lattice",
                                                            "capped", "bytes", "more_rays", "estimate") if k in rep},
                                     "entry": str(job.bakes.root / manifest["key"])}


class ReflectionProbes(Unit):
    """Each reflection probe's capture (render/reflection_probes.py: the scene traced from its
    position, cached by content as the irradiance probes are) and its prefiltered chain: one memo
    entry a capture, each chain the prefiltered unit's (prefilter())."""
    name = "reflection_probes"
    reads = ("env_cdf", "radiance")          # the tracer's (render/paths/tracer.py)

    def key(self, job) -> tuple:
        from iblbake.bake import cache
        from iblbake.render.reflection_probes import capture_settings
        transport = light_transport(job)
        # what the capture is traced from: a reading option (taps, the box) re-reads it, never re-traces it
        return tuple("reflection-" + cache.content_key({"kind": "reflection", "v": 4, "index": k, **transport,
                                                        "settings": capture_settings(settings),
                                                        "code": probes_code_hash()})
                     for k, settings in enumerate(job.scene.data["reflection_probes"]))

    def capture(self, job, k: int, settings: dict, key: str):
        """(image, cached, report) of capture k: from the cache, else traced."""
        from iblbake.bake import cache
        from iblbake.io import images
        from iblbake.render import reflection_probes as rp
        root = job.bakes.root

        def build(tmp: Path):
            traced = rp.capture_settings(settings)          # its key's: a reading option cannot reach the trace
            image, report = rp.capture(rp.tracer(job, traced), k, traced, job.progress)
            images.write_exr(tmp / "capture.exr", image, channels=rp.CHANNELS)
            return {"kind": "reflection", "files": [{"name": "capture.exr"}], "probe": traced, "report": report}

        def read(manifest):
            report = manifest.get("report")
            if not isinstance(report, dict) or not isinstance(report.get("inside"), dict):
                raise IblbakeError(f"{root / manifest['key']}: a reflection capture without its report")
            path = root / manifest["key"] / "capture.exr"
            image = images.read_exr(path, rp.CHANNELS)
            size = settings["size"]
            if image.shape != (size, 2 * size, len(rp.CHANNELS)) or not np.isfinite(image).all() \
                    or (image < 0).any() or (image[..., 3] > 1).any():
                raise IblbakeError(f"{path}: not a {2 * size}x{size} capture of finite, non-negative radiance, "
                                   f"coverage, sky and distance ({', '.join(rp.CHANNELS)})")
            return np.ascontiguousarray(image, np.float32), report

        (image, report), _manifest, cached = cache.get_checked(root, key, build, read, warn=job.warn)
        return image, cached, report

    def load(self, job):
        from iblbake.io.images import ImageInfo
        from iblbake.render import reflection_probes as rp

        from iblbake.render.probes.grid import scene_bounds

        out, cached_all, rays, bounds = [], True, 0, scene_bounds(job.arrays)
        for k, (settings, key) in enumerate(zip(job.scene.data["reflection_probes"], self.key(job))):
            (image, cached, report), held = job.bakes._recall(("reflection", key),
                                                              lambda: self.capture(job, k, settings, key))
            cached = cached or held          # a frame that shares the store's capture traced nothing
            for w in rp.warnings(k, report, job.scene.data, bounds):     # said for a cached capture too
                job.warn(w)
            traced = not cached
            bk = baker(job)
            chains = []
            for part, img in (("radiance", image[..., :3]), ("coverage", np.repeat(image[..., 3:4], 3, -1)),
                              ("sky", image[..., 4:7])):
                img = np.ascontiguousarray(img)
                info = ImageInfo(f"reflection probe {k} {part}", img.shape[1], img.shape[0], ("R", "G", "B"),
                                 "float32", hashlib.sha256(img.tobytes()).hexdigest())
                levels, pre_cached, _extra = prefilter(job, img, info, img.shape[0],
                                                       lambda img=img: bk.radiance_chain(img))
                chains.append(levels)
                cached = cached and pre_cached
            levels, coverage, sky = chains
            # held by the memo as the chains are: the same arrays each frame, uploaded once; over the
            # probe's proxy, which the capture's key lacks
            proxy = tuple(str(settings.get(n)) for n in rp.PROXY_KEYS)
            depth = job.bakes._get(("reflection-depth", key, proxy), lambda: rp.depth_levels(
                image[..., 7], settings, [lv.shape[:2] for lv in levels]))
            out.append({"settings": settings, "levels": levels, "coverage": coverage, "sky": sky, "depth": depth,
                        "capture": image, "excluded": rp.excluded(job.scene.data, settings)})
            cached_all = cached_all and cached
            rays += 2 * settings["size"] ** 2 * settings["samples"] if traced else 0
        return out, cached_all, {"probes": len(out), "rays_traced": rays}


class Lightmap(Unit):
    """The scene's lightmap (render/lightmaps: its texels traced by the path tracer on the job's
    device, cached by content in the bake store, lightmaps/store.py), for `effects.diffuse: lightmap`;
    its row says the atlas, the bake and the objects left without one (they read the probes or the
    panorama's SH)."""
    name = "lightmap"
    reads = ("env_cdf", "radiance")          # the tracer's (render/paths/tracer.py)

    @staticmethod
    def settings(job) -> dict:
        """The section's bake settings, `basis` included: the bake fits the texels to it (its key
        holds that basis' options only, lightmaps/store.py); `specular` where the frame reads the
        lobe from it (`effects.specular: lightmap`: a second set, in the key only then)."""
        s = job.scene.data["lightmap"]
        return {**s, "specular": True} if job.scene.data["effects"]["specular"] == "lightmap" else s

    def key(self, job):
        from iblbake.render.lightmaps import store
        return store.key(job, self.settings(job))

    def build(self, job, key):
        from iblbake.render.lightmaps import store
        lm, cached = store.baked(job, self.settings(job), job.progress)
        return lm, None, cached

    def result(self, job, made, held):
        from iblbake.render.lightmaps.bake import coarse_said
        from iblbake.render.probes.grid import scene_bounds
        lm, _manifest, cached = made
        rep, lay = lm["report"], lm["layout"]
        for w in coarse_said(rep["texels_per_unit"], scene_bounds(job.arrays)):     # said for a cached one too
            job.warn(w)
        objects = job.scene.data["objects"]
        without = [o.get("name") or f"objects.{i}" for i, o in enumerate(objects) if i not in lay.source]
        return lm, cached or held, {"atlas": [rep["width"], rep["height"]], "texels": rep["texels"],
                                    "texels_per_unit": rep["texels_per_unit"], "samples": rep["samples"],
                                    "bake_s": rep["seconds"], "basis": job.scene.data["lightmap"]["basis"],
                                    "bytes": rep["bytes"], "objects_lightmapped": len(objects) - len(without),
                                    "objects_without": without}


# every unit, in the order that breaks ties between units that do not read one another (the
# scene's first, as a frame places them; the radiance chain before the prefiltered one, which
# reuses it where both are planned)
UNITS = {u.name: u for u in (Geometry(), Panorama(), Sun(), Textures(), DeviceScene(), SH(), Basis(), Radiance(),
                             Prefiltered(), DFG(), EnvCDF(), Probes(), ReflectionProbes(), Lightmap())}


def order(names, units: dict | None = None) -> list:
    """`names` in a topological order of the units' declared reads: a unit after every unit it
    reads that is among them; ties in the units' order. A cycle is an error naming it."""
    units = UNITS if units is None else units
    names = set(names)
    wanted = [n for n in units if n in names]
    unknown = names - set(units)
    if unknown:
        raise KeyError(f"no bake unit named {sorted(unknown)}")
    out, placed = [], set()
    while len(out) < len(wanted):
        ready = [n for n in wanted if n not in placed and all(r in placed or r not in wanted for r in units[n].reads)]
        if not ready:
            raise ValueError(f"bake units read one another in a cycle: {sorted(set(wanted) - placed)}")
        out.append(ready[0])
        placed.add(ready[0])
    return out
