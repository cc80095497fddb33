"""Bounded reads: every file iblbake reads is checked, before it is opened, to be a regular file
(through symlinks) of at most its kind's limit in bytes, so `/dev/zero`, `/dev/urandom`, a FIFO
or a 3 GB "scene" fail in one line naming the file and the limit instead of blocking or filling
memory. Files handed to a library by path (OpenImageIO, trimesh) are checked with check_file;
files iblbake reads itself come through read_bytes / read_text / open_checked, which check again
on the open descriptor (opened non-blocking, so a FIFO swapped in meanwhile cannot hang it) and
never read more than the limit.
"""

from __future__ import annotations

import contextlib
import os
import stat

from iblbake.errors import InputError

KiB, MiB, GiB = 1 << 10, 1 << 20, 1 << 30

SCENE_BYTES = 1 * MiB          # a scene or a ladder is a few KB (meshes and panoramas have their own files)
JSON_BYTES = 64 * MiB          # manifests, layouts, iblbake's own documents
MESH_BYTES = 2 * GiB           # a mesh file, a glTF buffer or image ($IBLBAKE_MAX_MESH_BYTES)
IMAGE_BYTES_PER_PIXEL = 32     # a panorama or texture file of N pixels: 16 bytes a texel (float RGBA) twice
IMAGE_SLACK = 64 * MiB         # headers, metadata, tiles and mips beyond the pixels


def size_text(n: int) -> str:
    for unit, k in (("GiB", GiB), ("MiB", MiB), ("KiB", KiB)):
        if n >= k:
            v = n / k
            return f"{v:.0f} {unit}" if v == int(v) else f"{v:.1f} {unit}"
    return f"{n} bytes"


def env_count(name: str, default: int, unit: str) -> int:
    """A limit from the environment variable `name` (unset or empty: `default`); anything but a
    whole number >= 1 is an InputError naming the variable (-5 is no limit to go by)."""
    env = os.environ.get(name)
    if not env:
        return default
    try:
        value = int(env)
    except ValueError:
        value = 0
    if value < 1:
        raise InputError(f"{name}={env!r}: give a whole number of {unit} >= 1 (or unset it for {default})")
    return value


def mesh_bytes() -> int:
    return env_count("IBLBAKE_MAX_MESH_BYTES", MESH_BYTES, "bytes")


MESH_HINT = "; IBLBAKE_MAX_MESH_BYTES raises it"


def image_bytes(max_pixels: int) -> int:
    """The file size an image of at most max_pixels may have."""
    return int(max_pixels) * IMAGE_BYTES_PER_PIXEL + IMAGE_SLACK


_KINDS = ((stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO"),
          (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a folder"))


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def _check_stat(path, st, limit: int, what: str, hint: str) -> int:
    if os.path.islink(path):
        path = f"{path} (a link to {os.path.realpath(path)})"
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"{path}: is a folder, not {what}")
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{path}: is {_kind(st.st_mode)}, not a regular file; {what} is read from a regular file "
                         f"of at most {size_text(limit)}")
    if st.st_size > limit:
        raise InputError(f"{path}: {size_text(st.st_size)}, over the limit of {size_text(limit)} for {what}{hint}")
    return st.st_size


def check_file(path, limit: int, what: str = "an input file", hint: str = "") -> int:
    """The size of `path` if it is a regular file (symlinks followed) of at most `limit` bytes;
    else InputError in one line naming the file and the limit. `hint` says how to raise it."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror or e})") from None
    return _check_stat(path, st, limit, what, hint)


@contextlib.contextmanager
def open_checked(path, limit: int, what: str = "an input file", hint: str = ""):
    """A binary file object of `path` once check_file passes; the open descriptor is checked again
    (opened non-blocking: a FIFO put there meanwhile fails instead of blocking)."""
    check_file(path, limit, what, hint)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror or e})") from None
    # The descriptor is closed here once, never by the file object: a Ctrl-C landing as fdopen
    # returns (before its result is bound) would close it through the dropped object and then
    # again here, an EBADF that replaced the KeyboardInterrupt (seen in CI's kill loop).
    try:
        _check_stat(path, os.fstat(fd), limit, what, hint)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        with os.fdopen(fd, "rb", closefd=False) as f:
            yield f
    finally:
        os.close(fd)


def read_bytes(path, limit: int, what: str = "an input file", hint: str = "") -> bytes:
    """The whole file, at most `limit` bytes (a file that grew past it meanwhile fails too)."""
    with open_checked(path, limit, what, hint) as f:
        try:     # its size first (a read of limit + 1 bytes would allocate that much), then what is left
            data = f.read(os.fstat(f.fileno()).st_size)
            while len(data) <= limit:
                more = f.read(min(limit + 1 - len(data), 1 << 20))
                if not more:
                    break
                data += more
        except OSError as e:
            raise InputError(f"{path}: cannot read ({e.strerror or e})") from None
    if len(data) > limit:
        raise InputError(f"{path}: over the limit of {size_text(limit)} for {what}{hint}")
    return data


def read_text(path, limit: int, what: str = "an input file", hint: str = "") -> str:
    """read_bytes decoded as UTF-8 (UnicodeDecodeError for the caller to name)."""
    return read_bytes(path, limit, what, hint).decode("utf-8")


def read_head(path, n: int, what: str = "a file") -> bytes:
    """The first `n` bytes of a regular file of any size (what recognises a file's format)."""
    with open_checked(path, 1 << 62, what) as f:
        try:
            return f.read(n)
        except OSError as e:
            raise InputError(f"{path}: cannot read ({e.strerror or e})") from None
