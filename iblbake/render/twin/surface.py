"""What the lighting passes read of a G-buffer sample (kernels/surface.h): material, view vector,
shading normal, the diffuse weight, the panorama's rotation. numpy twin, float64."""

from __future__ import annotations

import math

import numpy as np

from iblbake.core import brdf
from iblbake.core import conventions


def fresnel(arrays, idx, base, metallic):
    """(F0, F90) of Schlick's Fresnel: the dielectric's (KHR_materials_specular, the table's third
    row) mixed with the metal's (base colour, 1) by metallic."""
    c = arrays.materials.astype(np.float64)[idx, 2]
    m = metallic[:, None]
    return c[:, :3] * (1 - m) + base * m, (c[:, 3:4] * (1 - m) + m) * np.ones(3)


def _materials(arrays, idx):
    m = arrays.materials.astype(np.float64)[idx]
    base, metallic, emissive, rough = m[:, 0, :3], m[:, 0, 3], m[:, 1, :3], m[:, 1, 3]
    return (base, metallic, emissive, rough) + fresnel(arrays, idx, base, metallic)


def facing_normal(n, v):
    nov = (n * v).sum(1, keepdims=True)
    bent = n + (1e-4 - nov) * v
    bent /= np.linalg.norm(bent, axis=1, keepdims=True)
    return np.where(nov >= 1e-4, n, bent)


def to_env(d, rotation_y_deg):
    return conventions.rotate_y(d, -rotation_y_deg)


def surface(gb, arrays):
    """Twin of surface_at for every hit sample: view vectors, bent shading normals, NoV and the
    material columns (base, metallic, emissive, roughness, F0, F90): from the material table, or
    resolve_materials()'s where it ran."""
    hit = gb["hit"]
    v = -gb["dir"][hit]
    if "resolved" in gb:
        base, metallic, emissive, rough, nrm, _occ = gb["resolved"]
        n = facing_normal(nrm, v)
        f0, f90 = fresnel(arrays, gb["material"][hit], base, metallic)
        return v, n, np.maximum((n * v).sum(1), 1e-4), (base, metallic, emissive, rough, f0, f90)
    n = facing_normal(gb["normal"][hit], v)
    return v, n, np.maximum((n * v).sum(1), 1e-4), _materials(arrays, gb["material"][hit])


def material_occlusion(gb):
    """The resolved materials' occlusion (1 without textures), per hit."""
    return gb["resolved"][5] if "resolved" in gb else np.ones(int(gb["hit"].sum()))


def diffuse_weight(base, metallic, rough, f0, f90, nov):
    kd = (1 - brdf.f_schlick_roughness(nov[:, None], f0, rough[:, None], f90)) * (1 - metallic[:, None])
    return kd * base / math.pi
