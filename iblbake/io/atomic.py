"""Atomic file writes: write to a hidden temp file beside the target, then rename.

A crash, SIGKILL or Ctrl-C never leaves a half-written file under the final
name; at worst a hidden `.NAME.tmp-*` file that no reader accepts.
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path

from iblbake.errors import IblbakeError


@contextlib.contextmanager
def atomic_path(final: str | os.PathLike):
    """Yield a temp path in the target's folder; rename it onto `final` on success. A missing
    output folder is created here, when the result is ready, so a command that fails before it
    writes leaves no empty folder behind (one rule for every command's outputs)."""
    final = Path(final)
    folder = final.parent if str(final.parent) else Path(".")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise IblbakeError(f"{final}: cannot create the output folder {folder}: {e.strerror or e}") from None
    try:
        tmp = _new_file_beside(final, folder)
    except OSError as e:
        raise IblbakeError(f"{final}: cannot write in {folder}: {e.strerror}") from None
    try:
        yield tmp
        # created 0600; the final file gets what a plain open() would give it
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, final)
    except OSError as e:
        _unlink(tmp)
        raise IblbakeError(f"{final}: write failed: {e.strerror or e}") from None
    except BaseException:
        _unlink(tmp)
        raise


def _new_file_beside(final: Path, folder: Path) -> str:
    """A new hidden file in `folder`, created exclusively with mode 0600 as tempfile.mkstemp does
    (whose import, with shutil's and random's, costs sh 7 ms of start-up); the extension kept
    last, since OpenImageIO picks the format from it."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        tmp = folder / f".{final.stem}.tmp-{os.urandom(6).hex()}{final.suffix}"
        try:
            os.close(os.open(tmp, flags, 0o600))
        except FileExistsError:
            continue
        return str(tmp)
    raise FileExistsError(17, "no free temporary name")


def _umask() -> int:
    mask = os.umask(0)      # the only way to read it is to set it; put it straight back
    os.umask(mask)
    return mask


def _unlink(path):
    with contextlib.suppress(OSError):
        os.unlink(path)


def write_bytes(final, data: bytes) -> None:
    with atomic_path(final) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())


def write_text(final, text: str) -> None:
    write_bytes(final, text.encode("utf-8"))


def write_json(final, obj) -> None:
    write_text(final, json.dumps(obj, indent=2, allow_nan=False) + "\n")


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
