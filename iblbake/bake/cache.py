"""Content-addressed bake cache: DIR/<key>/ holds the files of one bake and a manifest.json.

- The key hashes everything that changes the result (input content, options, kernel source).
- An entry is built in DIR/.tmp-<key>-<pid>/ and renamed into place with its manifest last, so a
  crash or kill midway never leaves an entry a later run accepts.
- A per-key file lock (filelock) serialises concurrent builders (make -j): the loser waits, then
  finds the finished entry and reuses it.
- On reuse every file is checked against the manifest: its size and modification time as the
  build left them, else (a copied, touched or rewritten entry) its sha256, as git's index does; a
  mismatch is a warning and a rebuild. (Hashing a render's 33 MB prefiltered chain took 35 ms of
  every warm render.)
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
from iblbake.errors import IblbakeError, InputError
from iblbake.io import reads
from iblbake.io.images import file_sha256

MANIFEST = "manifest.json"


def content_key(parts: dict) -> str:
    blob = json.dumps(parts, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


# A prune never removes an entry used this recently: a process that has just verified an entry
# may still be reading its files.
PRUNE_GRACE_S = 120.0


def default_root() -> Path:
    """$IBLBAKE_CACHE, else the per-user cache folder (shared by runs from any folder; no cache
    appears in a project tree)."""
    env = os.environ.get("IBLBAKE_CACHE")
    if env:
        return Path(env)
    import platformdirs
    return Path(platformdirs.user_cache_dir("iblbake")) / "bakes"


def said(root) -> str:
    """How a message names the cache folder `root`: by the variable where it is $IBLBAKE_CACHE
    (the user set it somewhere else: the message says what to change)."""
    env = os.environ.get("IBLBAKE_CACHE")
    return f"IBLBAKE_CACHE={env}" if env and Path(env) == Path(root) else str(root)


def _touch(entry: Path) -> None:
    """Mark an entry used now (its manifest's mtime): what prune's least-recently-used order reads."""
    try:
        os.utime(entry / MANIFEST)
    except OSError:
        pass


def verify(entry: Path, warn: Callable[[str], None] | None = None) -> dict | None:
    """The entry's manifest if the entry is complete and every file matches its hash, else None."""
    mpath = entry / MANIFEST
    if not mpath.is_file():
        return None
    try:
        manifest = read_manifest(mpath)
        for f in manifest["files"]:
            p = entry / f["name"]
            if not p.is_file() or (_stat(p) != (f.get("bytes"), f.get("mtime_ns")) and file_sha256(p) != f["sha256"]):
                if warn:
                    warn(f"cache file {p} does not match its manifest hash; rebuilding {entry.name}")
                return None
    except (ValueError, KeyError, TypeError, OSError, InputError):
        if warn:
            warn(f"cache manifest {mpath} is unreadable; rebuilding {entry.name}")
        return None
    return manifest


def read_manifest(mpath: Path) -> dict:
    """An entry's manifest: a regular file of at most reads.JSON_BYTES (an InputError otherwise)."""
    return json.loads(reads.read_text(mpath, reads.JSON_BYTES, "a cache manifest"))


def _stat(path: Path) -> tuple:
    st = path.stat()
    return st.st_size, st.st_mtime_ns


def _remove(path: Path):
    if path.exists():
        trash = path.with_name(f".trash-{path.name}-{os.getpid()}-{time.time_ns()}")
        os.replace(path, trash)
        shutil.rmtree(trash, ignore_errors=True)


def get_checked(root: Path, key: str, build: Callable[[Path], dict], read: Callable[[dict], object], *,
                warn: Callable[[str], None] | None = None) -> tuple:
    """(read(manifest), manifest, cached): get_or_build, then the entry read back and checked by
    `read` (an IblbakeError where it does not hold what its kind must). A cached entry that fails
    (files that match their manifest but not their kind: written by another version, or by hand) is
    said, removed and built again once; a fresh one that fails is the error."""
    manifest, cached = get_or_build(root, key, build, warn=warn)
    try:
        return read(manifest), manifest, cached
    except IblbakeError as e:
        if not cached:
            raise
        if warn:
            warn(f"{Path(root) / key}: {e}; baking it again")
        _remove(Path(root) / key)
    manifest, cached = get_or_build(root, key, build, warn=warn)
    return read(manifest), manifest, cached


def get_or_build(root: Path, key: str, build: Callable[[Path], dict], *,
                 warn: Callable[[str], None] | None = None) -> tuple[dict, bool]:
    """(manifest, cached). `build(tmpdir)` writes the files and returns the manifest body, whose
    "files" list names them; hashes are added here and the manifest is written last."""
    import filelock

    root = Path(root)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{said(root)}: cannot create the cache folder ({e.strerror}); give a folder "
                         f"that can be made and written") from None
    entry = root / key
    manifest = verify(entry)
    if manifest is not None:
        _touch(entry)
        return manifest, True
    try:
        with filelock.FileLock(str(root / f".{key}.lock")):
            manifest = verify(entry, warn)   # another process may have finished it meanwhile
            if manifest is not None:
                _touch(entry)
                return manifest, True
            for stale in root.glob(f".tmp-{key}-*"):   # left by a killed builder (we hold the lock)
                shutil.rmtree(stale, ignore_errors=True)
            tmp = root / f".tmp-{key}-{os.getpid()}"
            tmp.mkdir()
            try:
                body = build(tmp)
                for f in body["files"]:
                    f["sha256"] = file_sha256(tmp / f["name"])
                    f["bytes"], f["mtime_ns"] = _stat(tmp / f["name"])
                body["key"] = key
                write_json(tmp / MANIFEST, body)
                _remove(entry)
                os.replace(tmp, entry)
            except BaseException:
                shutil.rmtree(tmp, ignore_errors=True)
                raise
    except OSError as e:   # read-only folder, disk full, no permission: nothing was left behind
        raise IblbakeError(f"{said(root)}: cannot write the cache entry {key} ({e.strerror or e}); "
                           f"free space or use a writable cache folder") from None
    return body, False


def entries(root: Path) -> list:
    """Every complete entry: {key, kind, bytes, used (manifest mtime), path}, most recently used first."""
    root = Path(root)
    out = []
    if not root.is_dir():
        return out
    for e in root.iterdir():
        m = e / MANIFEST
        if e.name.startswith(".") or not m.is_file():
            continue
        try:
            kind = read_manifest(m).get("kind", "?")
            size = sum(f.stat().st_size for f in e.iterdir() if f.is_file())
            used = m.stat().st_mtime
        except (OSError, ValueError, InputError, AttributeError):
            continue
        out.append({"key": e.name, "kind": kind, "bytes": size, "used": used, "path": str(e)})
    return sorted(out, key=lambda x: -x["used"])


def prune(root: Path, max_bytes: int, grace_s: float = PRUNE_GRACE_S) -> tuple[list, list]:
    """Remove least-recently-used entries until the cache holds at most max_bytes. Safe beside
    other processes: an entry being built (its lock held) or used within grace_s is kept.
    Returns (removed, kept-although-over) entries."""
    import filelock

    root = Path(root)
    live = entries(root)
    total = sum(e["bytes"] for e in live)
    removed, busy = [], []
    now = time.time()
    for e in reversed(live):                      # least recently used first
        if total <= max_bytes:
            break
        if now - e["used"] < grace_s:
            busy.append(e)
            continue
        try:
            with filelock.FileLock(str(root / f".{e['key']}.lock"), timeout=0):
                if now - (Path(e["path"]) / MANIFEST).stat().st_mtime < grace_s:   # used meanwhile
                    busy.append(e)
                    continue
                _remove(Path(e["path"]))
        except (filelock.Timeout, FileNotFoundError):
            busy.append(e)
            continue
        total -= e["bytes"]
        removed.append(e)
    return removed, busy
