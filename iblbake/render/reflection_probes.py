"""Local reflection probes (Lagarde and Zanuttini 2012, "Local image-based lighting with
parallax-corrected cubemaps"; Unity's reflection probes, Unreal's box and sphere captures): the
radiance arriving at a point of the scene from every direction, captured by the reference's path
tracer (kernels/paths/probe_trace.cl) into an equirect panorama (the scene's part and the sky's
part apart: the sky is read without parallax), then prefiltered by the same code as
the distant panorama's chain (render/units.py: the reflection_probes unit, prefilter()).
`specular: prefiltered` reads it inside the probe's influence, along the reflected ray corrected
to where it leaves the probe's box or sphere (kernels/reflection_probes.h; twin:
render/twin/reflection_probes.py). Conventions: docs/conventions.md "Reflection probes"."""

from __future__ import annotations

import numpy as np

from iblbake.core import conventions, sampling
from iblbake.render.paths.rays import TexelRays
from iblbake.render.paths.trace import trace
from iblbake.render.paths.tracer import Tracer
from iblbake.render.twin.reflection_probes import OWN_MAX


def capture_directions(size: int, samples: int) -> np.ndarray:
    """(texels * samples, 4): each texel's samples, stratified (Hammersley points, a single sample
    at the centre), row by row, the sample fastest; w each sample's share of the texel's exact
    solid angle."""
    h, w = size, 2 * size
    n = samples
    k = np.arange(n)
    jitter = np.stack([(k + 0.5) / n, np.mod(sampling.radical_inverse_vdc(k.astype(np.uint32)) + 0.5 / n, 1.0)], -1)
    j, i = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    u = (i[..., None] + jitter[:, 0]) / w
    v = (j[..., None] + jitter[:, 1]) / h
    d = conventions.dir_from_equirect_uv(u, v)
    share = np.broadcast_to(conventions.equirect_row_solid_angles(w, h)[:, None, None] / n, (h, w, n))
    return np.concatenate([d, share[..., None]], -1).reshape(-1, 4)


# a probe's settings that only its reading takes (kernels/reflection_probes.h: the lobe's taps, the
# influence, its fade and its parallax proxy), out of its capture's key: changing them re-reads the
# capture, never re-traces it (each frame reads its own: sources/reflection_probes.py rprobe_info)
PROXY_KEYS = ("shape", "min", "max", "radius")        # the influence and parallax proxy: box or sphere
READ_KEYS = ("taps", "grazing_taps", "blend", "parallax", *PROXY_KEYS)


def capture_settings(settings: dict) -> dict:
    """What a probe's capture is traced from (its key): its settings less READ_KEYS."""
    return {k: v for k, v in settings.items() if k not in READ_KEYS}


# a capture's channels: the scene's radiance (RGB), its coverage (A), the sky seen past it and the
# distance to the scene (Z: the read marches a reflected ray against it, kernels/reflection_probes.h
# rprobe_hit)
CHANNELS = ("R", "G", "B", "A", "sky.R", "sky.G", "sky.B", "Z")


def capture(tracer, index: int, settings: dict, progress=None):
    """((size, 2 size, 8) float32: per texel the mean over its paths from the probe's position of
    the radiance of those that met the scene (RGB), the share of them that did (A, the coverage),
    the radiance of those that escaped (the panorama through the scene's openings: sky RGB) and the
    mean distance from the probe to where those that met the scene met it (Z, 0 where none did);
    report: {"inside": {object: share of the solid angle whose rays met its inside}}). The sky is
    read along the reflected ray itself (it is infinitely far: no parallax moves it;
    kernels/reflection_probes.h rprobe_sky). Probe number `index`: its random streams."""
    size, n = settings["size"], settings["samples"]
    texels = TexelRays(tracer, settings["position"], capture_directions(size, n), n, index, progress)
    sums, inside = trace(texels)              # the one driver (render/paths/trace.py)
    sums = np.concatenate([sums, texels.depth()[:, None]], 1)
    # radiance is >= 0; the panorama's tiny negative texels (environment.negative: keep) reach a few
    # paths, and read back a negative value would fail the capture's check
    sums[:, :3] = np.maximum(sums[:, :3], 0.0)
    sums[:, 4:] = np.maximum(sums[:, 4:], 0.0)
    return sums.reshape(size, 2 * size, len(CHANNELS)).astype(np.float32), {"inside": {str(k): round(v, 4)
                                                                           for k, v in inside.items()}}


def depth_levels(depth, settings: dict, shapes) -> list:
    """The capture's distance channel (size, 2 size) as the probes' table holds it (a fourth chain,
    grey, at the radiance chain's level `shapes`, (h, w) each; only level 0 is read): each texel's
    distance over the distance from the probe to its proxy's side in that direction, 1 where no
    ray met the scene (an opening). On the proxy the ratio is 1 whatever the direction, so its
    bilinear read is too (a box's edges, where the distance itself bends, included), and the
    march keeps the box projection exactly there (kernels/reflection_probes.h rprobe_hit)."""
    h, w = depth.shape
    d = conventions.equirect_texel_dirs(w, h).reshape(-1, 3)
    ratio = np.where(depth > 0, depth / proxy_distance(settings, d).reshape(h, w), 1.0)
    out = []
    for lh, lw in shapes:            # nearest texel: a distance is not filtered across an edge
        rows, cols = (np.arange(lh) * h) // lh, (np.arange(lw) * w) // lw
        out.append(np.repeat(ratio[rows][:, cols, None], 3, -1).astype(np.float32))
    return out


def proxy_distance(settings: dict, d) -> np.ndarray:
    """The distance from the probe's position to its box's or sphere's side along directions d (m, 3)."""
    from iblbake.render.twin.reflection_probes import exit_point

    pos = np.asarray(settings["position"], np.float64)
    return np.linalg.norm(exit_point(settings, np.broadcast_to(pos, d.shape), d) - pos, axis=-1)


INSIDE_WARN = 0.25     # a capture whose rays meet this share of an object's inside is inside it


def influence_box(settings: dict) -> tuple:
    """The box (lo, hi) a probe's influence holds: its min/max, or its sphere's about position."""
    if settings.get("shape", "box") == "sphere":
        pos, r = np.asarray(settings["position"], np.float64), float(settings["radius"])
        return pos - r, pos + r
    return np.asarray(settings["min"], np.float64), np.asarray(settings["max"], np.float64)


def warnings(k: int, report: dict, scene_data: dict, bounds=None) -> list:
    """A capture from inside an object: its rays meet that object's inside over more than
    INSIDE_WARN of the sphere (the probe sees the object's inner walls, not the room); an
    influence wholly outside the scene's bounds (lo, hi): no surface reads the probe (a new user's
    box at 19..21 beside a room: the chrome sphere read the distant sky, 8x, nothing said)."""
    from iblbake.scene.load import object_label

    settings = scene_data["reflection_probes"][k]
    out = [f"reflection_probes.{k}: its position {settings['position']} lies inside "
           f"{object_label(scene_data, int(o))} ({100 * share:.0f}% of its capture sees that object's inside); add "
           f"it to reflection_probes.{k}.exclude or move the probe"
           for o, share in report.get("inside", {}).items() if share > INSIDE_WARN
           and int(o) < len(scene_data["objects"])]
    if bounds is not None:
        from iblbake.render.probes.grid import apart

        lo, hi = influence_box(settings)
        if apart(lo, hi, bounds):
            plain = lambda v: [round(float(x), 6) for x in v]
            out.append(f"reflection_probes.{k}: its influence {plain(lo)}..{plain(hi)} lies wholly outside the "
                       f"scene's bounds {plain(bounds[0])}..{plain(bounds[1])}: no surface reads it (the distant "
                       f"panorama instead); move reflection_probes.{k} over the part of the scene the camera sees")
    probes = scene_data["reflection_probes"]
    if k == OWN_MAX and any(p.get("exclude_ids") for p in probes):
        out.append(f"reflection_probes: {len(probes)} probes and some exclude objects: an object reads only the "
                   f"probes excluding it among the first {OWN_MAX} (kernels/reflection_probes.h "
                   f"RPROBE_OWN_MAX); reflection_probes.{OWN_MAX} and later blend as probes of other objects")
    return out


def excluded(scene_data: dict, settings: dict) -> list:
    """The objects a probe's capture looks through: its exclude list, and every object not seen
    by reflection captures (objects.N.reflection_captures: false)."""
    return sorted(set(settings.get("exclude_ids") or []) |
                  {i for i, o in enumerate(scene_data["objects"]) if not o["reflection_captures"]})


def tracer(job, settings: dict):
    """The paths' tracer (render/paths/tracer.py) on a job (render/units.py Job) for a capture: its
    rays meet what camera rays meet, from either side of a double-sided surface (the irradiance
    probes' rays see back faces: a probe inside geometry), but the excluded objects."""
    return Tracer(job, {"bounces": settings["bounces"], "seed": settings["seed"]}, back_faces_black=False,
                  skip_objects=excluded(job.scene.data, settings))
