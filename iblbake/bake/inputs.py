"""Environment inputs in the forms users have them: an equirect panorama, or a cube map as a
horizontal or vertical cross, a strip of six faces, six face files, or a KTX2 cube map,
resampled to the equirect panorama every bake reads.

Layouts (faces in the Vulkan/OpenGL cube-map orientation, docs/conventions.md "Cube maps"):
    hcross (4:3)   . +Y  .  .        vcross (3:4)   . +Y .
                  -X +Z +X -Z                      -X +Z +X
                   . -Y  .  .                       . -Y .
                                                    . -Z .   (-Z turned 180 degrees)
    hstrip (6:1)  +X -X +Y -Y +Z -Z left to right; vstrip (1:6) the same top to bottom
    faces          a path with {face}, read as px nx py ny pz nz
Auto-detection by aspect ratio: 2:1 equirect, 4:3 hcross, 3:4 vcross, 6:1 hstrip, 1:6 vstrip;
a .ktx2 file is a KTX2 cube map.

Resampling treats the cube map as the box texels it stores: each equirect texel is the mean of
the cube map over its solid angle, by the exact solid angles of its overlaps with the cube
texels (iblbake/bake/cube_resample.py, in double on the OpenCL device).
"""

from __future__ import annotations

import numpy as np

from iblbake.errors import InputError
from iblbake.io import images, ktx2, reads

LAYOUTS = ("auto", "equirect", "hcross", "vcross", "hstrip", "vstrip", "faces", "ktx2")
FACE_NAMES = ("px", "nx", "py", "ny", "pz", "nz")
# what messages call the layout setting where the caller does not say: the commands' flag, and
# in the hint to set it, the scene key too (both set it)
LAYOUT_NAME, LAYOUT_HINT = "--input-layout", "--input-layout (environment.layout)"
# (column, row) of each face in a cross, in face-size units; vcross's -Z is turned 180 degrees
CROSS = {"hcross": [(2, 1), (0, 1), (1, 0), (1, 2), (1, 1), (3, 1)],
         "vcross": [(2, 1), (0, 1), (1, 0), (1, 2), (1, 1), (1, 3)]}


def _named_layout(path: str) -> str | None:
    """The layout a path itself names: six {face} files, or a KTX2 cube map."""
    if "{face}" in path:
        return "faces"
    return "ktx2" if path.lower().endswith(".ktx2") else None


def detect(path: str, w: int, h: int) -> str:
    named = _named_layout(path)
    if named:
        return named
    for layout, (a, b) in {"equirect": (2, 1), "hcross": (4, 3), "vcross": (3, 4), "hstrip": (6, 1),
                           "vstrip": (1, 6)}.items():
        if w * b == h * a:
            return layout
    return "equirect"


def faces_of(image: np.ndarray, layout: str, path: str, layout_hint: str = LAYOUT_HINT) -> np.ndarray:
    """The six faces (6, s, s, 3) of a cross or strip image."""
    h, w = image.shape[:2]
    cols, rows = {"hcross": (4, 3), "vcross": (3, 4), "hstrip": (6, 1), "vstrip": (1, 6)}[layout]
    if w % cols or h % rows or w // cols != h // rows or w == 0:
        raise InputError(f"{path}: {w}x{h} is not a {layout} of square faces ({cols} x {rows} of them); "
                         f"give {layout_hint} for what it is")
    s = w // cols
    if layout in CROSS:
        out = [image[r * s:(r + 1) * s, c * s:(c + 1) * s] for c, r in CROSS[layout]]
        if layout == "vcross":
            out[5] = out[5][::-1, ::-1]
    elif layout == "hstrip":
        out = [image[:, k * s:(k + 1) * s] for k in range(6)]
    else:
        out = [image[k * s:(k + 1) * s] for k in range(6)]
    return np.stack(out).astype(np.float32)


def read_environment(path, *, layout: str = "auto", names: dict | None = None, runtime=None,
                     layout_name: str = LAYOUT_NAME, layout_hint: str = LAYOUT_HINT, **policies):
    """(equirect image float32 (H, W, 3), ImageInfo) of an environment in any of LAYOUTS. The
    read policies (transfer, primaries, nonfinite, negative, max_pixels) apply to what the file
    holds, before resampling; the info describes the file, its warnings say what was resampled.
    A cube map resamples on `runtime`'s device where one is given, else by the numpy twin.
    Messages call the policies as `names` says (images.POLICY_NAMES), the layout `layout_name`
    (`layout_hint` where they say to give it)."""
    path = str(path)
    if layout == "auto":
        layout = _named_layout(path) or "auto"
    if layout == "faces":
        if "{face}" not in path:
            raise InputError(f"{path}: {layout_name} faces needs a path with {{face}} (read as {', '.join(FACE_NAMES)})")
        faces, info = [], None
        for face_path in files_of(path):
            img, inf = images.read_panorama(face_path, names=names, **policies)
            if faces and img.shape != faces[0].shape:
                raise InputError(f"{face_path}: {img.shape[1]}x{img.shape[0]}, the other faces are "
                                 f"{faces[0].shape[1]}x{faces[0].shape[0]}")
            if img.shape[0] != img.shape[1]:
                raise InputError(f"{face_path}: a cube face must be square, not {img.shape[1]}x{img.shape[0]}")
            faces.append(img)
            info = info or inf
        info.sha256 = _combined_sha([images.file_sha256(f) for f in files_of(path)])
        info.layout = "faces"
        return _resampled(np.stack(faces), info, "six face files", runtime)
    if layout == "ktx2":
        limit = policies.get("max_pixels") or images.max_pixels_default()
        pixels_name = {**images.POLICY_NAMES, **(names or {})}["max_pixels"]
        faces = ktx2.read_cube(path, reads.image_bytes(limit), f" ({pixels_name} or IBLBAKE_MAX_PIXELS raises it)")
        info = images.ImageInfo(path=path, width=faces.shape[2], height=faces.shape[1] * 6, channels_in=("R", "G", "B"),
                                format="ktx2", sha256=images.file_sha256(path), nonfinite_policy=policies.get(
                                    "nonfinite", "error"), negative_policy=policies.get("negative", "keep"))
        faces = images.validate_texels(faces.reshape(-1, faces.shape[2], 3), info, names).reshape(faces.shape)
        info.layout = "ktx2"
        return _resampled(faces, info, "a KTX2 cube map", runtime)
    img, info = images.read_panorama(path, names=names, **policies)
    if layout == "auto":
        layout = detect(path, info.width, info.height)
    info.layout = layout
    if layout == "equirect":
        if info.width != 2 * info.height:
            info.warnings.append(f"{path}: {info.width}x{info.height} is not 2:1 (nor 4:3, 3:4, 6:1, 1:6 of a cube "
                                 f"map); treated as a full latitude-longitude panorama")
        return img, info
    return _resampled(faces_of(img, layout, path, layout_hint), info, f"a {layout} cube map", runtime)


def files_of(path: str) -> list:
    """The files an environment path reads (six for a {face} path)."""
    return [path.replace("{face}", n) for n in FACE_NAMES] if "{face}" in path else [path]


def _resampled(faces, info, what: str, runtime=None):
    from iblbake.bake import cube_resample

    rt = runtime if runtime is not None else _default_runtime()
    if rt is not None and cube_resample.device_supports(rt):
        eq = cube_resample.cube_to_equirect_cl(rt, faces)
    else:
        if faces.shape[1] > 64:
            info.warnings.append(f"{info.path}: no OpenCL device with double precision; resampling the "
                                 f"{faces.shape[1]}x{faces.shape[1]} faces on the host (about "
                                 f"{faces.shape[1] ** 2 / 4e3:.0f} s)")
        eq = cube_resample.cube_to_equirect(faces)
    info.warnings.append(f"{info.path}: {what} of {faces.shape[1]}x{faces.shape[1]} faces, resampled to a "
                         f"{eq.shape[1]}x{eq.shape[0]} panorama")
    info.width, info.height = eq.shape[1], eq.shape[0]
    return eq, info


def _default_runtime():
    """The default OpenCL device for a caller that has none (sh's host path), or None."""
    try:
        from iblbake.device import runtime as cl
        return cl.Runtime()
    except Exception:      # no OpenCL at all: the host twin does it
        return None


def _combined_sha(parts) -> str:
    import hashlib
    return hashlib.sha256("".join(parts).encode()).hexdigest()
