"""Lights: analytic lights (directional, point, spot; KHR_lights_punctual units) shaded with the
IBL's BRDF and shadowed as each light asks, added into `radiance` (kernels/lights.cl; twin:
iblbake/render/twin/lights.py lights). In a reference frame (every term the scene renders is
`reference`) a light with a size is integrated over its disk or sphere, traced with the
reference's visibility."""

from __future__ import annotations

import numpy as np

from iblbake.render.device_scene import scene_lights as frame_lights
from iblbake.render.passes.base import Buffer, Pass, geometry_defines
from iblbake.scene import pack


def exact(fx) -> bool:
    return all(m == "reference" for m in (fx.diffuse, fx.specular) if m != "off")


def shadow_rays_per_sample(scene, fx, lights) -> int:
    """Shadow rays one G-buffer sample traces (the planned count: a miss traces none; a soft
    light's specular term traces its lobe's samples that land in the disk too, up to as many
    again, counted as none here)."""
    if exact(fx):
        if not scene.data["effects"]["reference"]["visibility"]:
            return 0
        return sum(scene.data["effects"]["reference"]["max_samples"] if _size(lt) > 0 else 1 for lt in lights)
    return sum({"none": 0, "hard": 1}.get(lt["shadows"], lt["shadow_samples"] if _size(lt) > 0 else 1)
               for lt in lights)


def _size(lt) -> float:
    return lt["directional"]["angular_diameter"] if "directional" in lt else next(
        lt[k]["radius"] for k in ("point", "spot") if k in lt)


class Lights(Pass):
    name = "lights"
    kernel = "lights.cl"
    params = ("lights", "nlights", "light_seed", "exact_samples")
    buffers = (Buffer("radiance"),)      # every lighting pass adds into it

    def runs(self, scene, fx):
        has = bool(scene.data["lights"]) or scene.data["environment"]["sun"] == "extract"
        return has and (fx.diffuse != "off" or fx.specular != "off")

    def reads_environment(self, scene, fx):
        return scene.data["environment"]["sun"] == "extract"     # the sun it extracts

    def defines(self, scene, fx):
        d = {}
        if fx.diffuse != "off":
            d["LIGHT_DIFFUSE"] = 1
        if fx.specular != "off":
            d["LIGHT_SPECULAR"] = 1
        if exact(fx):
            d["LIGHTS_EXACT"] = 1
            if scene.data["effects"]["reference"]["visibility"]:
                d.update(VISIBILITY=1, **geometry_defines(scene))
        elif any(lt["shadows"] != "none" for lt in scene.data["lights"]) or (
                scene.data["environment"]["sun"] == "extract" and scene.data["environment"]["sun_shadows"] != "none"):
            d.update(HAS_SHADOWS=1, **geometry_defines(scene))
        return d

    def setup(self, ctx) -> dict:
        """The light records (the scene's lights, and the panorama's sun where it is extracted),
        and for run() the lights and the sun themselves (not kernel arguments)."""
        sc = ctx.scene
        sun = ctx.loaded.get("sun")          # placed with the panorama (environment.sun: extract reads it)
        lights = frame_lights(sc, sun)
        recs = pack.light_records(lights)
        ref = sc.data["effects"]["reference"]
        return {"lights": ctx.rt.to_device(recs.reshape(-1, 4) if len(recs) else np.zeros((4, 4), np.float32)),
                "nlights": len(recs), "light_seed": ref["seed"], "exact_samples": ref["max_samples"],
                "frame_lights": lights, "sun": sun}

    def run(self, ctx):
        n = ctx.table["n"]
        s = self.launch_samples(ctx)
        args = ctx.args[self.name]
        rays = shadow_rays_per_sample(ctx.scene, ctx.plan.effects, args["frame_lights"])
        extra = {}
        first = len(ctx.scene.data["lights"])     # what was extracted; each light's direction in world space
        # its illuminance as the frame lights with it (environment.intensity's, as probes.json's lights)
        # one list, brightest first, each named as the manifests' lights name it (trial75: a list of
        # `sun` and `lamps` called studio's brightest softbox the sun)
        found = args["sun"]
        said = [{"source": f"environment.sun: extract ({k + 1} of {len(found)}, brightest first)", **s.to_json(),
                 "illuminance": float(lt["directional"]["illuminance"]),
                 "illuminance_before_intensity": s.to_json()["illuminance"],
                 "light_direction_world": [round(x, 6) for x in lt["directional"]["direction"]]}
                for k, (s, lt) in enumerate(zip(found, args["frame_lights"][first:]))]
        if said:
            extra["extracted"] = said
        return {"lights": ctx.args[self.name]["nlights"], "exact": exact(ctx.plan.effects),
                "shadow_rays_per_sample": rays, "shadow_rays_per_s": round(n * rays / max(s, 1e-9)), **extra}
