"""Helpers shared by the probe tests (test_probes*.py, test_sides.py): probe settings, synthetic
volumes, the probe kernel at chosen points, the probe scenes, and a bake store holding a given
volume."""

import math

import numpy as np

from iblbake.core import bases
from iblbake.render import probes, units
from iblbake.render.bakes import Bakes
from iblbake.render.sources.probes import probe_args, probe_defines
from tests.helpers import load_scene

def settings(**kw):
    """A probes section with the schema's defaults (docs/scene.md), some replaced."""
    from iblbake.scene.schema import SCHEMA
    return {**{k: f.default for k, f in SCHEMA.fields["probes"].fields.items()}, **kw}


def synthetic(counts, spacing, origin, rep="octahedral", value=None, rng=None, texels=6, dtexels=14, states=None):
    """A volume whose probe p holds value(position) (3,) at every direction, or random smooth
    irradiance (rng), with random but consistent distance moments."""
    grid = probes.Grid(tuple(origin), tuple(spacing), tuple(counts))
    pos = grid.positions()
    n = grid.count
    st = settings(irradiance=rep, irradiance_texels=texels, distance_texels=dtexels)
    if rep == "sh":
        irr = np.zeros((n, 9, 3))
        if value is not None:
            irr[:, 0] = np.array([value(p) for p in pos]) * math.sqrt(4 * math.pi)
        else:
            irr[:, 0] = rng.uniform(1, 3, (n, 3)) * math.sqrt(4 * math.pi)
            irr[:, 1:] = rng.uniform(-0.3, 0.3, (n, 8, 3))
    else:
        if value is not None:
            tiles = np.broadcast_to(np.array([value(p) for p in pos])[:, None, None, :], (n, texels, texels, 3))
        else:
            tiles = rng.uniform(0.5, 3, (n, texels, texels, 3))
        irr = probes.atlas(probes.with_borders(np.ascontiguousarray(tiles)), counts)
    mean = rng.uniform(0.2, 1.5, (n, dtexels, dtexels)) if rng is not None else np.full((n, dtexels, dtexels), 1.0)
    sq = mean ** 2 * (1 + (rng.uniform(0, 0.3, mean.shape) if rng is not None else 0.0))
    dist = probes.atlas(probes.with_borders(np.stack([mean, sq], -1)), counts)
    data = np.zeros((n, 4))
    if rng is not None:
        data[:, :3] = rng.uniform(-0.3, 0.3, (n, 3)) * np.asarray(spacing)
    if states is not None:
        data[:, 3] = states
    return probes.volume_dict(grid, st, irr, dist, data, {})


def kernel_irradiance(rt, vol, p, n, v, visibility, classification):
    """t_probes (kernels/selftest.cl) at points p, normals n, view directions v, with the volume's
    switches and its basis's options (a basis volume's settings carry them)."""
    defines = {"SH_BANDS": 3, **probe_defines({**vol.get("settings", {}), "irradiance": vol["representation"],
                                              "visibility": visibility, "classification": classification})}
    out = rt.empty(16 * len(p))

    def f4(a):
        return rt.to_device(np.pad(np.asarray(a, np.float32), ((0, 0), (0, 1))))
    rt.launch("selftest.cl", "t_probes", defines, (len(p),), {}, p=f4(p), n=f4(n), v=f4(v), out=out,
              **probe_args(rt, vol))
    return rt.read(out, (len(p), 4))[:, :3].astype(np.float64)


def unit(a):
    """Vectors (..., 3) normalised."""
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def far_sphere_scene(folder, sky, rep):
    """Probes around the origin; the only object a small sphere far away (no probe ray meets it)."""
    return load_scene(folder, f"far_{rep}", {
        "camera": {"perspective": {"position": [0, 0, 3], "look_at": [0, 0, 0]}, "resolution": [8, 8]},
        "environment": {"path": str(sky)},
        "materials": {"m": {"base_color": [0.8, 0.8, 0.8], "roughness": 1, "specular": 0}},
        "objects": [{"sphere": {"center": [500, 0, 0], "radius": 0.01}, "material": "m"}],
        "probes": {"min": [-1, -1, -1], "max": [1, 1, 1], "counts": [2, 2, 2], "irradiance": rep, "rays": 64,
                   "classification": False},
        "effects": {"diffuse": "probes", "specular": "off"}})


def sphere_scene(folder, sky, diffuse, rep="octahedral"):
    """A Lambert sphere in the uniform sky, shaded by `diffuse`."""
    return load_scene(folder, f"sphere_{diffuse}_{rep}", {
        "camera": {"perspective": {"position": [0, 0, 3], "look_at": [0, 0, 0], "fov_y": 40}, "resolution": [32, 32]},
        "environment": {"path": str(sky)},
        "materials": {"m": {"base_color": [0.8, 0.6, 0.4], "roughness": 1, "specular": 0}},
        "objects": [{"sphere": {"center": [0, 0, 0], "radius": 0.8}, "material": "m"}],
        "probes": {"min": [-2, -2, -2], "max": [2, 2, 2], "counts": [2, 2, 2], "irradiance": rep},   # probes at +-1
        "effects": {"diffuse": diffuse, "specular": "off"}})


class Given(Bakes):
    """A bake store whose probe volume is a given one (the far-sphere scene's, for another scene):
    its probes unit (render/units.py) loads that volume."""

    def __init__(self, root, volume):
        super().__init__(root)
        self.volume = volume

        class GivenProbes(units.Probes):
            def load(self, job):
                return volume, False, {}
        self.units = {**self.units, "probes": GivenProbes()}


def with_basis(sc, name, opts):
    """Scene `sc` with its probes in basis `name` with options `opts`."""
    sc.data["probes"].update(irradiance=name, **opts)
    return sc


def baked_volume(bakes):
    """The probe volume a render baked into the store `bakes`."""
    return bakes.result("probes")


def basis_volume(name, opts, rng, counts=(3, 2, 4), states=None):
    """synthetic()'s grid and distances, each probe holding its basis's fit of a random smooth sky."""
    vol = synthetic(counts, (0.5, 0.6, 0.4), (0, 0, 0), rng=rng, states=states)
    m = bases.BASES[name]
    dirs = probes.ray_directions(256, 3)
    n = int(np.prod(counts))
    a = rng.uniform(0.5, 2.0, (n, 1, 3))
    b = rng.normal(size=(n, 3, 3)) * 0.3
    sky = a + np.maximum(0, np.einsum("rj,pjc->prc", dirs, b))          # > 0, smooth, directional
    st = {**vol["settings"], "irradiance": name, **opts}
    return {**vol, "representation": name, "settings": st, "irradiance": m.project_rays(sky, dirs, opts)}
