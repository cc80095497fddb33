"""No command writes over a file it reads, and no two outputs of one command share a path.

Each command lists, before any work, every path it will write (by the option or key that names
it) and every file it reads (panoramas, scenes, meshes and their buffers, textures, ladders).
Paths are compared as the files they are: through symlinks (realpath) and hard links (the device
and inode of an existing file), so `-o link-to-input.exr` is caught too.
"""

from __future__ import annotations

import os

from iblbake.errors import IblbakeError, InputError


def _identities(path) -> set:
    ids = {("path", os.path.realpath(path))}
    try:
        st = os.stat(path)
    except OSError:
        return ids
    ids.add(("inode", st.st_dev, st.st_ino))
    return ids


def first_overlap(writes, reads):
    """The first clash in writes [(flag, path)] against reads [(what, path)] and the writes
    before it: (flag, path, message) or None. The message is one line naming both."""
    seen = {}
    for what, p in reads:
        for i in _identities(p):
            seen.setdefault(i, (True, what, p))
    for flag, p in writes:
        ids = _identities(p)
        hit = next((seen[i] for i in ids if i in seen), None)
        if hit is not None:
            is_input, what, q = hit
            if is_input:
                return flag, p, f"{flag} {p}: is {what}, which this command reads; give another output path"
            return flag, p, f"{flag} {p}: is also {what} {q}; give each output its own path"
        for i in ids:
            seen[i] = (False, flag, p)
    return None


def refuse_overlaps(writes, reads) -> None:
    """InputError on the first output that is an input or an earlier output."""
    clash = first_overlap(writes, reads)
    if clash is not None:
        raise InputError(clash[2])



# --- what iblbake wrote: replaced freely; anything else only with --force ----------------------

HEAD_BYTES = 64 << 10       # every mark sits in a file's first bytes (a header, a first line)


def mark() -> str:
    """What iblbake writes into each file as its name (PNG tEXt Software, EXR Software, a JSON
    document's generator, KTX2's KTXwriter, a text file's first line)."""
    from iblbake import __version__
    return f"iblbake {__version__}"


def _png_software(head: bytes) -> bytes | None:
    """The tEXt Software value of a PNG's chunks before its image data, or None."""
    import struct
    pos = 8
    while pos + 8 <= len(head):
        n, kind = struct.unpack(">I4s", head[pos:pos + 8])
        if kind in (b"IDAT", b"IEND"):
            return None
        if kind == b"tEXt":
            key, _, value = head[pos + 8:pos + 8 + n].partition(b"\0")
            if key == b"Software":
                return value
        pos += 12 + n
    return None


def _is_depfile(text: str) -> bool:
    """Make rules and nothing else (as iblbake and gcc -MD write them): `targets: prerequisites`
    lines with backslash continuations, no recipe, assignment or comment."""
    logical = text.replace("\\\n", " ").splitlines()
    rules = [ln for ln in logical if ln.strip()]
    return bool(rules) and all(":" in ln and not ln.startswith(("\t", "#")) and "=" not in ln for ln in rules)


def written_by_iblbake(path, first_lines=()) -> bool:
    """Whether the regular file `path` carries iblbake's mark for its format (by suffix), or
    begins with one of `first_lines` (the header row of a table iblbake writes)."""
    import json
    from pathlib import Path

    from iblbake.io import reads

    suffix = Path(path).suffix.lower()
    try:
        if suffix in (".gltf", ".glb"):
            from iblbake.io import gltf
            return gltf.written_by_iblbake(path)
        if suffix == ".bin":          # a glTF's buffer: iblbake's where the .gltf beside it, iblbake's, names it
            from urllib.parse import unquote

            from iblbake.io import gltf
            doc_path = Path(path).with_suffix(".gltf")
            if not gltf.written_by_iblbake(doc_path):
                return False
            doc = json.loads(reads.read_bytes(doc_path, reads.JSON_BYTES, "a glTF document"))
            return any(unquote(b.get("uri", "")) == Path(path).name for b in doc.get("buffers", []))
        if suffix == ".json":
            doc = json.loads(reads.read_text(path, reads.JSON_BYTES, "a JSON document"))
            return isinstance(doc, dict) and any(str(doc.get(k, "")).startswith("iblbake")
                                                 for k in ("format", "generator"))
        head = reads.read_head(path, HEAD_BYTES)
    except (IblbakeError, OSError, ValueError):
        return False
    if suffix == ".png":
        return head[:8] == b"\x89PNG\r\n\x1a\n" and (_png_software(head) or b"").startswith(b"iblbake")
    if suffix == ".exr":
        return head[:4] == b"v/1\x01" and b"Software\0string\0" in head and b"iblbake" in head
    if suffix == ".ktx2":
        return head[:12] == b"\xabKTX 20\xbb\r\n\x1a\n" and b"KTXwriter\0iblbake" in head
    text = head.decode("utf-8", "replace")
    first = text.split("\n", 1)[0]
    if any(first == line for line in first_lines):
        return True
    if suffix == ".d":
        return _is_depfile(text)
    return "iblbake" in first


def refuse_foreign(writes, force: bool, first_lines=()) -> None:
    """One rule for every command's outputs: an existing file iblbake did not write is replaced
    only with --force; one that is not a regular file (a folder, a FIFO, a device) never."""
    import os
    import stat

    for flag, p in writes:
        try:
            st = os.stat(p)
        except FileNotFoundError:
            continue
        except OSError as e:
            raise InputError(f"{flag} {p}: cannot check the existing file ({e.strerror or e})") from None
        if not stat.S_ISREG(st.st_mode):
            kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file (a device, FIFO or socket)"
            raise InputError(f"{flag} {p}: exists and is {kind}; give the path of a file to write")
        if not force and not written_by_iblbake(p, first_lines):
            raise InputError(f"{flag} {p}: exists and is not a file iblbake wrote; pass --force to overwrite it")
