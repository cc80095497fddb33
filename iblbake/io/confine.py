"""Where the files a scene or an asset names may be (docs/manual.md, "Paths a scene may name").

A scene's outputs (output.frame, the AOVs) stay inside the scene's folder, and the files a glTF
names by URI (buffers, images) inside the glTF's folder: absolute paths, `..`, percent-encoded
`%2E%2E` and symlinks whose target lies outside are refused, each checked on the path with every
link resolved. data: URIs read no file and are always taken. `--allow-outside` (or
IBLBAKE_ALLOW_OUTSIDE=1, what the flag sets for the library and its worker processes) lifts the
rule for the user who means it. The files a scene itself names as inputs (panorama, meshes,
textures) are the user's, like a command line's arguments, and may be anywhere.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from urllib.parse import unquote

from iblbake.errors import InputError

ENV = "IBLBAKE_ALLOW_OUTSIDE"
HINT = f"pass --allow-outside (or set {ENV}=1) if you mean it"
_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")      # RFC 3986: a URI's scheme (file:, http:)


def allowed() -> bool:
    """Whether the user lifted the rule (IBLBAKE_ALLOW_OUTSIDE=1)."""
    v = os.environ.get(ENV, "").strip()
    if v in ("", "0"):
        return False
    if v == "1":
        return True
    raise InputError(f"{ENV}={v!r}: give 1 (scenes and assets may name files outside their folder) or 0")


def inside(folder, path) -> bool:
    """Whether `path`, every link resolved, is `folder` (links resolved) or lies below it."""
    return Path(os.path.realpath(path)).is_relative_to(os.path.realpath(folder))


def output_path(folder: Path, given: str) -> tuple:
    """(the absolute path a scene's output names, None) or (None, why it is refused)."""
    full = Path(os.path.realpath(folder / given))         # an absolute `given` replaces the folder
    if allowed() or inside(folder, full):
        return full, None
    return None, f"leaves the scene's folder {folder}"


def asset_file(asset, uri: str) -> Path:
    """The file a glTF at `asset` names by the relative URI `uri` (percent-decoded); ValueError
    saying why where it names none or one outside the glTF's folder."""
    if _SCHEME.match(uri):
        raise ValueError("is a URI with a scheme; iblbake reads files beside the glTF (a relative URI) "
                         "and data: URIs")
    name = unquote(uri, errors="surrogateescape")     # %FE: the byte 0xFE, as os.fsencode wrote it
    if not name or "\0" in name:
        raise ValueError("names no file")
    folder = Path(asset).parent
    f = folder / name
    if not allowed() and not inside(folder, f):
        what = "an absolute path" if os.path.isabs(name) else "a path that leaves the glTF's folder"
        raise ValueError(f"is {what} ({os.path.realpath(f)}); a glTF reads files beside it or below, {HINT}")
    return f
