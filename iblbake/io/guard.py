"""No command writes over a file it reads, and no two outputs of one command share a path.

Each command lists, before any work, every path it will write (by the option or key that names
it) and every file it reads (panoramas, scenes, meshes and their buffers, textures, ladders).
Paths are compared as the files they are: through symlinks (realpath) and hard links (the device
and inode of an existing file), so `-o link-to-input.exr` is caught too.
"""

from __future__ import annotations

import os

from iblbake.errors import InputError


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

