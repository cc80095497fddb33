"""The one table of what host and kernels must agree on: mode ids, primitive kinds, shared
constants and buffer record layouts.

kernels/layout.h is generated from it (`python -m iblbake.scene.layout > kernels/layout.h`);
tests/test_render_passes.py checks that the committed header is what this table emits.
"""

from __future__ import annotations

from iblbake.core.bsdf import DELTA_ALPHA
from iblbake.core.metrics import LUMINANCE
from iblbake.core.sampling import ENV_GUIDE_BINS

DIFFUSE_MODES = {"off": 0, "sh": 1, "reference": 2, "probes": 3, "basis": 4, "lightmap": 5}   # basis: core/bases DIFFUSE
SPECULAR_MODES = {"off": 0, "importance": 1, "prefiltered": 2, "reference": 3, "lobe": 4, "basis": 5,   # basis: core/bases SPECULAR
                  "probes": 6, "lightmap": 7}
BACKGROUND_MODES = {"hide": 0, "show": 1, "color": 2, "blur": 3}
TONEMAP_IDS = {"aces": 0, "reinhard": 1, "hable": 2, "pbr_neutral": 3, "linear": 4}
LIGHT_KINDS = {"directional": 0, "point": 1, "spot": 2}
SHADOW_MODES = {"none": 0, "hard": 1, "soft": 2}
# what a ray hit (kernels/scene.h Hit.kind; the twin's gb["kind"])
PRIM_KINDS = {"none": 0, "sphere": 1, "plane": 2, "triangle": 3}
# DELTA_ALPHA (core/bsdf.py, where the BSDF's twin reads it): GGX lobes narrower than this alpha
# (= roughness^2) are mirrors where a path samples them: float32 cannot resolve the lobe (D
# overflows, the half-vector warp collapses), so the BSDF takes the mirror direction with weight F
# (kernels/bsdf.h, render/twin, study/accuracy)
# ENV_GUIDE_BINS (core/sampling.py cdf_guides): the bins of the guide tables of the panorama's marginal
# CDF and of each row's, read by kernels/envmap.h
# random streams: a seed ^ its stream, so that two uses of one seed draw independent numbers
# (kernels/sampler.h; the reference's stream is the seed itself, each light's seed ^ pcg_hash(j + 1))
RANDOM_STREAMS = {"ao": 0x5A0}

# Records are float4 rows (ints stored bit-cast in float lanes); the host packs them in
# iblbake/scene/pack.py, the kernels index them with these strides.
FLOAT4S = {
    # (base_color, metallic), (emissive, roughness), (the dielectric's F0 times its specular weight, that
    # weight: its F90) of KHR_materials_specular; Schlick's F90 = mix(weight, 1, metallic)
    "MATERIAL": 3,
    "SPHERE": 2,     # (centre, radius), (material, object, surface flags, -)
    "PLANE": 5,      # (point, material), (normal, object), (tangent, half width), (bitangent, half depth),
                     # (surface flags, -, -, -)
    "TRIANGLE": 6,   # v0|material, v1|object, v2|surface flags, n0, n1, n2
    "BVH_NODE": 2,   # the binary tree's (GPUs): (min, first), (max, count)
    # the 4-wide tree's (CPUs): four children's min x, min y, min z, max x, max y, max z (a lane
    # each), their codes (int: a node's index, or -1 - a leaf's float4 offset in the same buffer),
    # padding (scene/bvh.py widen)
    "BVH4_NODE": 8,
    # a leaf's up to four triangles: v0 x, y, z, v1 x, y, z, v2 x, y, z (a lane each), (first, count |
    # int) (scene/bvh.py device_tree)
    "BVH4_LEAF": 10,
    # (position, or the unit direction towards a directional light | kind), (colour x intensity or
    # illuminance | shadow mode), (spot axis, the way light travels | radius, or a directional
    # light's angular radius in radians), (spot scale, spot offset, range (0: none), shadow samples)
    "LIGHT": 4,
    # per corner (u0, v0, u1, v1) of TEXCOORD_0 and _1 (glTF's: v down the image), per corner the
    # tangent (xyz, w: the bitangent's side), and (0.5 log2 of UV area per world area of each set, -, -)
    "TRIANGLE_ATTR": 7,
    # (alpha, alpha cutoff (-1: opaque), normal scale, occlusion strength), (1: single-sided, -, -, -),
    # then per map kind (MAP_KINDS order) three rows: the UV transform's rows (m00 m01 m02 | texture
    # index, -1 none) and (m10 m11 m12 | texcoord set), and (0.5 log2(w h |det M|) of its texture, -, -, -)
    "MATERIAL_MAPS": 17,
}
MAP_KINDS = ("base_color", "metallic_roughness", "normal", "occlusion", "emissive")
# a primitive's surface flags: its material asks for a test at every hit (single-sided, alpha-masked);
# it bounds a solid, whose inside an irradiance probe's ray meets from behind its normal (flipped:
# in front of it, a closed mesh wound inwards) (docs/conventions.md "Sides")
SURFACE_FLAGS = {"single_sided": 1, "alpha_mask": 2, "solid": 4, "solid_flipped": 8}
# Per-sample G-buffer records, one float4 each: what every pass reads by these names.
GBUFFER = {
    "gb_pos": "hit position, w: distance along the ray (MISS_T where nothing is hit)",
    "gb_nrm": "shading normal facing the viewer, w: material index",
    "gb_dir": "primary ray direction, w: object index",
    # with textures (HAS_TEXTURES): the G-buffer pass's surface coordinates, the material pass's output
    "gb_uv": "TEXCOORD_0 and TEXCOORD_1 at the hit (u0, v0, u1, v1)",
    "gb_tan": "unit tangent (the direction of increasing u), w: the bitangent's side",
    "gb_lod": "mip level of the hit's footprint for each set, before the texture's size (x, y)",
    # with a lightmap (HAS_LIGHTMAP): where the hit lies in its atlas (kernels/lightmap.h lightmap_uv)
    "gb_lm": "UV1 in the lightmap's texel units (u, v), z: 1 where the hit has a lightmap, else 0",
    "gb_mat": "3 per sample: (base colour, metallic), (emissive, roughness), (shading normal, occlusion)",
}
MISS_T = -1.0
# The irradiance probe volume as the kernels read it (kernels/probes.h PROBE_PARAMS' probe_volume), one
# record shared by host and shader as RTXGI's DDGIVolumeDescGPU: field -> (row, first lane, lanes,
# type). Lengths in world units; the names are a sampled volume's keys (render/probes/volume.py
# sampled), which pack_probe_volume packs and probes.glsl writes as PROBE_<NAME> in this order.
PROBE_VOLUME = {
    "counts": (2, 0, 3, "int"),              # probes along x, y, z
    "origin": (0, 0, 3, "float"),            # probe (0, 0, 0)'s grid position
    "spacing": (1, 0, 3, "float"),           # the cell
    "normal_bias": (0, 3, 1, "float"),       # the sample point moved along the normal
    "view_bias": (1, 3, 1, "float"),         # ... and towards the viewer
    "irradiance_texels": (2, 3, 1, "int"),   # an octahedral tile's interior texels per side
    "distance_texels": (3, 0, 1, "int"),     # ... of the distance moments' tile
}
FLOAT4S["PROBE_VOLUME"] = 4
# DDGI's weights (RTXGI Irradiance.hlsl DDGIGetVolumeIrradiance), the one value of each for the kernel
# (layout.h), the twin (render/twin/probes.py) and probes.glsl (render/probes/glsl.py)
PROBE_WEIGHTS = {
    "WRAP_FLOOR": 0.2,          # the wrap-shading term's offset: a probe behind the surface still counts
    "CHEBYSHEV_FLOOR": 0.05,    # visibility never quite 0: some probe must count
    "CRUSH": 0.2,               # weights below it are crushed, w^3 / CRUSH^2
    "TRILINEAR_FLOOR": 0.001,   # the trilinear weight's floor, with visibility
    "NEAR_DEAD": 0.05,          # a side of a point's cell under this share of the weight: a wall's (probe_irradiance)
    "STEP_REACH": 0.4,          # probe_irradiance's step goes on from a layer's read at most this many cells
    "STEP_FLOOR": 0.5,          # and keeps at least this share of the read (its line past a bright layer went
                                # below 0: a new user's L-shaped room's inner corner, black where the truth is x0.8)
}
# entries of the kernels' traversal stack of the 4-wide BVH (kernels/scene.h trace_range): a node
# pushes at most 4 and pops one, so a tree of d levels needs 3 d + 1 (scene/bvh.py widen checks)
BVH_STACK = 96
# the paths (kernels/paths/paths.h and its twin render/twin/paths.py): bounces before Russian roulette
# (pbrt-v4: 1, Mitsuba 3: 5; of 3, 4 and 5 the least time to 1% on the Mitsuba scenes, docs/benchmarks.md),
# and a float-safety cap on unbounded paths (survival <= 0.95 per bounce)
RR_DEPTH = 4
MAX_PATH = 256


def pack_probe_volume(volume: dict) -> "np.ndarray":
    """PROBE_VOLUME's float4 rows (float32; int fields bit-cast) of a sampled volume's values."""
    import numpy as np
    rows = np.zeros((FLOAT4S["PROBE_VOLUME"], 4), np.float32)
    ints = rows.view(np.int32)
    for name, (row, lane, n, kind) in PROBE_VOLUME.items():
        (ints if kind == "int" else rows)[row, lane:lane + n] = volume[name]
    return rows


def _probe_volume_lines() -> list[str]:
    """The record's fields as accessors of its rows v (kernels/probes.h PROBE_VOLUME_LOCALS)."""
    out = []
    for k, (r, lane, n, kind) in PROBE_VOLUME.items():
        get = f"(v)[{r}].{'xyzw'[lane:lane + n]}"
        out.append(f"#define PROBE_VOLUME_{k.upper()}(v) "
                   + (f"as_int{n if n > 1 else ''}({get})" if kind == "int" else f"({get})"))
    return out


def _modes(prefix: str, table: dict) -> list[str]:
    return [f"#define {prefix}_{k.upper()} {v}" for k, v in table.items()]


def header_text() -> str:
    rows = ["/* Generated by `python -m iblbake.scene.layout` from iblbake/scene/layout.py: do not edit.",
            " * Mode ids and buffer record layouts shared by the host and every render kernel. */",
            "#ifndef IBLBAKE_LAYOUT_H", "#define IBLBAKE_LAYOUT_H", ""]
    rows += _modes("DIFFUSE", DIFFUSE_MODES) + _modes("SPECULAR", SPECULAR_MODES)
    rows += _modes("BACKGROUND", BACKGROUND_MODES) + _modes("TONEMAP", TONEMAP_IDS)
    rows += _modes("LIGHT", LIGHT_KINDS) + _modes("SHADOWS", SHADOW_MODES) + _modes("PRIM", PRIM_KINDS)
    rows += [f"#define MAP_{k.upper()} {i}" for i, k in enumerate(MAP_KINDS)]
    rows += [f"#define SURFACE_{k.upper()} {v}" for k, v in SURFACE_FLAGS.items()] + [""]
    rows += [f"#define {k}_FLOAT4S {v}" for k, v in FLOAT4S.items()] + [""]
    rows += [f"/* {k}: {v} */" for k, v in GBUFFER.items()]
    rows += [f"#define MISS_T ({MISS_T}f)", f"#define DELTA_ALPHA {DELTA_ALPHA!r}f",
             f"#define ENV_GUIDE_BINS {ENV_GUIDE_BINS}", f"#define BVH_STACK {BVH_STACK}",
             f"#define RR_DEPTH {RR_DEPTH}", f"#define MAX_PATH {MAX_PATH}"]
    rows += [f"#define LUMINANCE_{c} {w!r}f" for c, w in zip("RGB", LUMINANCE.tolist())]
    rows += [f"#define STREAM_{k.upper()} {v:#x}u" for k, v in RANDOM_STREAMS.items()]
    rows += [""] + _probe_volume_lines() + [f"#define PROBE_{k} {v!r}f" for k, v in PROBE_WEIGHTS.items()]
    rows += ["", "#endif", ""]
    return "\n".join(rows)


def basis_headers_text() -> str:
    """kernels/basis_headers.h: every directional basis's header (core/bases BASES' HEADER, in
    their order), which kernels/bases.h includes; a new basis's module lists its own."""
    from iblbake.core.bases import BASES
    return "\n".join(["/* Generated by `python -m iblbake.scene.layout basis_headers` from core/bases (each basis's",
                      " * HEADER): do not edit. kernels/bases.h includes it; a header's code compiles where its",
                      " * BASIS_<NAME> is defined. */"]
                     + [f'#include "{m.HEADER}"' for m in BASES.values() if m.HEADER] + [""])


if __name__ == "__main__":
    import sys
    print(basis_headers_text() if sys.argv[1:] == ["basis_headers"] else header_text(), end="")
