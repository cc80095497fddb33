"""A scene's probe volume: its irradiance probes and reflection probes, baked."""

from __future__ import annotations

from dataclasses import dataclass, field

from iblbake.api.guards import _arguments, _cache, _callback, _device, _names
from iblbake.api.runtimes import _job, _on_device, _runtime
from iblbake.api.scenes import load_scene
from iblbake.errors import InputError


@dataclass
class ProbeVolume:
    """A scene's irradiance probe volume (DDGI, RTXGI's layouts; docs/manual.md 'iblbake probes').

    irradiance: float32 (what the volume's files hold), the octahedral atlas (rows, columns, 3)
        or, for probes.irradiance: sh, (probes, 9, 3) SH irradiance coefficients (SH's
        convention), or for a directional basis (probes, floats, 3) its radiance coefficients
        (manifest['basis'] says its layout).
    distance: float32 atlas of the ray distances' moments (R: mean distance, G: its square).
    data: float32 (probes, 4): each probe's offset from its grid position in world units, and
        its state (0 active, 1 inactive).
    grid: origin, spacing and counts (x, y, z); probe (gx, gy, gz) sits at
        origin + (gx, gy, gz) * spacing + offset, index gy * nx * nz + gz * nx + gx.
    states: the count of active and inactive probes.
    manifest: probes.json as `iblbake probes` writes it (every convention spelled out).
    reflections: each reflection probe's capture: {'capture': float32 (h, 2h, 8): R, G, B, A, sky.R,
        sky.G, sky.B, Z (render/reflection_probes.py CHANNELS), 'settings', and its prefiltered chains}.
    cached: whether the bake came from the cache. entry: the cache folder holding the atlases.
    environment: where lights were extracted (environment.sun: extract found some), the panorama less them
        (float32 (h, w, 3), the probes' light; environment.exr, probes.json's `environment`), else None.
    """

    irradiance: object
    distance: object
    data: object
    grid: dict
    states: dict
    representation: str
    manifest: dict
    reflections: list
    cached: bool
    entry: str
    device: str
    volume: dict = field(repr=False, default_factory=dict)
    environment: object = field(repr=False, default=None)

    def glsl(self) -> str:
        """probes.glsl: a GLSL function that samples the volume's files."""
        from iblbake.render import probes
        return probes.glsl(self.volume, self.manifest)


@_arguments
def bake_probes(scene, device: str | None = None, *, cache=None, warn=None, progress=None,
                names: dict | None = None) -> ProbeVolume:
    """Bake a scene's irradiance probe volume (its `probes:` section; a scene without one gets
    the section's defaults: an automatic grid over the scene's bounds, its spacing from the scene's
    interior, 1024 rays each, octahedral irradiance) by tracing paths from every probe, and each
    reflection probe's capture; cached by content in `cache` (as render). names: what error
    messages call each argument (by default its name; the command line passes its flags)."""

    import numpy as np

    from iblbake.render import probes

    _names(names)
    _device(device)
    cache = _cache(cache)
    _callback("warn", warn)
    _callback("progress", progress)
    sc = load_scene(scene, names=names)     # the probes unit is asked for by name: the scene is left as it is
    if not sc.data["objects"]:
        raise InputError(f"{sc.source}: the scene has no objects; probes light objects (add some)")
    rt = _runtime(device, names)
    job = _job(sc, rt, cache, warn, progress)
    bakes = job.bakes
    with _on_device(rt):
        vol, cached, extra = bakes.load("probes", job)
        reflections = bakes.load("reflection_probes", job)[0] if sc.data["reflection_probes"] else []
    vol = probes.sampled(vol, sc.data["probes"])
    env, fx = sc.data["environment"], sc.data["effects"]
    seen = bakes.environment(env)[0]          # what the probes saw: the residual where lights were extracted
    sky = probes.sky_entry(seen, env, fx["sh_bands"], fx["sh_window"])
    residual = seen if bakes.sun(env) else None     # lights were extracted: the panorama less them
    man = probes.manifest(vol, probes.light_entries(sc, bakes.sun(env)), sky,
                          probes.environment_entry(env, probes.ENVIRONMENT_FILE) if residual is not None else None)
    from iblbake.render.reflection_probes import CHANNELS as rp_channels
    man["reflection_probes"] = [{"file": f"reflection_{k}.exr", **c["settings"],
                                 "channels": list(rp_channels),
                                 "layout": "equirect in the world frame (the panoramas' mapping); R, G, B the linear "
                                           "radiance of the paths that met the scene, A the share of them that did "
                                           "(the coverage), sky.R, sky.G, sky.B the radiance of those that escaped "
                                           "(the sky through the openings, read without parallax), Z the mean distance from the "
                                           "probe to where they met the scene (0 where none did; read channels by name); "
                                           "docs/conventions.md 'Reflection probes' has the reading"}
                                for k, c in enumerate(reflections)]
    f32 = [np.asarray(vol[k], np.float32) for k in ("irradiance", "distance", "data")]     # as the files hold them
    return ProbeVolume(*f32, man["grid"], man["states"], man["representation"], man, list(reflections), cached,
                       extra["entry"], rt.device_label, vol, residual)
