"""`iblbake render`: plan the effect set of a scene, bake what it reads, run the passes.

plan(scene) decides, from the scene alone, which terms exist (the kernel defines), which bakes
they read and which passes run; render() carries the plan out and returns the frame and a report
of every bake and pass with its time, cache hit or miss, and the device.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iblbake.bake import cache
from iblbake.bake.radiance import to_rgba
from iblbake.device import runtime as cl
from iblbake.core import sampling
from iblbake.errors import IblbakeError
from iblbake.scene.load import Scene

DIFFUSE_MODES = {"off": 0, "sh": 1, "reference": 2}
SPECULAR_MODES = {"off": 0, "importance": 1, "prefiltered": 2, "reference": 3}
BACKGROUND_MODES = {"hide": 0, "show": 1, "color": 2, "blur": 3}
TONEMAP_IDS = {"aces": 0, "reinhard": 1, "hable": 2, "pbr_neutral": 3, "linear": 4}
SH_FORMAT_VERSION = 1


@dataclass
class Plan:
    diffuse: str
    specular: str
    background: str
    emissive: bool
    bakes: list            # names, in order: sh, radiance, prefiltered, dfg, env_cdf
    passes: list           # gbuffer, shade, reference, background, resolve, tonemap
    defines: dict          # render.cl build options
    notes: list = field(default_factory=list)

    def to_json(self):
        return {"diffuse": self.diffuse, "specular": self.specular, "background": self.background,
                "emissive": self.emissive, "bakes": self.bakes, "passes": self.passes,
                "defines": self.defines, "notes": self.notes}


def plan(scene: Scene) -> Plan:
    """The effect set: only what the scene calls for, and only what some output reads."""
    d = scene.data
    fx, env, out = d["effects"], d["environment"], d["output"]
    notes = []
    used = {o["material"] for o in d["objects"]}
    mats = [d["materials"][m] for m in used]
    diffuse, specular = fx["diffuse"], fx["specular"]
    if not d["objects"]:
        if diffuse != "off" or specular != "off":
            notes.append("no objects: no lighting is computed")
        diffuse = specular = "off"
    elif diffuse != "off" and all(m["metallic"] >= 1.0 or max(m["base_color"]) == 0.0 for m in mats):
        notes.append(f"diffuse {diffuse} skipped: every material is metallic or black (kD = 0)")
        diffuse = "off"
    emissive = any(max(m["emissive"]) > 0 for m in mats)
    bg = env["background"]
    if isinstance(bg, list):
        background = "color"
    elif bg == "show":
        background = "blur" if env["blur"] > 0 else "show"
    else:
        background = "hide"
    bakes = []
    if diffuse == "sh":
        bakes.append("sh")
    if specular == "importance":
        bakes.append("radiance")
    if specular == "prefiltered" or background == "blur":
        bakes.append("prefiltered")
    if specular == "prefiltered":
        bakes.append("dfg")
    if "reference" in (diffuse, specular):
        bakes.append("env_cdf")
    passes = ["gbuffer"]
    if diffuse == "sh" or specular in ("importance", "prefiltered") or emissive:
        passes.append("shade")
    if "reference" in (diffuse, specular):
        passes.append("reference")
    if background != "hide":
        passes.append("background")
    passes.append("resolve")
    if any(p.lower().endswith(".png") for p in out["frame"]):
        passes.append("tonemap")
    if not out["frame"] and not any(out[a] for a in ("normal", "albedo", "depth")):
        notes.append("no output requested (output.frame or -o): rendering without writing")
    defines = {"DIFFUSE_MODE": DIFFUSE_MODES[diffuse], "SPECULAR_MODE": SPECULAR_MODES[specular],
               "BACKGROUND": BACKGROUND_MODES[background]}
    if diffuse == "sh":
        defines["SH_BANDS"] = fx["sh_bands"]
    if specular == "importance":
        if fx["force_mip0"]:
            defines["FORCE_MIP0"] = 1
        if fx["normalize"] == "accepted":
            defines["IMPORTANCE_ACCEPTED"] = 1
    if specular == "prefiltered" and fx["prefilter"]["dominant_direction"]:
        defines["DOMINANT_DIRECTION"] = 1
    if emissive:
        defines["HAS_EMISSIVE"] = 1
    kinds = {k for o in d["objects"] for k in ("sphere", "plane", "mesh") if k in o}
    for k, name in (("sphere", "HAS_SPHERES"), ("plane", "HAS_PLANES"), ("mesh", "HAS_TRIANGLES")):
        if k in kinds:
            defines[name] = 1
    if any(out[a] for a in ("normal", "albedo", "depth")):
        defines["WRITE_AOVS"] = 1
    return Plan(diffuse, specular, background, emissive, bakes, passes, defines, notes)


# ---------------------------------------------------------------------------------------------
# Host-side scene arrays (shared with the numpy twin renderer)


def camera_vectors(cam: dict):
    """(origin, forward, right*half_width, up*half_height, orthographic) in float64."""
    w, h = cam["resolution"]
    proj = cam["projection"]
    c = cam[proj]
    pos = np.asarray(c["position"], np.float64)
    fwd = np.asarray(c["look_at"], np.float64) - pos
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.asarray(c["up"], np.float64))
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    if proj == "perspective":
        hh = math.tan(math.radians(c["fov_y"]) / 2)
        hw = hh * w / h
    else:
        hw = c["width"] / 2
        hh = hw * h / w
    return pos, fwd, right * hw, up * hh, proj == "orthographic"


def pixel_jitter(spp: int):
    """Sub-pixel sample positions: the centre for spp = 1, else a centred Hammersley set."""
    if spp == 1:
        return np.array([[0.5, 0.5]])
    pts = sampling.hammersley(spp).astype(np.float64)
    return np.mod(pts + 0.5 / spp, 1.0)


@dataclass
class SceneArrays:
    materials: np.ndarray     # (m, 2, 4) float32
    material_names: list
    spheres: np.ndarray       # (s, 2, 4) float32
    planes: np.ndarray        # (p, 4, 4) float32
    tris: np.ndarray          # (t, 6, 4) float32, BVH order: v0|material, v1|object, v2, 3 normals
    bvh: np.ndarray           # (nodes, 8) float32
    geometry_report: dict


def _int_bits(x):
    return np.asarray(x, np.int32).view(np.float32)


def scene_arrays(scene: Scene) -> SceneArrays:
    from iblbake.scene import geometry

    d = scene.data
    names = list(d["materials"])
    index = {n: i for i, n in enumerate(names)}
    mats = np.zeros((max(len(names), 1), 2, 4), np.float32)
    for i, n in enumerate(names):
        m = d["materials"][n]
        mats[i, 0, :3], mats[i, 0, 3] = m["base_color"], m["metallic"]
        mats[i, 1, :3], mats[i, 1, 3] = m["emissive"], m["roughness"]
    spheres, planes = [], []
    for oid, o in enumerate(d["objects"]):
        if "sphere" in o:
            s = np.zeros((2, 4), np.float32)
            s[0, :3], s[0, 3] = o["sphere"]["center"], o["sphere"]["radius"]
            s[1, 0], s[1, 1] = _int_bits(index[o["material"]]), _int_bits(oid)
            spheres.append(s)
        elif "plane" in o:
            p = o["plane"]
            n, t, b = geometry.plane_frame(p["normal"])
            size = p["size"]
            hw, hd = (math.inf, math.inf) if size is None else \
                ((size / 2, size / 2) if not isinstance(size, list) else (size[0] / 2, size[1] / 2))
            a = np.zeros((4, 4), np.float32)
            a[0, :3], a[0, 3] = p["point"], _int_bits(index[o["material"]])
            a[1, :3], a[1, 3] = n, _int_bits(oid)
            a[2, :3], a[2, 3] = t, hw
            a[3, :3], a[3, 3] = b, hd
            planes.append(a)
    t0 = time.perf_counter()
    tris = geometry.build_triangles(d["objects"], index, scene.source)
    load_s = time.perf_counter() - t0
    report = {"meshes": tris.stats, "triangles": len(tris), "load_s": round(load_s, 4)}
    if len(tris):
        lo, hi = geometry.triangle_bounds(tris)
        bvh = geometry.build_bvh(lo, hi)
        o = bvh.order
        arr = np.zeros((len(tris), 6, 4), np.float32)
        arr[:, 0, :3], arr[:, 0, 3] = tris.v0[o], _int_bits(tris.material[o])
        arr[:, 1, :3], arr[:, 1, 3] = tris.v1[o], _int_bits(tris.object_id[o])
        arr[:, 2, :3] = tris.v2[o]
        arr[:, 3:6, :3] = tris.normals[o]
        nodes = bvh.nodes
        report.update({"bvh_build_s": round(bvh.build_s, 4), "bvh_nodes": bvh.node_count, "bvh_depth": bvh.depth})
    else:
        arr = np.zeros((0, 6, 4), np.float32)
        nodes = np.zeros((0, 8), np.float32)
    return SceneArrays(mats, names, np.array(spheres, np.float32).reshape(-1, 2, 4),
                       np.array(planes, np.float32).reshape(-1, 4, 4), arr, nodes, report)


def env_sampling_tables(image):
    """Piecewise-constant environment sampling over texels: p(texel) proportional to
    luminance x exact solid angle. Returns (marginal cdf (H+1), conditional cdfs (H, W+1),
    pdf over solid angle per texel (H, W)), float32, built in float64."""
    from iblbake.core import conventions

    h, w = image.shape[:2]
    lum = np.maximum(image[..., :3].astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722]), 0.0)
    omega = conventions.equirect_row_solid_angles(w, h)
    weight = lum * omega[:, None]
    total = weight.sum()
    if not total > 0:                     # a black panorama: sample by solid angle
        weight = np.broadcast_to(omega[:, None], (h, w)).copy()
        total = weight.sum()
    row = weight.sum(axis=1)
    marginal = np.concatenate([[0.0], np.cumsum(row)]) / total
    marginal[-1] = 1.0
    cond = np.zeros((h, w + 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.cumsum(weight, axis=1) / row[:, None]
    cond[:, 1:] = np.where(row[:, None] > 0, c, (np.arange(1, w + 1) / w)[None, :])
    cond[:, -1] = 1.0
    pdf = weight / total / omega[:, None]
    return marginal.astype(np.float32), cond.astype(np.float32), pdf.astype(np.float32)


def sh_irradiance_coeffs(image, bands: int, window: str, backend: str, rt):
    from iblbake.core import sh
    from iblbake.bake import sh as shbake

    coeffs, _ = shbake.project(image, bands, backend, rt)
    return coeffs * sh.window(bands, window)[:, None] * sh.ahat(bands)[:, None]


def reference_noise(lum_sum, odd_sum, taken: int) -> float:
    """Relative standard error of the reference frame, from its two independent replicates
    (even and odd sample numbers): the RMS over pixels of half their difference, divided by the
    mean pixel luminance."""
    n_odd = taken // 2
    n_even = taken - n_odd
    even = (lum_sum - odd_sum) / n_even
    odd = odd_sum / max(n_odd, 1)
    mean = (lum_sum / taken).mean()
    if mean <= 0:
        return 0.0
    return math.sqrt(np.mean((even - odd) ** 2) / 4.0) / mean


# ---------------------------------------------------------------------------------------------


class Report:
    def __init__(self, device: str):
        self.device = device
        self.bakes: list = []
        self.passes: list = []

    def bake(self, name, seconds, cached, **extra):
        self.bakes.append({"name": name, "seconds": round(seconds, 4), "cached": cached, **extra})

    def run(self, name, seconds, **extra):
        self.passes.append({"name": name, "seconds": round(seconds, 4), **extra})


@dataclass
class Frame:
    hdr: np.ndarray                 # (h, w, 4) linear RGB + coverage
    png: np.ndarray | None          # (h, w, 3) uint8
    aovs: dict
    report: dict


def _chain_buffers(rt, levels):
    """One buffer of levels back to back (RGBA) and the offset/size tables chain_lookup reads."""
    from iblbake.bake import radiance

    offs, lws, lhs, parts = [], [], [], []
    o = 0
    for lvl in levels:
        h, w = lvl.shape[:2]
        offs.append(o)
        lws.append(w)
        lhs.append(h)
        parts.append(radiance.to_rgba(lvl).reshape(-1, 4))
        o += w * h
    data = np.concatenate(parts).astype(np.float32)
    consts = [rt.to_device(np.asarray(x, np.int32)) for x in (offs, lws, lhs)]
    return rt.to_device(data), consts, len(levels)


def render(scene: Scene, *, device: str | None = None, cache_root: Path | None = None,
           warn=None, progress=None) -> Frame:
    from iblbake.io import images
    from iblbake.bake import layouts
    from iblbake.bake import mips as mipsbake

    t_start = time.perf_counter()
    pl = plan(scene)
    d = scene.data
    fx, env, cam, out = d["effects"], d["environment"], d["camera"], d["output"]
    rt = cl.Runtime(device)
    rep = Report(rt.device_label)
    root = Path(cache_root) if cache_root else cache.default_root()
    warn = warn or (lambda _m: None)

    # ---- geometry
    t0 = time.perf_counter()
    arrays = scene_arrays(scene)
    rep.bake("geometry", time.perf_counter() - t0, False, **arrays.geometry_report)

    # ---- environment: read only when some bake or pass reads it
    needs_env = bool(pl.bakes) or pl.background in ("show", "blur")
    image = info = None
    if needs_env:
        t0 = time.perf_counter()
        image, info = images.read_panorama(env["path"], nonfinite=env["nonfinite"], negative=env["negative"],
                                          names={"nonfinite": "environment.nonfinite:",
                                                 "negative": "environment.negative:"})
        for w in info.warnings:
            warn(w)
        rep.bake("read_environment", time.perf_counter() - t0, False, path=info.path,
                 size=[info.width, info.height])
    policies = {"nonfinite": env["nonfinite"], "negative": env["negative"]}
    baker = mipsbake.Baker("opencl", rt=rt)
    sh_coeffs = chain = prefiltered = dfg_table = cdf = None

    if "sh" in pl.bakes:
        t0 = time.perf_counter()
        bands, window = fx["sh_bands"], fx["sh_window"]
        key = "sh-" + cache.content_key({"kind": "sh", "v": SH_FORMAT_VERSION, "input": info.sha256,
                                         "bands": bands, "window": window, "policies": policies,
                                         "kernel": cl.source_hash("sh_project.cl")})

        def build_sh(tmp: Path):
            from iblbake.io.atomic import write_json
            e = sh_irradiance_coeffs(image, bands, window, "opencl", rt)
            write_json(tmp / "irradiance.json", {"bands": bands, "window": window,
                                                 "irradiance": e.tolist()})
            return {"kind": "sh", "files": [{"name": "irradiance.json"}], "parameters":
                    {"bands": bands, "window": window, **policies}, "input": info.to_json(),
                    "device": rt.device_label}

        manifest, cached = cache.get_or_build(root, key, build_sh, warn=warn)
        import json
        sh_coeffs = np.asarray(json.loads((root / manifest["key"] / "irradiance.json").read_text())["irradiance"])
        rep.bake("sh", time.perf_counter() - t0, cached, bands=bands, entry=str(root / manifest["key"]))

    if "radiance" in pl.bakes:
        t0 = time.perf_counter()
        manifest, cached, levels = mipsbake.bake_radiance(baker, image, info, root, policies, warn=warn)
        chain = levels if levels is not None else mipsbake.load_chain(root, manifest)
        rep.bake("radiance", time.perf_counter() - t0, cached, levels=len(chain), entry=str(root / manifest["key"]))

    if "prefiltered" in pl.bakes:
        t0 = time.perf_counter()
        p = fx["prefilter"]
        opts = mipsbake.PrefilterOptions("equirect", p["size"], p["levels"], layouts.MIN_LEVEL_SIZE, p["method"],
                                         p["samples"], p["lod_bias"], True).resolved(info.height)
        state = {"chain": chain}

        def chain_levels():
            if state["chain"] is None:      # the radiance chain in memory only: no radiance entry
                state["chain"] = baker.radiance_chain(image)
            return state["chain"]

        pm, cached = mipsbake.bake_prefiltered(baker, chain_levels, info, root, policies, opts, warn=warn)
        prefiltered = [images.read_exr(root / pm["key"] / f["name"])[..., :3] for f in pm["files"]]
        rep.bake("prefiltered", time.perf_counter() - t0, cached, levels=len(prefiltered),
                 methods=[f["method"] for f in pm["files"]], entry=str(root / pm["key"]))

    if "dfg" in pl.bakes:
        t0 = time.perf_counter()
        p = fx["prefilter"]
        dm, cached = mipsbake.bake_dfg(baker, root, p["dfg_size"], p["dfg_samples"], False, warn=warn)
        dfg_table = images.read_exr(root / dm["key"] / "dfg.exr")[..., :2]
        rep.bake("dfg", time.perf_counter() - t0, cached, size=p["dfg_size"], entry=str(root / dm["key"]))

    if "env_cdf" in pl.bakes:
        t0 = time.perf_counter()
        cdf = env_sampling_tables(image)
        rep.bake("env_cdf", time.perf_counter() - t0, False)

    # ---- passes
    width, height = cam["resolution"]
    spp = cam["spp"]
    n = width * height * spp
    npix = width * height
    prog_defines = dict(pl.defines)
    rot = math.radians(env["rotation_y"])
    env_rot = np.array([math.cos(rot), math.sin(rot)], np.float32)
    env_scale = np.float32(env["intensity"])
    mats_buf = rt.to_device(arrays.materials.reshape(-1, 4))
    dummy = rt.to_device(np.zeros(4, np.float32))
    zeros_i = rt.to_device(np.zeros(4, np.int32))

    def kern(name):
        return rt.kernel("render.cl", name, prog_defines)

    gb_pos, gb_nrm, gb_dir = rt.empty(n * 16), rt.empty(n * 16), rt.empty(n * 16)
    radiance = rt.empty(n * 16)
    rt.cl.enqueue_fill_buffer(rt.queue, radiance, np.float32(0), 0, n * 16)
    # primary rays: every sample, hit or not (the background pass reads the miss directions)
    k = kern("gbuffer")
    pos, fwd, right, up, ortho = camera_vectors(cam)
    cam4 = np.zeros((4, 4), np.float32)
    cam4[0, :3], cam4[0, 3] = pos, 1.0 if ortho else 0.0
    cam4[1, :3], cam4[2, :3], cam4[3, :3] = fwd, right, up
    cam_buf = rt.to_device(cam4)

    def padded(a, shape):
        return a if len(a) else np.zeros(shape, np.float32)

    t0 = time.perf_counter()
    rt.run(k, (n,), None, cam_buf, np.int32(width), np.int32(height), np.int32(spp),
           rt.to_device(pixel_jitter(spp).astype(np.float32)),
           rt.to_device(padded(arrays.spheres, (1, 2, 4))), np.int32(len(arrays.spheres)),
           rt.to_device(padded(arrays.planes, (1, 4, 4))), np.int32(len(arrays.planes)),
           rt.to_device(padded(arrays.bvh, (1, 8))), rt.to_device(padded(arrays.tris, (1, 6, 4))),
           np.int32(len(arrays.tris)), gb_pos, gb_nrm, gb_dir)
    rt.finish()
    s = time.perf_counter() - t0
    rep.run("gbuffer", s, primary_rays=n, rays_per_s=round(n / max(s, 1e-9)))

    def chain_args(levels):
        buf, consts, nlev = _chain_buffers(rt, levels)
        return [buf, *consts, np.int32(nlev)]

    if "shade" in pl.passes:
        k = kern("shade")
        sh_buf = rt.to_device(np.pad(sh_coeffs, ((0, 0), (0, 1))).astype(np.float32)
                              if sh_coeffs is not None else np.zeros((1, 4), np.float32))
        if pl.specular == "importance":
            c_args = chain_args(chain)
        elif pl.specular == "prefiltered":
            c_args = chain_args(prefiltered)
        else:
            c_args = [dummy, zeros_i, zeros_i, zeros_i, np.int32(1)]
        nsamp = fx["samples"] if pl.specular == "importance" else 1
        ham = np.zeros((max(nsamp, 1), 4), np.float32)
        if pl.specular == "importance":       # (cos phi, sin phi, u1): sample_ggx_half_cs
            pts = sampling.hammersley(nsamp)
            ham[:, 0], ham[:, 1], ham[:, 2] = np.cos(2 * np.pi * pts[:, 0]), np.sin(2 * np.pi * pts[:, 0]), pts[:, 1]
        dfg_arr = dfg_table.astype(np.float32) if dfg_table is not None else np.zeros((2, 2, 2), np.float32)
        t0 = time.perf_counter()
        rt.run(k, (n,), None, gb_pos, gb_nrm, gb_dir, np.int32(n), mats_buf, env_rot, env_scale, sh_buf,
               *c_args, rt.to_device(ham), np.int32(nsamp), np.float32(fx["mip_bias"]),
               rt.to_device(dfg_arr.reshape(-1, 2)), np.int32(dfg_arr.shape[0]), radiance)
        rt.finish()
        s = time.perf_counter() - t0
        extra = {"samples": nsamp} if pl.specular == "importance" else {}
        rep.run("shade", s, mpixel_samples_per_s=round(n * max(nsamp, 1) / s / 1e6, 2), **extra)

    ref_mean = None
    if "reference" in pl.passes:
        ref = fx["reference"]
        k = kern("reference")
        marginal, cond, pdf = cdf
        img_buf = rt.to_device(to_rgba(image).astype(np.float32))
        args_pre = [gb_pos, gb_nrm, gb_dir, np.int32(n), mats_buf, env_rot, env_scale, img_buf,
                    np.int32(image.shape[1]), np.int32(image.shape[0]), rt.to_device(marginal),
                    rt.to_device(cond), rt.to_device(pdf)]
        hit = rt.read(gb_pos, (n, 4))[:, 3] != -1.0
        out_buf = rt.empty(n * 16)
        acc = np.zeros((n, 3))
        acc_odd = np.zeros(n)
        taken = 0
        noise = math.inf
        t0 = time.perf_counter()
        lumw = np.array([0.2126, 0.7152, 0.0722])
        batch = ref["batch"] + (ref["batch"] & 1)      # even: both replicates advance together
        while taken < ref["max_samples"]:
            b = min(batch, ref["max_samples"] - taken)
            rt.run(k, (n,), None, *args_pre, np.uint32(ref["seed"]), np.int32(taken), np.int32(b), out_buf)
            r = rt.read(out_buf, (n, 4)).astype(np.float64)
            acc += r[:, :3]
            acc_odd += r[:, 3]
            taken += b
            if progress:
                progress(taken / ref["max_samples"])
            if not hit.any():
                break
            if taken >= 2 * batch:
                noise = reference_noise(acc[hit] @ lumw, acc_odd[hit], taken)
                if noise <= ref["target_noise"]:
                    break
        ref_mean = (acc / max(taken, 1)).astype(np.float32)
        rep.run("reference", time.perf_counter() - t0, samples_per_pixel=taken,
                relative_noise=None if not math.isfinite(noise) else round(noise, 6),
                stopped="target_noise" if noise <= ref["target_noise"] else "max_samples")

    if "background" in pl.passes:
        k = kern("background")
        bgc = np.zeros(4, np.float32)
        lod = 0.0
        if pl.background == "color":
            bgc[:3] = env["background"]
            c_args = [dummy, zeros_i, zeros_i, zeros_i, np.int32(1)]
        elif pl.background == "blur":
            c_args = chain_args(prefiltered)
            lod = env["blur"] * (len(prefiltered) - 1)
        else:
            c_args = chain_args([image])
        t0 = time.perf_counter()
        rt.run(k, (n,), None, gb_pos, gb_dir, np.int32(n), env_rot, env_scale, bgc, *c_args,
               np.float32(lod), radiance)
        rt.finish()
        rep.run("background", time.perf_counter() - t0)

    # ---- resolve
    k = kern("resolve")
    hdr_buf = rt.empty(npix * 16)
    aov = "WRITE_AOVS" in pl.defines
    an, aa, ad = (rt.empty(npix * 16), rt.empty(npix * 16), rt.empty(npix * 4)) if aov else (dummy, dummy, dummy)
    ref_buf = rt.to_device(np.concatenate([ref_mean, np.zeros((n, 1), np.float32)], axis=1)) \
        if ref_mean is not None else dummy
    t0 = time.perf_counter()
    rt.run(k, (npix,), None, radiance, ref_buf, np.float32(1.0 if ref_mean is not None else 0.0),
           gb_pos, gb_nrm, mats_buf, np.int32(spp), np.int32(npix), hdr_buf, an, aa, ad)
    hdr = rt.read(hdr_buf, (height, width, 4))
    aovs = {}
    if aov:
        aovs = {"normal": rt.read(an, (height, width, 4)), "albedo": rt.read(aa, (height, width, 4)),
                "depth": rt.read(ad, (height, width))}
    rep.run("resolve", time.perf_counter() - t0)

    png = None
    if "tonemap" in pl.passes:
        tdef = {"TONEMAP": TONEMAP_IDS[fx["tonemap"]], "OUTPUT_SRGB": int(fx["output_transfer"] == "srgb")}
        if out["dither"]:
            tdef["DITHER"] = 1
        k = rt.kernel("tonemap.cl", "tonemap_u8", tdef)
        out_u8, disp = rt.empty(npix * 4), rt.empty(npix * 16)
        t0 = time.perf_counter()
        rt.run(k, (npix,), None, hdr_buf, np.float32(2.0 ** fx["exposure"]), np.float32(fx["gamma"]),
               np.int32(npix), out_u8, disp)
        png = rt.read(out_u8, (height, width, 4), np.uint8)[..., :3]
        rep.run("tonemap", time.perf_counter() - t0, operator=fx["tonemap"])

    report = {
        "device": rt.device_label,
        "effects": pl.to_json(),
        "bakes": rep.bakes,
        "passes": rep.passes,
        "kernel_builds": [{"kernel": b["kernel"], "defines": b["defines"], "seconds": round(b["seconds"], 4)}
                          for b in rt.builds],
        "resolution": [width, height],
        "spp": spp,
        "elapsed_s": round(time.perf_counter() - t_start, 4),
    }
    return Frame(hdr, png, aovs, report)


def output_paths(scene: Scene) -> list:
    out = scene.data["output"]
    return [*out["frame"], *(out[a] for a in ("normal", "albedo", "depth") if out[a])]


def write_outputs(frame: Frame, scene: Scene) -> list:
    """Write every requested output atomically; returns the paths written."""
    from iblbake.io import images

    out = scene.data["output"]
    written = []
    for p in output_paths(scene):
        try:
            Path(p).parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise IblbakeError(f"{p}: cannot create its folder ({e.strerror})") from None
    for p in out["frame"]:
        if p.lower().endswith(".png"):
            images.write_png(p, frame.png)
        else:
            images.write_exr(p, frame.hdr, channels=("R", "G", "B", "A"))
        written.append(p)
    for a in ("normal", "albedo", "depth"):
        if out[a]:
            img = frame.aovs[a]
            if a == "depth":
                images.write_exr(out[a], img[..., None], channels=("Z",))
            else:
                images.write_exr(out[a], img, channels=("R", "G", "B", "A"))
            written.append(out[a])
    return written
