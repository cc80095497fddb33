"""A scene's lightmap: baked (cached by content) and written as the files engines load."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from iblbake.api.guards import _arguments, _cache, _callback, _device, _names, _path
from iblbake.api.runtimes import _job, _on_device, _runtime
from iblbake.api.scenes import load_scene
from iblbake.errors import InputError


@dataclass
class Lightmap:
    """A scene's baked lightmap (docs/manual.md 'iblbake lightmap').

    atlases: per basis the bake holds (render/lightmaps/bake.py BASES), float64 (h, w, 3) for the
        plain irradiance or (h, w, floats, 3) coefficient sets (lightmap.json's `bases` says how
        each is read).
    valid: (h, w) bool, the texels baked or dilated.  width, height: the atlas' texels.
    report: the bake's (texels, rays traced, seconds...).  cached: whether it came from the cache.
    lights: the lights whose direct light is not in the atlases (the scene's and those extracted
    from the panorama), which an engine draws per pixel as the frame does (lightmap.json's `lights`).
    environment: where lights were extracted (environment.sun: extract found some), the panorama less them
    (float32 (h, w, 3), the bake's light; lightmap_environment.exr), else None.
    """

    atlases: dict
    valid: object
    width: int
    height: int
    report: dict
    cached: bool
    device: str
    scene: object = field(repr=False, default=None)
    baked: dict = field(repr=False, default_factory=dict)
    lights: list = field(repr=False, default_factory=list)
    environment: object = field(repr=False, default=None)

    def write(self, folder) -> dict:
        """Every file of `iblbake lightmap` into folder (made where missing), replaced together
        (atomically) or none; returns lightmap.json's content."""
        from iblbake.io import atomic
        from iblbake.render.lightmaps import export
        folder = Path(_path("folder", folder, "the output folder's"))
        for n in self.files():
            atomic.check_writable(folder / n)
        with atomic.Batch() as batch:
            return export.write(self.baked, self.scene, folder, batch, self.lights, self.environment)

    def files(self) -> list:
        """The names write() writes, lightmap.json last."""
        from iblbake.render.lightmaps import export
        return export.file_names(export.held(self.baked), self.scene.data["lightmap"],
                                 self.baked.get("specular_options"), self.environment is not None)


def declared(sc) -> bool:
    """Whether the scene asks for a lightmap: its file (or a --set) has a `lightmap:` section."""
    return isinstance(sc.raw, dict) and "lightmap" in sc.raw


@_arguments
def bake_lightmap(scene, device: str | None = None, *, cache=None, warn=None, progress=None,
                  names: dict | None = None) -> Lightmap:
    """Bake a scene's lightmap (its `lightmap:` section, which it must have) by tracing paths from
    every texel of its static geometry; cached by content in `cache` (as render). names: what
    error messages call each argument (the command line passes its flags)."""
    from iblbake.render.lightmaps import export

    _names(names)
    _device(device)
    cache = _cache(cache)
    _callback("warn", warn)
    _callback("progress", progress)
    sc = load_scene(scene, names=names)
    if not declared(sc):
        raise InputError(f"{sc.source}: the scene has no `lightmap:` section; add one (`lightmap: {{}}` takes the "
                         f"defaults, docs/scene.md)")
    rt = _runtime(device, names)
    job = _job(sc, rt, cache, warn, progress)
    bakes = job.bakes
    with _on_device(rt):
        # the frame's unit (the lobe's set where the frame reads one), which says what a frame says of it
        lm, cached, _extra = bakes.load("lightmap", job)
    atlases = {b: lm[b] for b in export.held(lm)}
    from iblbake.render.probes import light_entries      # what an engine draws itself, as probes.json says
    env = sc.data["environment"]
    residual = bakes.environment(env)[0] if bakes.sun(env) else None     # lights were extracted: the rest
    return Lightmap(atlases, lm["valid"], lm["layout"].width, lm["layout"].height, lm["report"], cached,
                    rt.device_label, sc, lm, light_entries(sc, bakes.sun(env)), residual)
