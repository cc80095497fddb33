"""Content-addressed bake cache: DIR/<key>/ holds the files of one bake and a manifest.json.

- The key hashes everything that changes the result (input content, options, kernel source).
- An entry is built in DIR/.tmp-<key>-<pid>/ and renamed into place with its manifest last, so a
  crash or kill midway never leaves an entry a later run accepts.
- A per-key file lock (filelock) serialises concurrent builders (make -j): the loser waits, then
  finds the finished entry and reuses it.
- On reuse every file's sha256 is checked against the manifest; a mismatch is a warning and a
  rebuild.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from pathlib import Path
from typing import Callable

from iblbake.io.atomic import write_json
from iblbake.errors import IblbakeError
from iblbake.io.images import file_sha256

MANIFEST = "manifest.json"


def content_key(parts: dict) -> str:
    blob = json.dumps(parts, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def default_root() -> Path:
    return Path(os.environ.get("IBLBAKE_CACHE") or "iblbake-cache")


def verify(entry: Path, warn: Callable[[str], None] | None = None) -> dict | None:
    """The entry's manifest if the entry is complete and every file matches its hash, else None."""
    mpath = entry / MANIFEST
    if not mpath.is_file():
        return None
    try:
        manifest = json.loads(mpath.read_text())
        for f in manifest["files"]:
            p = entry / f["name"]
            if not p.is_file() or file_sha256(p) != f["sha256"]:
                if warn:
                    warn(f"cache file {p} does not match its manifest hash; rebuilding {entry.name}")
                return None
    except (ValueError, KeyError, TypeError, OSError):
        if warn:
            warn(f"cache manifest {mpath} is unreadable; rebuilding {entry.name}")
        return None
    return manifest


def _remove(path: Path):
    if path.exists():
        trash = path.with_name(f".trash-{path.name}-{os.getpid()}-{time.time_ns()}")
        os.replace(path, trash)
        shutil.rmtree(trash, ignore_errors=True)


def get_or_build(root: Path, key: str, build: Callable[[Path], dict], *,
                 warn: Callable[[str], None] | None = None) -> tuple[dict, bool]:
    """(manifest, cached). `build(tmpdir)` writes the files and returns the manifest body, whose
    "files" list names them; hashes are added here and the manifest is written last."""
    import filelock

    root = Path(root)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise IblbakeError(f"{root}: cannot create the cache folder ({e.strerror})") from None
    entry = root / key
    manifest = verify(entry)
    if manifest is not None:
        return manifest, True
    try:
        with filelock.FileLock(str(root / f".{key}.lock")):
            manifest = verify(entry, warn)   # another process may have finished it meanwhile
            if manifest is not None:
                return manifest, True
            for stale in root.glob(f".tmp-{key}-*"):   # left by a killed builder (we hold the lock)
                shutil.rmtree(stale, ignore_errors=True)
            tmp = root / f".tmp-{key}-{os.getpid()}"
            tmp.mkdir()
            try:
                body = build(tmp)
                for f in body["files"]:
                    f["sha256"] = file_sha256(tmp / f["name"])
                body["key"] = key
                write_json(tmp / MANIFEST, body)
                _remove(entry)
                os.replace(tmp, entry)
            except BaseException:
                shutil.rmtree(tmp, ignore_errors=True)
                raise
    except OSError as e:   # read-only folder, disk full, no permission: nothing was left behind
        raise IblbakeError(f"{root}: cannot write the cache entry {key} ({e.strerror or e}); "
                           f"free space or use a writable cache folder") from None
    return body, False
