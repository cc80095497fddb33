"""`iblbake sh`: project a panorama onto SH and build the JSON document.

Two backends compute the same radiance coefficients L_k:
- opencl: kernels/sh_project.cl computes per-row Fourier sums (the bandwidth-bound part), the
  host contracts them in float64 (sh.project_row_sums).
- numpy: sh.project, the same separable exact-texel-integral form in float64 on the host.
Both are checked against sh.project_direct (per-texel quadrature) and closed forms in tests.
"""

from __future__ import annotations

import functools
import math
import time

import numpy as np

from iblbake.core import conventions
from iblbake.core import sh
from iblbake.errors import IblbakeError

FORMAT = "iblbake.sh"
FORMAT_VERSION = 1
BACKENDS = ("opencl", "numpy")
# `auto` projects on the host where that is quicker than starting OpenCL: measured on 2 cores, the
# float64 host projection of a 1024x512 panorama takes 0.008 s at 3 bands, 0.010 s at 5, 0.09 s
# at 8 and 0.91 s at 16, and importing pyopencl, probing the device, loading the program and
# projecting about 0.12 s whatever the bands. Texels x bands^2 up to this is the host's side.
HOST_TEXEL_BANDS2 = 4e7


def choose_backend(backend: str, width: int, height: int, bands: int) -> str:
    """opencl or numpy; auto picks numpy below HOST_TEXEL_BANDS2 texels x bands^2."""
    if backend != "auto":
        return backend
    return "numpy" if width * height * bands * bands <= HOST_TEXEL_BANDS2 else "opencl"


MAX_TERM_GROUP = 5  # measured: 5 beats 8 (register pressure) and 3-4 (more passes)


def term_group(bands: int) -> int:
    """Azimuth terms per pass over a chunk (TG in kernels/sh_project.cl): as few passes as
    possible, split evenly so that little padding is computed."""
    nt = 2 * bands - 1
    passes = -(-nt // MAX_TERM_GROUP)
    return -(-nt // passes)


def row_chunk(width: int) -> int:
    """Pixels summed per work-item: a multiple of 16 (one SIMD step), ~8 chunks a row (at most
    512 pixels, 6 KB, so a chunk stays in L1), so the partial sums stay small next to the image."""
    return max(64, min(512, -(-width // 128) * 16))


@functools.lru_cache(maxsize=8)
def _trig(width: int, bands: int, rotate_y_deg: float):
    nt = 2 * bands - 1
    tg = term_group(bands)
    ntp = -(-nt // tg) * tg
    t = np.zeros((ntp, width), dtype=np.float32)
    t[:nt] = sh.azimuth_table(conventions.equirect_phi(width, rotate_y_deg), bands).T
    return t


def project_opencl(rt, image, bands: int, rotate_y_deg: float = 0.0):
    """Radiance coefficients (bands^2, 3) on the OpenCL device; returns (coeffs, kernel seconds)."""
    image = np.ascontiguousarray(image, dtype=np.float32)
    h, w, c = image.shape
    if c != 3:
        raise ValueError("project_opencl expects RGB")
    nt = 2 * bands - 1
    trig = _trig(w, bands, float(rotate_y_deg))
    ntp = trig.shape[0]
    chunk = row_chunk(w)
    nx = -(-w // chunk)
    defines = {"NT": ntp, "TG": term_group(bands)}
    rt.kernel("sh_project.cl", "sh_row_sums", defines)      # built before the timing
    img_buf = rt.to_device(image)
    trig_buf = rt.to_device(trig)
    out_buf = rt.empty(h * nx * ntp * 3 * 4)
    t0 = time.perf_counter()
    rt.launch("sh_project.cl", "sh_row_sums", defines, (nx, h), image=img_buf, width=w, trig=trig_buf, chunk=chunk,
              out=out_buf)
    partial = rt.read(out_buf, (h, nx, ntp, 3))
    kernel_s = time.perf_counter() - t0
    row_sums = partial[:, :, :nt].sum(axis=1, dtype=np.float64)
    return sh.project_row_sums(row_sums, bands, w), kernel_s


def project(image, bands: int, backend: str, rt=None, rotate_y_deg: float = 0.0):
    """(coeffs (bands^2, 3) float64, seconds of projection)."""
    t0 = time.perf_counter()
    if backend == "opencl":
        coeffs, _ = project_opencl(rt, image, bands, rotate_y_deg)
    elif backend == "numpy":
        coeffs = sh.project(image, bands, rotate_y_deg)
    else:
        raise ValueError(f"unknown backend {backend!r}")
    return coeffs, time.perf_counter() - t0


def document(coeffs_radiance, *, bands: int, window: str, info, options: dict, device: str | None,
             timings: dict) -> dict:
    """The JSON document of `iblbake sh` (format version 1)."""
    w = sh.window(bands, window)
    radiance = coeffs_radiance * w[:, None]
    irradiance = radiance * sh.ahat(bands)[:, None]
    names = [f"l{l}m{m}" for l in range(bands) for m in range(-l, l + 1)]
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "basis": {
            "type": "real spherical harmonics",
            "normalization": "orthonormal (integral of Y^2 over the sphere = 1)",
            "polar_axis": "+z",
            "azimuth": "phi = atan2(y, x)",
            "condon_shortley_phase": False,
            "ordering": "k = l*(l+1) + m, l = 0..bands-1, m = -l..l",
            "world": "right-handed, +y up",
            "panorama_mapping": "u = 0.5 - atan2(x, z)/(2 pi), v = acos(y)/pi, v = 0 top row",
            "l_le_2": "Y0=0.282095 Y1=0.488603y Y2=0.488603z Y3=0.488603x Y4=1.092548xy "
                      "Y5=1.092548yz Y6=0.315392(3z^2-1) Y7=1.092548xz Y8=0.546274(x^2-y^2)",
        },
        "bands": bands,
        "coefficient_names": names,
        "window": window,
        "window_weights": [float(x) for x in sh.window(bands, window)[[l * l for l in range(bands)]]],
        "radiance": _rows(radiance),
        "irradiance": _rows(irradiance),
        "ahat": [sh.truncated_cos_sh(l) for l in range(bands)],
        "evaluation": {
            "radiance": "L(d) ~ sum_k radiance[k] * Y_k(d)",
            "irradiance": "E(n) = max(0, sum_k irradiance[k] * Y_k(n))  (Ahat folded in, as Ramamoorthi and Hanrahan 2001)",
            "diffuse": "albedo / pi * E(n)",
        },
        "input": info.to_json(),
        "options": options,
        "device": device,
        "timings": timings,
    }


def _rows(coeffs) -> list:
    out = []
    for row in coeffs:
        vals = [float(v) for v in row]
        if not all(math.isfinite(v) for v in vals):
            raise ValueError("non-finite SH coefficient")
        out.append(vals)
    return out


# Engine formats (docs/manual.md "SH for engines"). Each engine evaluates its own polynomials in world
# x, y, z of a unit normal; iblbake's basis for l <= 2 is those polynomials times the positive
# constants below (no Condon-Shortley phase, z polar axis, the same world: right-handed, +y up),
# so an export is a rescaling per coefficient, with no sign flips or axis swaps.
POLY_CONSTANTS = np.array([0.5 / math.sqrt(math.pi)] + [math.sqrt(3.0 / (4.0 * math.pi))] * 3
                          + [0.5 * math.sqrt(15.0 / math.pi)] * 2 + [0.25 * math.sqrt(5.0 / math.pi)]
                          + [0.5 * math.sqrt(15.0 / math.pi), 0.25 * math.sqrt(15.0 / math.pi)])
FORMATS = ("iblbake", "filament", "threejs", "gltf", "glsl")
# what each format's file may be called; the first is what `sh A B -o DIR/` names them
SUFFIXES = {"iblbake": (".json",), "filament": (".txt",), "threejs": (".json",), "gltf": (".json",),
            "glsl": (".glsl", ".frag", ".vert", ".comp", ".h")}
SUFFIX = {fmt: names[0] for fmt, names in SUFFIXES.items()}
NAMES = ["L00", "L1-1", "L10", "L11", "L2-2", "L2-1", "L20", "L21", "L22"]


def _nine(doc: dict, key: str, engine: str, most: int = 3) -> np.ndarray:
    bands = doc["bands"]
    if bands > most:
        raise IblbakeError(f"--format {engine} holds at most {most} bands (9 coefficients); give --bands 3 or fewer")
    return np.asarray(doc[key], np.float64)


def filament_coefficients(doc: dict) -> np.ndarray:
    """Filament's IndirectLight::Builder::irradiance(bands, sh): sh[k] = L_lm A_lm Chat_l / pi
    with its A_lm carrying the Condon-Shortley signs its basis has; in iblbake's signs that is
    E_k |A_k| / pi, so Irradiance_SphericalHarmonics(n) (its shader: sh[0] + sh[1] y + sh[2] z +
    sh[3] x + sh[4] yx + sh[5] yz + sh[6] (3z^2 - 1) + sh[7] zx + sh[8] (x^2 - y^2)) is E(n)/pi,
    the diffuse light a Lambertian albedo of 1 reflects."""
    e = _nine(doc, "irradiance", "filament")
    return e * POLY_CONSTANTS[:len(e), None] / math.pi


def filament_text(doc: dict) -> str:
    """cmgen's sh.txt layout (one "(r, g, b); // name" line per coefficient), which Filament's
    samples read back."""
    c = filament_coefficients(doc)
    return "".join(f"({r:.9g}, {g:.9g}, {b:.9g}); // {NAMES[k]}, irradiance, pre-scaled base"
                   f"{' (iblbake, from ' + doc['input']['path'] + ')' if k == 0 else ''}\n"
                   for k, (r, g, b) in enumerate(c))


def threejs_coefficients(doc: dict) -> np.ndarray:
    """three.js's SphericalHarmonics3 (a LightProbe's sh): the radiance coefficients L_lm in its
    basis, which is iblbake's for l <= 2 (getAt uses 0.282095, 0.488603 y, z, x, 1.092548 xy, yz,
    0.315392 (3z^2 - 1), 1.092548 xz, 0.546274 (x^2 - y^2)); its getIrradianceAt and shader
    multiply by pi, 2pi/3, pi/4 themselves. Fewer than 3 bands are padded with zeros."""
    lr = _nine(doc, "radiance", "threejs")
    out = np.zeros((9, 3))
    out[:len(lr)] = lr
    return out


def threejs_json(doc: dict) -> str:
    """`new THREE.LightProbe(new THREE.SphericalHarmonics3().fromArray(json.sh))`."""
    import json
    return json.dumps({"generator": "iblbake", "type": "LightProbe", "source": doc["input"]["path"],
                       "sh": [round(float(v), 9) for v in threejs_coefficients(doc).ravel()],
                       "intensity": 1.0}, indent=1) + "\n"


# EXT_lights_image_based's irradianceCoefficients as Babylon.js, the extension's reference loader,
# reads them (SphericalHarmonics.FromArray, then x intensity / pi and evaluated in its shader's
# SPHERICAL_HARMONICS path): irradiance E_lm (pre-convolved, not pre-scaled), in Babylon's basis,
# whose odd-m terms carry the Condon-Shortley sign (l1-1 = -c y, l11 = -c x, l2-1 = -c yz,
# l21 = -c xz), at the direction in Babylon's left-handed world, where the loader's root node
# (rotation 180 degrees about y, scale z -1) puts glTF's (x, y, z) at (-x, y, z). Both are signs:
GLTF_SIGNS = np.array([1, -1, 1, -1, 1, -1, 1, -1, 1]) * np.array([1, 1, 1, -1, -1, 1, 1, -1, 1])


def gltf_coefficients(doc: dict) -> np.ndarray:
    """The 9 x 3 irradianceCoefficients of an EXT_lights_image_based light (fewer bands padded
    with zeros): E_k times GLTF_SIGNS (Condon-Shortley signs, then the x mirror of the loader)."""
    e = _nine(doc, "irradiance", "gltf")
    out = np.zeros((9, 3))
    out[:len(e)] = e
    return out * GLTF_SIGNS[:, None]


def gltf_json(doc: dict) -> str:
    """The light's irradianceCoefficients as a JSON fragment (export-gltf writes the whole light)."""
    import json
    return json.dumps({"generator": "iblbake", "extension": "EXT_lights_image_based", "source": doc["input"]["path"],
                       "irradianceCoefficients": [[round(float(v), 9) for v in row]
                                                  for row in gltf_coefficients(doc)]}, indent=1) + "\n"


def export(doc: dict, fmt: str) -> str:
    import json
    if fmt == "iblbake":
        return json.dumps(doc, indent=2, allow_nan=False) + "\n"
    return {"filament": filament_text, "threejs": threejs_json, "gltf": gltf_json, "glsl": glsl_snippet}[fmt](doc)


def glsl_snippet(doc: dict) -> str:
    """A GLSL function with the irradiance coefficients baked in, for any number of bands."""
    bands, src = doc["bands"], doc["input"]["path"]
    n = bands * bands
    return f"""// iblbake SH irradiance: {bands} bands ({n} coefficients), window {doc['window']}, from {src}
// Real orthonormal SH, z polar axis, no Condon-Shortley phase, k = l*(l+1)+m; world +y up.
// diffuse = albedo / PI * shIrradiance(normalize(N));
""" + glsl_function(doc["irradiance"], bands)


def glsl_function(irradiance, bands: int, name: str = "shIrradiance", table: str = "SH_IRRADIANCE",
                  count: str = "SH_BANDS") -> str:
    """The constants `count` and `table` (irradiance E_k, bands^2 rows) and `vec3 name(vec3 d)`
    evaluating them at a unit direction, clamped at 0 (the snippet's; probes.glsl's sky too)."""
    n = bands * bands
    vals = ",\n    ".join(
        "vec3(" + ", ".join(f"{v:.9g}" for v in c) + ")" for c in irradiance)
    return f"""const int {count} = {bands};
const vec3 {table}[{n}] = vec3[{n}](
    {vals}
);

vec3 {name}(vec3 d) {{
    float K[{count}];
    for (int l = 0; l < {count}; ++l) K[l] = sqrt((2.0 * float(l) + 1.0) / (4.0 * 3.14159265358979));
    float pmm = 1.0, cm = 1.0, sm = 0.0;
    vec3 e = vec3(0.0);
    for (int m = 0; m < {count}; ++m) {{
        if (m > 0) {{
            pmm *= float(2 * m - 1);
            float c = cm * d.x - sm * d.y; sm = sm * d.x + cm * d.y; cm = c;
            for (int l = m; l < {count}; ++l) K[l] *= inversesqrt(float((l + m) * (l - m + 1)));
        }}
        float p2 = 0.0, p1 = pmm;
        for (int l = m; l < {count}; ++l) {{
            float p = (l == m) ? pmm : (l == m + 1) ? (2.0 * float(m) + 1.0) * d.z * pmm
                    : ((2.0 * float(l) - 1.0) * d.z * p1 - float(l + m - 1) * p2) / float(l - m);
            if (l > m) {{ p2 = p1; p1 = p; }}
            if (m == 0) e += {table}[l * (l + 1)] * K[l] * p;
            else {{
                float kp = 1.41421356 * K[l] * p;
                e += {table}[l * (l + 1) + m] * kp * cm + {table}[l * (l + 1) - m] * kp * sm;
            }}
        }}
    }}
    return max(e, vec3(0.0));
}}
"""


IRRADIANCE_VERSION = 1


def irradiance_coeffs(image, bands: int, window: str, backend: str, rt):
    """E_lm = Ahat_l w_l L_lm: what the renderer's SH diffuse term evaluates."""
    coeffs, _ = project(image, bands, backend, rt)
    return coeffs * sh.window(bands, window)[:, None] * sh.ahat(bands)[:, None]


def bake_irradiance(rt, image, info, root, policies: dict, bands: int, window: str, warn=None):
    """The renderer's SH entry (irradiance.json), keyed by the input's content, bands, window,
    read policies and the projection kernel's source. Returns (coefficients, manifest, cached)."""
    import json
    from pathlib import Path

    from iblbake.bake import cache
    from iblbake.device.programs import source_hash
    from iblbake.io.atomic import write_json

    root = Path(root)
    key = "sh-" + cache.content_key({"kind": "sh", "v": IRRADIANCE_VERSION, "input": info.sha256,
                                     "bands": bands, "window": window, "policies": policies,
                                     "kernel": source_hash("sh_project.cl")})

    def build(tmp: Path):
        e = irradiance_coeffs(image, bands, window, "opencl", rt)
        write_json(tmp / "irradiance.json", {"bands": bands, "window": window, "irradiance": e.tolist()})
        return {"kind": "sh", "files": [{"name": "irradiance.json"}], "parameters":
                {"bands": bands, "window": window, **policies}, "input": info.to_json(),
                "device": rt.device_label}

    manifest, cached = cache.get_or_build(root, key, build, warn=warn)
    from iblbake.io import reads
    coeffs = np.asarray(json.loads(reads.read_text(root / manifest["key"] / "irradiance.json", reads.JSON_BYTES,
                                                   "a cached SH document"))["irradiance"])
    return coeffs, manifest, cached


# --- how far the SH irradiance is from the exact one ---------------------------------------------

ERROR_NORMALS = 256


def fibonacci_normals(n: int = ERROR_NORMALS):
    """n fixed unit normals spread evenly over the sphere (a Fibonacci lattice, +y polar)."""
    from iblbake.core.bases.common import fibonacci_sphere
    return fibonacci_sphere(n)


def exact_irradiance(image, normals, rotate_y_deg: float = 0.0):
    """E(n) = sum over every texel of L max(0, n.d) dOmega (texel centres, exact solid angles),
    float64, for the panorama rotated by rotate_y_deg, at each normal (K, 3) -> (K, C).

    On an equirect row (polar angle theta) n.d = sin(theta) sin(theta_n) cos(phi - phi_n) +
    cos(theta) cos(theta_n): the texels it keeps form one arc of columns around phi_n, and the
    sum over an arc of L (A cos(phi - phi_n) + B) is A (cos phi_n S_c + sin phi_n S_s) + B S_1 with
    S the arc's sums of L cos phi, L sin phi and L: prefix sums per row make each (row, normal)
    pair O(1) instead of O(width) (the same sum as brute force, 1e-12 apart)."""
    from iblbake.core import conventions

    img = np.asarray(image, np.float64)
    h, w, nch = img.shape
    theta = conventions.equirect_theta(h)
    phi = conventions.equirect_phi(w, rotate_y_deg)                  # decreasing in j: pi + rot - 2 pi (j + .5) / w
    om = conventions.equirect_row_solid_angles(w, h)
    n = np.asarray(normals, np.float64)
    tn = np.arccos(np.clip(n[:, 1], -1, 1))
    pn = np.arctan2(n[:, 0], n[:, 2])
    a = np.sin(theta)[:, None] * np.sin(tn)[None, :]                  # (h, K)
    b = np.cos(theta)[:, None] * np.cos(tn)[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(a > 0, -b / np.where(a > 0, a, 1.0), np.where(b > 0, -np.inf, np.inf))
    half = np.arccos(np.clip(c, -1, 1)) * w / (2 * np.pi)             # the arc's half width in columns
    # column j's centre sits at t - (j + 1/2) columns from phi_n, t = w (pi + rot - phi_n) / (2 pi)
    t = w * (np.pi + np.radians(rotate_y_deg) - pn) / (2 * np.pi)
    lo = np.floor(t[None, :] - half - 0.5).astype(np.int64) + 1
    hi = np.ceil(t[None, :] + half - 0.5).astype(np.int64) - 1
    count = np.clip(hi - lo + 1, 0, w)
    count = np.where(c <= -1, w, np.where(c >= 1, 0, count))
    start = np.mod(lo, w)
    cos_pn, sin_pn = np.cos(pn)[None, :, None], np.sin(pn)[None, :, None]
    out = np.zeros((len(n), nch))
    # prefix[r, j] = sums over columns < j of (L, L cos phi, L sin phi), continued over a second
    # turn (total + prefix) so that an arc across the seam is one difference; rows in chunks
    # whose buffer stays in cache
    rows = max(1, min(h, (1 << 19) // (w * 3 * nch)))
    prefix = np.empty((rows, 2 * w + 1, 3 * nch))
    prefix[:, 0] = 0.0
    cos_phi, sin_phi = np.cos(phi)[None, :, None], np.sin(phi)[None, :, None]
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        m = r1 - r0
        first = prefix[:m, 1:w + 1]
        first[..., :nch] = img[r0:r1]
        np.multiply(img[r0:r1], cos_phi, out=first[..., nch:2 * nch])
        np.multiply(img[r0:r1], sin_phi, out=first[..., 2 * nch:])
        np.cumsum(first, axis=1, out=first)
        np.add(first, prefix[:m, w:w + 1], out=prefix[:m, w + 1:])
        flat = prefix[:m].reshape(-1, 3 * nch)
        idx = start[r0:r1] + (2 * w + 1) * np.arange(m)[:, None]
        s = np.take(flat, idx + count[r0:r1], axis=0) - np.take(flat, idx, axis=0)   # (m, K, 3C)
        s1, sc, ss = s[..., :nch], s[..., nch:2 * nch], s[..., 2 * nch:]
        contrib = a[r0:r1, :, None] * (cos_pn * sc + sin_pn * ss) + b[r0:r1, :, None] * s1
        out += np.einsum("r,rkc->kc", om[r0:r1], contrib)
    return out


def irradiance_error(image, irradiance_coeffs, bands: int, rotate_y_deg: float = 0.0, intensity: float = 1.0):
    """The `error` block of `iblbake sh`: the SH irradiance max(0, sum E_k Y_k) against the exact
    irradiance at the 256 fixed normals, in luminance (Rec. 709 weights; one exact sum instead
    of three keeps it within a fifth of the bake's own time): relative RMSE, the largest
    relative error of a normal, and the ringing (the most negative un-clamped value of any
    channel, and it over the mean irradiance)."""
    from iblbake.core.metrics import LUMINANCE, relative_rmse

    img = np.asarray(image)
    lum = LUMINANCE if img.shape[-1] >= 3 else np.ones(1)
    normals = fibonacci_normals()
    exact = exact_irradiance((img[..., :len(lum)] @ lum.astype(img.dtype))[..., None], normals, rotate_y_deg)[:, 0]
    exact *= intensity
    approx = sh.evaluate(irradiance_coeffs, normals, bands)
    la = np.maximum(approx, 0.0)[:, :len(lum)] @ lum
    mean = float(exact.mean())
    floor = 1e-3 * max(mean, 1e-300)
    neg = float(min(approx.min(), 0.0))
    return {"normals": len(normals), "metric": "luminance",
            "against": "sum over every texel of L max(0, n.d) dOmega, float64",
            "relative_rmse": relative_rmse(la, exact),
            "max_relative_error": float((np.abs(la - exact) / (exact + floor)).max()),
            "most_negative": neg, "most_negative_relative": neg / mean if mean > 0 else 0.0}
