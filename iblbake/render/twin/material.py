"""The material pass (kernels/material.cl): every G-buffer sample's material with its maps read. numpy twin, float64."""

from __future__ import annotations

import numpy as np

from iblbake.render.twin.gbuffer import _slot, map_uv


def resolve_materials(gb, arrays, tex):
    """Each hit's material from its factors and maps (kernels/material.cl): gb["resolved"] =
    (base, metallic, emissive, roughness, shading normal, occlusion) of the hits."""
    from iblbake.scene import textures as scene_textures

    hit = gb["hit"]
    idx = gb["material"][hit]
    m = arrays.materials.astype(np.float64)[idx]
    base, metallic, emissive, rough = m[:, 0, :3].copy(), m[:, 0, 3].copy(), m[:, 1, :3].copy(), m[:, 1, 3].copy()
    nrm, occ = gb["normal"][hit].copy(), np.ones(len(idx))
    uv01, lods, tan = gb["uv"][hit], gb["lod"][hit], gb["tangent"][hit]
    for mi in np.unique(idx):
        sel = idx == mi
        mm = tex["mat_maps"][mi]

        def fetch(kind):
            texture, texcoord, rows, offset = _slot(tex, mi, kind)
            if texture < 0:
                return None
            lod = lods[sel, 1 if texcoord == 1 else 0] + offset
            return scene_textures.sample(tex["set"].textures[texture], map_uv(rows, texcoord, uv01[sel]), lod)

        c = fetch("base_color")
        if c is not None:
            base[sel] *= c[:, :3]
        c = fetch("metallic_roughness")
        if c is not None:
            metallic[sel] *= c[:, 2]
            rough[sel] *= c[:, 1]
        c = fetch("normal")
        if c is not None:
            tn = c[:, :3].copy()
            tn[:, :2] *= mm[0, 2]
            nn = nrm[sel]
            bt = tan[sel, 3:4] * np.cross(nn, tan[sel, :3])
            pp = tan[sel, :3] * tn[:, 0:1] + bt * tn[:, 1:2] + nn * tn[:, 2:3]
            lp = np.linalg.norm(pp, axis=1, keepdims=True)
            nrm[sel] = np.where(lp > 1e-12, pp / np.maximum(lp, 1e-300), nn)
        c = fetch("occlusion")
        if c is not None:
            occ[sel] = 1 + mm[0, 3] * (c[:, 0] - 1)
        c = fetch("emissive")
        if c is not None:
            emissive[sel] *= c[:, :3]
    gb["resolved"] = (base, np.clip(metallic, 0, 1), emissive, np.clip(rough, 0, 1), nrm, np.clip(occ, 0, 1))
    return gb
