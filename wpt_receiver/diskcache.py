"""A small on-disk cache of numpy arrays keyed by a content hash (used for the coupling table).

Location: ``$DRONEWPT_CACHE_DIR`` if set (an empty value turns the cache off), else
``$XDG_CACHE_HOME/dronewpt``, else ``~/.cache/dronewpt``. Each entry is one ``.npy`` file named
after the key's SHA-256; the key text is stored beside it and checked on load, so a stale,
truncated or corrupt file is rebuilt instead of used. Files are written to a temporary name and
renamed (atomic on POSIX), so concurrent processes (sweep workers) never read half a file.
Failing to write (read-only home, full disk) only costs the rebuild next time.
"""

from __future__ import annotations

import functools
import hashlib
import os
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["cache_dir", "key_digest", "load", "store", "prune", "installed_version", "package_version"]

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


def installed_version(package: str) -> str | None:
    """``package``'s installed version for a cache key, without importing the package or :mod:`importlib.metadata`
    (whose import, ~15 ms with the email parser it loads, was most of a key's cost): the version in the name of its
    ``NAME-VERSION.dist-info`` folder in the first ``sys.path`` entry that has one (the order in which
    ``importlib.metadata`` looks; pip names the folder after the name and version of its ``METADATA``), or None
    (not installed as a distribution: the caller falls back to the package's own ``__version__`` or metadata)."""
    return _dist_info_versions().get(_normalised(package))


def package_version(package: str) -> str:
    """``package``'s version for a cache key: :func:`installed_version`, else (not installed as a distribution, e.g. a
    source build on the path) the imported package's ``__version__``."""
    found = installed_version(package)
    if found is None:
        import importlib
        found = str(importlib.import_module(package).__version__)
    return found


def _normalised(name: str) -> str:
    """A distribution's name as its ``.dist-info`` folder spells it (lower case, each run of ``-``, ``_``, ``.`` one
    ``_``: PEP 503's normalisation with the wheel spec's escaping)."""
    return re.sub(r"[-_.]+", "_", name).lower()


@functools.lru_cache(maxsize=1)
def _dist_info_versions() -> dict[str, str]:
    """Normalised distribution name -> version from the ``.dist-info`` folders of the ``sys.path`` entries (the
    first entry's winning), read once per process."""
    out: dict[str, str] = {}
    for entry in sys.path:
        try:
            with os.scandir(entry or ".") as it:
                names = sorted(e.name for e in it if e.name.endswith(".dist-info"))
        except OSError:   # a zip file, a missing folder
            continue
        for n in names:
            name, sep, version = n[:-len(".dist-info")].partition("-")
            if sep and version:
                out.setdefault(_normalised(name), version)
    return out
