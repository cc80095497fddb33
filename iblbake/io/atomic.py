"""Atomic file writes: write to a hidden temp file beside the target, check every write and
fsync it, then rename. A crash, SIGKILL, Ctrl-C or full disk never leaves a half-written file
under the final name (the old file stays); at worst a hidden `.NAME.tmp-*` file that no reader
accepts. Several outputs of one command go together (Batch): all are replaced, or none.
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path

from iblbake.errors import IblbakeError


class Batch:
    """Outputs written together: each goes to a hidden temp file beside its target, checked
    (every write's result, then fsync), and only when all of them are written are they renamed
    into place; if any fails, none is replaced (the old files are kept), the temp files are
    removed and so is any output folder the batch created. One output is a batch of one
    (atomic_path, write_bytes). A missing output folder is created when the result is ready, so a
    command that fails before it writes leaves no empty folder behind."""

    def __init__(self):
        self._staged = []            # (tmp, final)
        self._made = []              # folders this batch created, outermost first

    def path(self, final) -> str:
        """A new temp path for `final` (its folder made if missing)."""
        final = Path(final)
        folder = final.parent if str(final.parent) else Path(".")
        missing = []
        f = folder
        while not f.exists() and f != f.parent:
            missing.append(f)
            f = f.parent
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise IblbakeError(f"{final}: cannot create the output folder {folder}: {e.strerror or e}") from None
        self._made += [m for m in reversed(missing) if m not in self._made]
        try:
            tmp = _new_file_beside(final, folder)
        except OSError as e:
            self.discard()
            raise IblbakeError(f"{final}: cannot write in {folder}: {e.strerror}") from None
        self._staged.append((tmp, final))
        return tmp

    def write_bytes(self, final, data: bytes) -> None:
        tmp = self.path(final)
        try:
            with open(tmp, "wb") as f:
                f.write(data)
        except OSError as e:
            self.discard()
            raise IblbakeError(f"{final}: write failed: {e.strerror or e}") from None

    def write_text(self, final, text: str) -> None:
        self.write_bytes(final, text.encode("utf-8"))

    def write_json(self, final, obj) -> None:
        self.write_text(final, json.dumps(obj, indent=2, allow_nan=False) + "\n")

    def commit(self) -> None:
        """fsync every temp file (a write the disk could not hold fails here, not later), then
        rename them all into place."""
        final = None
        try:
            for tmp, final in self._staged:
                fd = os.open(tmp, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
                # created 0600; the final file gets what a plain open() would give it
                os.chmod(tmp, 0o666 & ~_umask())
            for tmp, final in self._staged:
                os.replace(tmp, final)
        except OSError as e:
            self.discard()
            raise IblbakeError(f"{final}: write failed: {e.strerror or e}") from None
        self._staged, self._made = [], []

    def discard(self) -> None:
        for tmp, _ in self._staged:
            _unlink(tmp)
        for folder in reversed(self._made):      # innermost first; only while empty
            with contextlib.suppress(OSError):
                folder.rmdir()
        self._staged, self._made = [], []

    def __enter__(self):
        return self

    def __exit__(self, kind, value, tb):
        if kind is None:
            self.commit()
        else:
            self.discard()
        return False


@contextlib.contextmanager
def atomic_path(final: str | os.PathLike, batch: Batch | None = None):
    """Yield a temp path in the target's folder for a writer that takes a path (OpenImageIO);
    it is renamed onto `final` with the rest of `batch`, or alone (checked and fsynced) when no
    batch is given. An OSError from the writer is a one-line error naming `final`."""
    own = batch is None
    batch = batch or Batch()
    tmp = batch.path(final)
    try:
        yield tmp
    except OSError as e:
        batch.discard()
        raise IblbakeError(f"{final}: write failed: {e.strerror or e}") from None
    except BaseException:
        batch.discard()
        raise
    if own:
        batch.commit()


def _new_file_beside(final: Path, folder: Path) -> str:
    """A new hidden file in `folder`, created exclusively with mode 0600 as tempfile.mkstemp does
    (whose import, with shutil's and random's, costs sh 7 ms of start-up); the extension kept
    last, since OpenImageIO picks the format from it."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    stem, suffix = _temp_parts(final, folder)
    for _ in range(100):
        tmp = folder / f".{stem}.tmp-{os.urandom(6).hex()}{suffix}"
        try:
            os.close(os.open(tmp, flags, 0o600))
        except FileExistsError:
            continue
        return str(tmp)
    raise FileExistsError(17, "no free temporary name")


_TEMP_EXTRA = len(".") + len(".tmp-") + 12      # what a temporary name adds to the stem and suffix


def _temp_parts(final: Path, folder: Path) -> tuple[str, str]:
    """The stem and suffix a temporary name beside `final` carries: the stem cut, on a character
    boundary, so that the whole name stays within the folder's longest name (255 bytes on most
    file systems: an output named with 240 bytes is legal, its temporary file 18 bytes longer was
    not), a suffix of more than 16 bytes dropped."""
    try:
        limit = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        limit = 255
    suffix = final.suffix if len(os.fsencode(final.suffix)) <= 16 else ""
    stem = final.name[:len(final.name) - len(suffix)] if suffix else final.name
    room = limit - _TEMP_EXTRA - len(os.fsencode(suffix))
    while len(os.fsencode(stem)) > room:
        stem = stem[:-1]
    return stem, suffix


def _umask() -> int:
    mask = os.umask(0)      # the only way to read it is to set it; put it straight back
    os.umask(mask)
    return mask


def _unlink(path):
    with contextlib.suppress(OSError):
        os.unlink(path)


def write_bytes(final, data: bytes, batch: Batch | None = None) -> None:
    """`data` into `final` atomically (with `batch`'s other outputs, where given)."""
    if batch is not None:
        batch.write_bytes(final, data)
        return
    with Batch() as b:
        b.write_bytes(final, data)


def write_text(final, text: str, batch: Batch | None = None) -> None:
    write_bytes(final, text.encode("utf-8"), batch)


def write_json(final, obj, batch: Batch | None = None) -> None:
    write_text(final, json.dumps(obj, indent=2, allow_nan=False) + "\n", batch)


def check_writable(final: str | os.PathLike, what: str = "output", shown=None) -> None:
    """Fail before any work if `final` could not be written: its nearest existing folder must be
    a writable folder (read-only mounts and permissions are caught here, not after a long bake)."""
    final = Path(final)
    folder = final.parent
    final = shown or final
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise IblbakeError(f"{final}: cannot write the {what}: {folder} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise IblbakeError(f"{final}: cannot write the {what}: {folder} is not writable "
                           f"(read-only or no permission)")
