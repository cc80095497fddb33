"""Irradiance probes (kernels/probes.h): RTXGI's octahedral mapping and atlas layout, and the
irradiance at surface points from the eight probes around each. numpy twin, float64."""

from __future__ import annotations

import numpy as np

from iblbake.core.bases.probes import PROBE_BASES
from iblbake.scene.layout import PROBE_WEIGHTS

# DDGI's weights (Irradiance.hlsl), the kernel's and probes.glsl's: scene/layout.py PROBE_WEIGHTS
CRUSH, WRAP_FLOOR = PROBE_WEIGHTS["CRUSH"], PROBE_WEIGHTS["WRAP_FLOOR"]
CHEBYSHEV_FLOOR, TRILINEAR_FLOOR = PROBE_WEIGHTS["CHEBYSHEV_FLOOR"], PROBE_WEIGHTS["TRILINEAR_FLOOR"]
NEAR_DEAD = PROBE_WEIGHTS["NEAR_DEAD"]        # probe_irradiance's step: a side with a wall
STEP_REACH = PROBE_WEIGHTS["STEP_REACH"]      # and the farthest it goes on from a layer's read, in cells
STEP_FLOOR = PROBE_WEIGHTS["STEP_FLOOR"]      # and the share of the read it keeps at least


def octahedral(d):
    """DDGIGetOctahedralCoordinates: unit directions (..., 3) -> [-1, 1]^2, +z at the centre."""
    d = np.asarray(d, np.float64)
    uv = d[..., :2] / np.abs(d).sum(-1, keepdims=True)
    s = np.where(uv >= 0, 1.0, -1.0)
    folded = (1 - np.abs(uv[..., ::-1])) * s
    return np.where(d[..., 2:3] < 0, folded, uv)


def octahedral_direction(uv):
    """DDGIGetOctahedralDirection: the inverse of octahedral()."""
    uv = np.asarray(uv, np.float64)
    d = np.concatenate([uv, 1 - np.abs(uv).sum(-1, keepdims=True)], -1)
    s = np.where(uv >= 0, 1.0, -1.0)
    folded = (1 - np.abs(uv[..., ::-1])) * s
    d[..., :2] = np.where(d[..., 2:3] < 0, folded, d[..., :2])
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def texel_directions(n: int):
    """The directions of a probe's n x n interior texels, row by row (DDGIGetNormalizedOctahedral-
    Coordinates: texel centres)."""
    c = (np.arange(n) + 0.5) / n * 2 - 1
    u, v = np.meshgrid(c, c)
    return octahedral_direction(np.stack([u, v], -1)).reshape(-1, 3)


def probe_index(c, counts):
    """Probe index of grid coordinates c (..., 3) (RTXGI, right-handed, y up)."""
    nx, _ny, nz = counts
    return c[..., 1] * nx * nz + c[..., 2] * nx + c[..., 0]


def probe_coords(index, counts):
    """Grid coordinates (..., 3) of probe indices: the inverse of probe_index."""
    nx, _ny, nz = counts
    index = np.asarray(index)
    return np.stack([index % nx, index // (nx * nz), (index // nx) % nz], -1)


def tile_origin(index, n: int, counts):
    """(column, row) of the first texel of probe `index`'s tile (border included) in its atlas."""
    nx, _ny, nz = counts
    index = np.asarray(index)
    return np.stack([(index % nx + index // (nx * nz) * nx) * (n + 2), (index // nx) % nz * (n + 2)], -1)


def atlas_read(atlas, index, oct_uv, n: int, counts):
    """Bilinear reads of probe tiles at octahedral coordinates (DDGIGetProbeUV, then the filter)."""
    t0 = tile_origin(index, n, counts).astype(np.float64)
    x = t0[..., 0] + 0.5 * (n + 2) + oct_uv[..., 0] * 0.5 * n - 0.5
    y = t0[..., 1] + 0.5 * (n + 2) + oct_uv[..., 1] * 0.5 * n - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    a, b = atlas[y0, x0], atlas[y0, x0 + 1]
    c, d = atlas[y0 + 1, x0], atlas[y0 + 1, x0 + 1]
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


def irradiance_at(volume, index, n):
    """Each probe's own irradiance at normals n (>= 0)."""
    basis = PROBE_BASES[volume["representation"]]      # a coefficient basis evaluates itself (core/bases/probes.py)
    if not basis.atlas:
        e = basis.irradiance_at(volume["irradiance"], index, n, basis.options(volume["settings"]))
    else:
        e = atlas_read(volume["irradiance"], index, octahedral(n), volume["irradiance_texels"], volume["counts"])[..., :3]
    return np.maximum(e, 0.0)


def volume_weight(volume, p):
    """Twin of probe_volume_weight (RTXGI's DDGIGetVolumeBlendWeight): 1 inside the box of the
    probes' cells (half a cell beyond the outer probes along an axis with more than one)."""
    spacing = np.asarray(volume["spacing"], np.float64)
    n = np.asarray(volume["counts"], np.float64)
    half = 0.5 * spacing * np.where(n > 1, n, 0.0)
    delta = np.abs(p - (np.asarray(volume["origin"]) + 0.5 * spacing * (n - 1))) - half
    return (1 - np.clip(delta / spacing, 0, 1)).prod(-1)


SOURCE_NONE, SOURCE_CELL, SOURCE_NEAREST = 0, 1, 2      # kernels/probes.h PROBE_SOURCE_*


def specular_at(volume, index, spec):
    """Each probe's radiance along the warped lobe: sum_k s_k c_k of its basis block, >= 0
    (kernels/bases.h basis_weighted); spec (m, K) the lobe's weights at each point."""
    c = np.asarray(volume["irradiance"], np.float64)[index]          # (m, K, C)
    return np.maximum(0.0, np.einsum("mk,mkc->mc", spec, c))


def weight(volume, c, p, biased, n, visibility: bool, classification: bool):
    """Twin of probe_weight: the own weights (m,) of probes at grid coordinates c, their trilinear
    factors left out (DDGI's with visibility, 1 without), 0 for an inactive probe; no value read."""
    origin, spacing = np.asarray(volume["origin"], np.float64), np.asarray(volume["spacing"], np.float64)
    index = probe_index(c, np.asarray(volume["counts"]))
    data = volume["data"][index]
    live = data[:, 3] == 0 if classification else np.ones(len(p), bool)
    if not visibility:
        return np.where(live, 1.0, 0.0)
    pp = origin + c * spacing + data[:, :3]
    to_p = pp - p
    wrap = 0.5 * ((to_p / np.linalg.norm(to_p, axis=1, keepdims=True) * n).sum(1) + 1)
    w = wrap * wrap + WRAP_FLOOR
    to_probe = pp - biased
    dist = np.linalg.norm(to_probe, axis=1)
    m = atlas_read(volume["distance"], index, octahedral(-to_probe / dist[:, None]), volume["distance_texels"],
                   volume["counts"])
    var = np.abs(m[:, 0] ** 2 - m[:, 1])
    dv = dist - m[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        cheb = np.where(dist > m[:, 0], (var / (var + dv * dv)) ** 3, 1.0)
    w = np.maximum(1e-6, w * np.maximum(CHEBYSHEV_FLOOR, cheb))
    return np.where(live, np.where(w < CRUSH, w ** 3 / CRUSH ** 2, w), 0.0)


def contribution(volume, c, p, biased, n, falloff, visibility: bool, classification: bool, spec=None):
    """Twin of probe_contribution: (weight (m,), value (m, 3)) of probes at grid coordinates c: the
    own weight (weight()) times the factor falloff (trilinear, floored with visibility); the value
    the irradiance (its square root with visibility) or, given the specular lobe's weights spec
    (m, K), the radiance along it (linear)."""
    index = probe_index(c, np.asarray(volume["counts"]))
    e = irradiance_at(volume, index, n) if spec is None else specular_at(volume, index, spec)
    w = weight(volume, c, p, biased, n, visibility, classification)
    if visibility:
        return w * np.maximum(falloff, TRILINEAR_FLOOR).prod(1), np.sqrt(e) if spec is None else e
    return np.where(w > 0, falloff.prod(1), 0.0), e


def irradiance(volume, p, n, v, *, visibility: bool, classification: bool):
    """The irradiance part of irradiance_and_source."""
    return irradiance_and_source(volume, p, n, v, visibility=visibility, classification=classification)[0]


def cell(volume, x):
    """Twin of probe_cell: the grid cell of points x (m, 3), its lowest probe's (i, j, k) clamped to
    the grid, x's trilinear fractions in it (0-1), and x in grid units."""
    counts = np.asarray(volume["counts"])
    g = (x - np.asarray(volume["origin"], np.float64)) / np.asarray(volume["spacing"], np.float64)
    base = np.clip(np.floor(g).astype(int), 0, counts - 1)
    return base, np.clip(g - base, 0, 1), g


def irradiance_and_source(volume, p, n, v, *, visibility: bool, classification: bool, spec=None):
    """Twin of probe_irradiance (blend_and_source stepped from the layers to the point in a
    junction's cell: near_wall) and, given `spec`, of probe_blend's radiance along the lobe."""
    e, source = blend_and_source(volume, p, n, v, visibility=visibility, classification=classification, spec=spec)
    if spec is not None:
        return e, source
    return near_wall(volume, p, n, v, e, source, visibility, classification), source


def sides(volume, p, n, v, visibility: bool, classification: bool):
    """Twin of probe_sides: the probes' weight on either side of the (unbiased) cell of points p
    along each axis, the axis' own trilinear factor left out (side (m, 3, 2)), each side's weighted
    mean offset along the axis in cells (shift (m, 3, 2), the relocated probes': where the layer
    stands), the cell's lowest probe and p's fractions in it. Own weights only (weight(): no value
    read); the kernel shares the blend's where the cells overlap, the same weights."""
    counts, spacing = np.asarray(volume["counts"]), np.asarray(volume["spacing"], np.float64)
    biased = p + n * volume["normal_bias"] + v * volume["view_bias"]
    base, alpha, _ = cell(volume, p)
    side, shift = np.zeros((len(p), 3, 2)), np.zeros((len(p), 3, 2))
    for i in range(8):
        off = np.array([i & 1, (i >> 1) & 1, (i >> 2) & 1])
        c = np.clip(base + off, 0, counts - 1)
        w = weight(volume, c, p, biased, n, visibility, classification)
        o = np.asarray(volume["data"])[probe_index(c, counts), :3] / spacing
        f = np.where(off == 1, alpha, 1 - alpha)
        if visibility:
            f = np.maximum(f, TRILINEAR_FLOOR)
        for k in range(3):
            wk = w * np.prod(np.delete(f, k, axis=1), axis=1)
            side[:, k, off[k]] += wk
            shift[:, k, off[k]] += wk * o[:, k]
    return side, shift, base, alpha


def dead_sides(side):
    """Twin of probe_dead_side for every axis: (m, 3) 0 the low side under NEAR_DEAD of the weight
    (a wall's), 1 the high, -1 neither."""
    total = side.sum(2)
    return np.where(~(total > 0), -1, np.where(side[:, :, 0] < NEAR_DEAD * total, 0,
                                               np.where(side[:, :, 1] < NEAR_DEAD * total, 1, -1)))


def near_wall(volume, p, n, v, e, source, visibility: bool, classification: bool):
    """Twin of probe_irradiance's step: where one side of the point's own (unbiased) cell along an
    axis carries under NEAR_DEAD of the probes' weight (the axis' trilinear factor left out), on two
    axes or three, or on one with the cell one further along another axis (towards the point's nearer
    layer) having such a side on that axis (within a cell of a junction), the read e goes on linearly
    along each of the point's own walls from the live layer where its probes stand (their mean
    offset) to the point, by the reads one cell apart; the steps' sum kept within [STEP_FLOOR, 1] e:
    the step only darkens, and not to black."""
    if not (visibility or classification):
        return e                    # every probe weighs 1: no side is light
    counts, spacing = np.asarray(volume["counts"]), np.asarray(volume["spacing"], np.float64)
    side, shift, base, alpha = sides(volume, p, n, v, visibility, classification)
    dead = dead_sides(side)
    walls = (dead >= 0).sum(1)
    for k in range(3):
        rows = np.flatnonzero((walls == 1) & (dead[:, k] < 0) & (source == SOURCE_CELL))
        if not len(rows):
            continue
        q = p[rows].copy()
        q[:, k] += np.where(alpha[rows, k] < 0.5, -1.0, 1.0) * spacing[k]
        walls[rows] += dead_sides(sides(volume, q, n[rows], v[rows], visibility, classification)[0])[:, k] >= 0
    step = np.zeros_like(e)
    for k in range(3):
        for d in (0, 1):
            t = alpha[:, k] if d else 1 - alpha[:, k]
            nxt = base[:, k] - 1 if d else base[:, k] + 2
            rows = np.flatnonzero((dead[:, k] == d) & (counts[k] > 2) & (t > 1e-6) & (nxt >= 0)
                                  & (nxt <= counts[k] - 1) & (source == SOURCE_CELL) & (walls >= 2))
            if not len(rows):
                continue
            live = 1 - d
            o = (-1 if d else 1) * shift[rows, k, live] / side[rows, k, live]
            q = p[rows].copy()
            q[:, k] += (-1 if d else 1) * (t[rows] + 1) * spacing[k]
            e2, s2 = blend_and_source(volume, q, n[rows], v[rows], visibility=visibility,
                                      classification=classification)
            reach = np.minimum(np.maximum(t[rows] + o, 0.0) / np.maximum(1.0 - o, 0.25), STEP_REACH)
            step[rows] -= np.where((s2 == SOURCE_CELL)[:, None], reach[:, None] * (e2 - e[rows]), 0.0)
    return np.clip(e + step, STEP_FLOOR * e, e)


def blend_and_source(volume, p, n, v, *, visibility: bool, classification: bool, spec=None):
    """Twin of probe_blend for points p, normals n, view vectors v (m, 3): (irradiance (m, 3),
    source (m,): SOURCE_CELL the cell's eight probes, SOURCE_NEAREST the active probes of the 4^3
    around it by inverse square distance where all eight are off, SOURCE_NONE neither (0)).
    `volume`: counts, origin, spacing, normal_bias and view_bias (world units), data (probes, 4:
    offset in world units, state), representation, irradiance (sh: (probes, 9, 3); else the atlas),
    distance (the moments' atlas), irradiance_texels, distance_texels. With `spec` (m, K), the
    specular lobe's weights of a basis that carries one, the radiance along the lobe instead
    (kernels/probes.h probe_specular: the same weights, blended linearly)."""
    counts = np.asarray(volume["counts"])
    biased = p + n * volume["normal_bias"] + v * volume["view_bias"]
    base, alpha, g = cell(volume, biased)
    total = np.zeros((len(p), 3))
    wsum = np.zeros(len(p))
    for i in range(8):
        off = np.array([i & 1, (i >> 1) & 1, (i >> 2) & 1])
        w, value = contribution(volume, np.clip(base + off, 0, counts - 1), p, biased, n,
                                np.where(off == 1, alpha, 1 - alpha), visibility, classification, spec)
        total += w[:, None] * value
        wsum += w
    source = np.where(wsum > 0, SOURCE_CELL, SOURCE_NEAREST)
    wide = np.nonzero(wsum <= 0)[0]
    for dz in range(-1, 3):
        for dy in range(-1, 3):
            for dx in range(-1, 3):
                if not len(wide):
                    break
                c = base[wide] + [dx, dy, dz]
                inside = ((c >= 0) & (c < counts)).all(1)
                rows, c = wide[inside], c[inside]
                dc = c - g[rows]
                f = np.stack([1 / np.maximum((dc * dc).sum(1), 0.01), np.ones(len(rows)), np.ones(len(rows))], 1)
                w, value = contribution(volume, c, p[rows], biased[rows], n[rows], f, visibility, classification,
                                        None if spec is None else spec[rows])
                total[rows] += w[:, None] * value
                wsum[rows] += w
    source = np.where(wsum > 0, source, SOURCE_NONE)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(wsum[:, None] > 0, total / np.where(wsum > 0, wsum, 1)[:, None], 0.0)
    return (out * out if visibility and spec is None else out), source


def specular(volume, p, n, v, spec, sky):
    """Twin of probes_specular: the radiance along the warped lobe from the probes (spec (m, K) the
    lobe's weights, core/bases specular_weights), blended by the volume's weight with `sky` (the
    distant split sum's radiance) outside it and where no active probe is near."""
    wv = volume_weight(volume, p)[:, None]
    li, source = irradiance_and_source(volume, p, n, v, visibility=volume["visibility"],
                                       classification=volume["classification"], spec=spec)
    return (1 - wv) * sky + wv * np.where((source == SOURCE_NONE)[:, None], sky, li)
