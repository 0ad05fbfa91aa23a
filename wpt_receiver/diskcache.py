"""A small on-disk cache of numpy arrays keyed by a content hash (used for the coupling table).

Location: ``$DRONEWPT_CACHE_DIR`` if set (an empty value turns the cache off), else
``$XDG_CACHE_HOME/dronewpt``, else ``~/.cache/dronewpt``. Each entry is one ``.npy`` file named
after the key's SHA-256; the key text is stored beside it and checked on load, so a stale,
truncated or corrupt file is rebuilt instead of used. Files are written to a temporary name and
renamed (atomic on POSIX), so concurrent processes (sweep workers) never read half a file.
Failing to write (read-only home, full disk) only costs the rebuild next time.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["cache_dir", "key_digest", "load", "store", "prune"]

ENV_VAR = "DRONEWPT_CACHE_DIR"


def cache_dir() -> Path | None:
    """The cache folder, or ``None`` when ``$DRONEWPT_CACHE_DIR`` is set to an empty string."""
    env = os.environ.get(ENV_VAR)
    if env is not None:
        return Path(env).expanduser() if env.strip() else None
    xdg = os.environ.get("XDG_CACHE_HOME", "").strip()
    return (Path(xdg) if xdg else Path.home() / ".cache") / "dronewpt"


def key_digest(key: str) -> str:
    """SHA-256 hex digest of the key text (the file name of its entry)."""
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


def _paths(name: str, key: str):
    d = cache_dir()
    if d is None:
        return None, None
    stem = f"{name}-{key_digest(key)[:32]}"
    return d / f"{stem}.npy", d / f"{stem}.key"


def load(name: str, key: str, shape: tuple) -> np.ndarray | None:
    """The cached float array for ``key`` if present, intact, of ``shape`` and finite; else ``None``."""
    arr_path, key_path = _paths(name, key)
    if arr_path is None:
        return None
    try:
        if key_path.read_text("utf-8") != key:
            return None
        arr = np.load(arr_path, allow_pickle=False)
    except (OSError, ValueError, EOFError, UnicodeDecodeError):
        return None
    if arr.shape != tuple(shape) or arr.dtype != np.float64 or not np.all(np.isfinite(arr)):
        return None
    return arr


def _atomic_write(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def store(name: str, key: str, arr: np.ndarray) -> Path | None:
    """Write ``arr`` under ``key`` (array first, then its key file); returns the path or ``None``."""
    arr_path, key_path = _paths(name, key)
    if arr_path is None:
        return None
    try:
        arr_path.parent.mkdir(parents=True, exist_ok=True)
        _atomic_write(arr_path, lambda fh: np.save(fh, np.ascontiguousarray(arr, dtype=np.float64)))
        _atomic_write(key_path, lambda fh: fh.write(key.encode("utf-8")))
    except OSError:
        return None
    return arr_path


def prune(name: str, keep: int) -> int:
    """Remove all but the ``keep`` newest entries (by modification time) named ``name``; the number
    removed. Races with other processes only cost a rebuild (a vanished file is skipped)."""
    d = cache_dir()
    if d is None:
        return 0
    try:
        entries = []
        for p in d.glob(f"{name}-*.npy"):
            try:
                entries.append((p.stat().st_mtime, p))
            except OSError:
                continue
    except OSError:
        return 0
    entries.sort(reverse=True)
    for _, p in entries[keep:]:
        try:
            p.unlink(missing_ok=True)
            p.with_suffix(".key").unlink(missing_ok=True)
        except OSError:
            pass
    return max(0, len(entries) - keep)
