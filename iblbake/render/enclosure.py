"""What the camera's surroundings earn a frame, said once a series. Inside a room: a split sum (or
any mode) that reads the distant panorama mirrors the sky there, not the room around it (a new
user's trial: +42% on a red wall of a closed room). Measured from the camera: the share of
ENCLOSED_RAYS directions (a spherical Fibonacci set) whose rays meet the scene; at ENCLOSED_SHARE
or more, and with no reflection probe read, the frame says so (docs/conventions.md "Reflection
probes"). Far outside the scene: a camera left unscaled in a scene scaled by 0.01 (trial74)
rendered the room as a few pixels of a sky frame, nothing said (far_camera)."""

from __future__ import annotations

import numpy as np

from iblbake.render.probes.grid import scene_bounds
from iblbake.render.probes.rays import spherical_fibonacci
from iblbake.render.twin.gbuffer import _plane_t, _sphere_t

ENCLOSED_RAYS = 256
FAR_SPAN = 0.125           # the scene's bounding sphere over the frame's height: under it, far_camera says so
ENCLOSED_SHARE = 0.9        # a room with a window or a door still counts; a floor alone, half, does not
DISTANT_READERS = ("importance", "prefiltered", "lobe")      # and the specular bases (core/bases.py)


def met_share(arrays, point, rays: int = ENCLOSED_RAYS) -> float:
    """The share of `rays` directions from `point` whose rays meet a sphere, plane or triangle of
    the scene (either side; float64)."""
    o = np.asarray(point, np.float64)
    d = spherical_fibonacci(rays).astype(np.float64)[:, :3]
    met = np.zeros(len(d), bool)
    for sp in arrays.spheres.astype(np.float64):
        met |= np.isfinite(_sphere_t(o, d, sp))
    for pl in arrays.planes.astype(np.float64):
        met |= np.isfinite(_plane_t(o, d, pl))
    for k in range(0, len(arrays.tris), 2048):      # triangles against every ray at once, in chunks
        met |= _meets_triangles(o, d, arrays.tris[k:k + 2048, :3, :3].astype(np.float64))
    return float(met.mean())


def _meets_triangles(o, d, v) -> np.ndarray:
    """Whether each ray o + t d (t > 0) meets any of the triangles v (n, 3, 3) (Moller-Trumbore)."""
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    p = np.cross(d[:, None], e2[None])                       # (rays, tris, 3)
    det = (p * e1[None]).sum(-1)
    sv = o - v[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        u = (sv[None] * p).sum(-1) * inv
        q = np.cross(sv, e1)
        w = (d @ q.T) * inv
        t = (q * e2).sum(-1)[None] * inv
    return ((det != 0) & (u >= 0) & (u <= 1) & (w >= 0) & (u + w <= 1) & (t > 0)).any(1)


def reads_distant_sky(scene, fx) -> bool:
    """Whether the frame's specular term (fx: render/plan.py Effects) reads the distant panorama
    alone, no reflection probe read, on some material with a specular lobe."""
    from iblbake.core import bases
    from iblbake.render.sources.reflection_probes import reflects_locally
    from iblbake.scene import materials

    if fx.specular not in DISTANT_READERS + tuple(bases.SPECULAR) or reflects_locally(scene, fx):
        return False
    return any(m["metallic"] > 0 or m["specular"] > 0 for m in materials.used(scene))


# the note's words (benchmarks/corpus_absolute.py leaves it out for its own distant rung)
DISTANT_NOTE = "reflects the distant panorama, but"


def warnings(scene, fx, arrays) -> list:
    """The frame's note where its specular term mirrors the distant sky from inside a room."""
    if not reads_distant_sky(scene, fx):
        return []
    cam = scene.data["camera"]
    share = met_share(arrays, cam[cam["projection"]]["position"])
    if share < ENCLOSED_SHARE:
        return []
    # a scene whose probes this render leaves unread (a study's distant rung, effects.reflection_probes:
    # false) is told so, not told to add one (trial72)
    remedy = ("its reflection probes are not read here (they are with effects.specular: prefiltered and "
              "effects.reflection_probes: true)" if scene.data["reflection_probes"]
              else "add a reflection probe (reflection_probes:, docs/scene.md)")
    return [f"effects.specular: {fx.specular} {DISTANT_NOTE} {100 * share:.0f}% of the "
            f"directions from the camera meet the scene (a room): its reflections show the sky, not the room; "
            f"{remedy} or use effects.specular: reference"]


def far_camera(scene, arrays) -> list:
    """The note where the camera stands outside the scene's bounds and their bounding sphere spans
    under FAR_SPAN of the frame's height (its angle over fov_y; orthographic: its diameter over the
    view's height): the frame is mostly sky, as a camera left at scale 1 in a scene scaled by 0.01
    renders it. None where an infinite plane is in the scene (it reaches the camera)."""
    bounds = scene_bounds(arrays)
    if bounds is None or len(arrays.planes) and not np.isfinite(arrays.planes[:, 2:4, 3]).all():
        return []
    lo, hi = (np.asarray(b, np.float64) for b in bounds)
    cam = scene.data["camera"]
    kind = cam["projection"]
    pos = np.asarray(cam[kind]["position"], np.float64)
    if ((pos >= lo) & (pos <= hi)).all():
        return []
    centre, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2
    dist = float(np.linalg.norm(pos - centre))
    w, h = cam["resolution"]
    if kind == "perspective":
        if dist <= radius:
            return []
        span = 2 * np.degrees(np.arcsin(radius / dist)) / cam[kind]["fov_y"]
    else:
        span = 2 * radius / (cam[kind]["width"] * h / w)
    if span >= FAR_SPAN:
        return []
    key = f"camera.{kind}.position"
    return [f"{key} {pos.tolist()} stands {dist:.3g} from the scene's centre, outside its bounds "
            f"({np.round(lo, 6).tolist()}..{np.round(hi, 6).tolist()}, {2 * radius:.3g} across): the scene spans "
            f"{100 * span:.1f}% of the frame's height; a camera not scaled with the scene? (move {key} and look_at)"]
