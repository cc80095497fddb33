"""The BSDF of the glTF metallic-roughness material at a path's vertices, float64: Lambert's diffuse
lobe weighted by kD and GGX's specular lobe sampled by its visible normals, mixed by the specular
lobe's probability ps. Twin of kernels/bsdf.h (tests/test_bsdf.py holds the two together): its
evaluate, pdf and sample are the kernel's bsdf_eval, bsdf_pdf and bsdf_sample, vectorised over
vertices (rows). docs/conventions.md "Material model" and "Paths"."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from iblbake.core import brdf
from iblbake.core import conventions
from iblbake.core import sampling
from iblbake.core.metrics import luminance

# GGX lobes narrower than this alpha are mirrors (deltas) where a path samples them: float32 cannot
# resolve them (kernels/layout.h, generated from iblbake/scene/layout.py, which reads it here)
DELTA_ALPHA = 1e-4


class Material(NamedTuple):
    """A vertex's material as its BSDF reads it (rows): f0, f90 (N, 3) Schlick's F = f0 + (f90 -
    f0)(1 - VoH)^5; alpha (N,) = roughness^2; kd (N, 3) the diffuse weight kD base / pi at the
    vertex's NoV (kernels/surface.h diffuse_weight)."""
    f0: np.ndarray
    f90: np.ndarray
    alpha: np.ndarray
    kd: np.ndarray


def specular_probability(mt: Material, nov, diffuse: bool, specular: bool):
    """kernels/bsdf.h specular_probability: the specular lobe's share of the lobes' albedos
    (Schlick's F at NoV against kD pi), within [0.1, 0.9] where both exist, else 0 or 1; 1 for
    the specular term alone (F(NoV) is 0 for F0 = 0 head-on, F(VoH) elsewhere is not)."""
    nov = np.asarray(nov, np.float64)
    if not diffuse:
        return np.full(len(nov), 1.0 if specular else 0.0)
    s = luminance(brdf.f_schlick(nov[:, None], mt.f0, mt.f90)) if specular else np.zeros(len(nov))
    d = luminance(mt.kd * np.pi)
    with np.errstate(invalid="ignore", divide="ignore"):
        ps = np.clip(s / (s + d), 0.1, 0.9)
    return np.where(~(s > 0), 0.0, np.where(~(d > 0), 1.0, ps))


def ggx_lobe(mt: Material, v, n, nov, l, nol, ps):
    """kernels/bsdf.h ggx_lobe: (D V NoL, F(VoH) (..., 3), ps times the visible normals' pdf of l),
    h = normalize(v + l), D from |n x h|^2 and NoH^2 as the kernel's."""
    hv = v + l
    hv = hv / np.maximum(np.linalg.norm(hv, axis=-1, keepdims=True), 1e-300)
    noh, voh = np.maximum((n * hv).sum(-1), 0), np.maximum((v * hv).sum(-1), 0)
    cx = np.cross(n, hv)
    a = np.maximum(mt.alpha, 1e-30)
    dd = brdf.d_ggx_sc((cx * cx).sum(-1), noh * noh, a)
    pdf = ps * sampling.g1_smith(nov, a) * dd / (4 * nov)
    return dd * brdf.v_smith_ggx_correlated(nov, np.maximum(nol, 0), a) * np.maximum(nol, 0), \
        brdf.f_schlick(voh[..., None], mt.f0, mt.f90), pdf


def evaluate(mt: Material, v, n, nov, l, ps, diffuse: bool, specular: bool):
    """kernels/bsdf.h bsdf_eval: (f NoL (..., 3), pdf (...)) of the terms asked for at directions l;
    a delta lobe (alpha < DELTA_ALPHA) adds nothing. Rows, or any shapes that broadcast (vertices
    (c, 1) against directions (d,): the quadrature of twin/reference.py)."""
    nol = (n * l).sum(-1)
    ps = np.broadcast_to(np.asarray(ps, np.float64), nol.shape)
    f, pdf = np.zeros(nol.shape + (3,)), np.zeros(nol.shape)
    up = nol > 0
    if diffuse:
        f += mt.kd * np.maximum(nol, 0)[..., None]
        pdf += (1 - ps) * np.maximum(nol, 0) / np.pi
    if specular:
        lobe = up & (mt.alpha >= DELTA_ALPHA)
        dvn, fr, pg = ggx_lobe(mt, v, n, nov, l, nol, ps)
        f += np.where(lobe[..., None], fr * dvn[..., None], 0.0)
        pdf += np.where(lobe, pg, 0.0)
    return np.where(up[..., None], f, 0.0), np.where(up, pdf, 0.0)


def pdf(mt: Material, v, n, nov, l, ps, diffuse: bool, specular: bool):
    """kernels/bsdf.h bsdf_pdf: the pdf with which sample() picks l."""
    return evaluate(mt, v, n, nov, l, ps, diffuse, specular)[1]


def sample(mt: Material, v, n, nov, ps, diffuse: bool, specular: bool, u_lobe, u):
    """kernels/bsdf.h bsdf_sample: (f NoL / pdf (N, 3), direction (N, 3), pdf (N,), inf for a
    mirror): the specular lobe where u_lobe < ps (visible normals from u, the mirror for a delta
    lobe), else the cosine hemisphere from u; the frame is conventions.tangent_frame(n)."""
    nov = np.asarray(nov, np.float64)
    ps = np.broadcast_to(np.asarray(ps, np.float64), nov.shape)
    u_lobe = np.broadcast_to(np.asarray(u_lobe, np.float64), nov.shape)
    t, b = conventions.tangent_frame(n)
    spec = u_lobe < ps
    mirror = spec & (mt.alpha < DELTA_ALPHA)
    vl = np.stack([(v * t).sum(1), (v * b).sum(1), nov], -1)
    hl = sampling.sample_ggx_vndf(vl, np.maximum(mt.alpha, 1e-30), u)
    hs = t * hl[:, 0:1] + b * hl[:, 1:2] + n * hl[:, 2:3]
    l_spec = 2 * (v * hs).sum(1, keepdims=True) * hs - v
    ll = sampling.sample_cosine_hemisphere(u)
    l_cos = t * ll[:, 0:1] + b * ll[:, 1:2] + n * ll[:, 2:3]
    l = np.where(spec[:, None], l_spec, l_cos)
    l = np.where(mirror[:, None], 2 * nov[:, None] * n - v, l)
    f, p = evaluate(mt, v, n, nov, l, ps, diffuse, specular)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where((p > 0)[:, None], f / np.where(p > 0, p, 1)[:, None], 0.0)
        w_mirror = brdf.f_schlick(nov[:, None], mt.f0, mt.f90) / np.where(ps > 0, ps, 1)[:, None]
    return np.where(mirror[:, None], w_mirror, w), l, np.where(mirror, np.inf, p)
