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

__all__ = ["cache_dir", "key_digest", "load", "store", "prune", "installed_version", "package_version",
           "unusable_reason", "warn_unusable"]

ENV_VAR = "DRONEWPT_CACHE_DIR"
#: set (to the ``DRONEWPT_CACHE_DIR`` warned about) once :func:`warn_unusable` has said so: the processes started
#: after it (a sweep's workers, forked or spawned: they inherit the environment) do not say it again
WARNED_VAR = "DRONEWPT_CACHE_DIR_WARNED"


def cache_dir() -> Path | None:
    """The cache folder, or ``None`` when ``$DRONEWPT_CACHE_DIR`` is set to an empty string."""
    env = os.environ.get(ENV_VAR)
    if env is not None:
        return Path(env).expanduser() if env.strip() else None
    xdg = os.environ.get("XDG_CACHE_HOME", "").strip()
    return (Path(xdg) if xdg else Path.home() / ".cache") / "dronewpt"


def unusable_reason(folder: Path) -> str | None:
    """Why ``folder`` cannot hold the cache (``"is a file, not a folder"``, ``"cannot be written"``, ``"cannot be
    made: '/x' is a file"`` ...), or None when it can be (or made where it is missing). A few ``stat`` calls, no
    write (it runs at import)."""
    folder = Path(folder).absolute()
    if folder.exists():
        if not folder.is_dir():
            return "is a file, not a folder"
        return None if os.access(folder, os.W_OK | os.X_OK) else "is a folder this user cannot write to"
    parent = folder.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        return f"cannot be made: {str(parent)!r} is a file"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"cannot be made: {str(parent)!r} cannot be written"
    return None


def warn_unusable(numba_folder: Path | None = None) -> str | None:
    """One warning on stderr (the ``dronewpt`` logger's, as the compile notice) when ``$DRONEWPT_CACHE_DIR`` is set to
    a place the cache cannot use (a file, a folder that cannot be written or made): the user's setting would
    otherwise be ignored silently, each run rebuilding what the cache holds (the coupling tables, the mission loop's
    ahead-of-time build: ~33 s instead of ~1 s for the default mission). ``numba_folder``: where numba's cache went
    instead (an installed copy, :func:`~wpt_receiver.kernel_cache.place_numba_cache`). Said once per process tree
    (:data:`WARNED_VAR`); the run goes on. Returns the text, or None when nothing was said."""
    env = os.environ.get(ENV_VAR)
    if not env or not env.strip() or os.environ.get(WARNED_VAR) == env:
        return None
    why = unusable_reason(Path(env).expanduser())
    if why is None:
        return None
    instead = "the disk cache is off (the coupling tables and the mission loop's ahead-of-time build are rebuilt " \
              "in every run: tens of seconds each)"
    if numba_folder is not None:
        instead += f", numba's cache is in {str(numba_folder)!r}"
    text = (f"dronewpt: warning: {ENV_VAR}={env!r} {why}: {instead}; valid: a folder this user can write (or "
            f"{ENV_VAR}= empty to turn the cache off without this warning)")
    os.environ[WARNED_VAR] = env
    import logging
    logging.getLogger("dronewpt").warning(text)
    return text


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
    (whose import, ~15 ms with the email parser it loads, was most of a key's cost), or None when the folder names
    cannot tell it for sure (the caller then falls back to what it did before: :mod:`importlib.metadata` or the
    package's ``__version__``).

    The version is the one in the name of the package's ``NAME-VERSION.dist-info`` folder in the first ``sys.path``
    entry that has metadata for it (the order in which ``importlib.metadata`` looks; pip names the folder after the
    name and version of its ``METADATA``), and only when that is unambiguous: None when that entry holds two
    ``.dist-info`` folders for it (left behind by ``pip install --target T --upgrade``, pypa/pip#13763) or an
    ``.egg-info`` one, when an earlier entry holds a module or package of that name without metadata (a source
    build on ``PYTHONPATH`` shadowing an installed copy), when a zip file or ``.egg`` folder comes earlier on the
    path (not read here), or when the folder's version is escaped (``_``). So the key holds the same string as
    ``importlib.metadata.version`` for a distribution installed as one ``.dist-info`` folder in a plain directory
    (checked for every installed distribution in tests/test_startup_keys.py); a distribution that only a custom
    ``sys.meta_path`` finder provides is not seen here."""
    return _dist_info_versions().get(_normalised(package))


def package_version(package: str) -> str:
    """``package``'s version for a cache key (the same string as its ``__version__`` when the two agree): the imported
    package's ``__version__`` when it is imported already, else :func:`installed_version`, else (not installed as
    one unambiguous distribution, e.g. a source build on the path) the imported package's ``__version__``."""
    module = sys.modules.get(package)
    found = getattr(module, "__version__", None) if module is not None else None
    if found is None:
        found = installed_version(package)
    if found is None:
        import importlib
        found = importlib.import_module(package).__version__
    return str(found)


def _normalised(name: str) -> str:
    """A distribution's name as its ``.dist-info`` folder spells it (lower case, each run of ``-``, ``_``, ``.`` one
    ``_``: PEP 503's normalisation with the wheel spec's escaping)."""
    return re.sub(r"[-_.]+", "_", name).lower()


@functools.lru_cache(maxsize=1)
def _dist_info_versions() -> dict[str, str | None]:
    """Normalised name -> version (None: unknown, see :func:`installed_version`) from the ``.dist-info`` and
    ``.egg-info`` folders and the top-level modules of the ``sys.path`` entries, the first entry that has a name
    deciding it; read once per process. Scanning stops at the first zip file or ``.egg`` folder: any name not
    decided before it is left out (None)."""
    out: dict[str, str | None] = {}
    for entry in sys.path:
        folder = os.fspath(entry) or "."
        if os.path.basename(os.path.normpath(folder)).lower().endswith(".egg"):
            break
        try:
            with os.scandir(folder) as it:
                children = [e.name for e in it]
        except OSError:   # a missing folder, or a zip file (which importlib.metadata reads and this does not)
            if os.path.exists(folder):
                break
            continue
        found: dict[str, list[str | None]] = {}
        modules = set()
        for child in children:
            low = child.lower()
            if low.endswith((".dist-info", ".egg-info")):
                stem, suffix = child.rsplit(".", 1)
                name, sep, version = stem.partition("-")
                ok = suffix.lower() == "dist-info" and sep and version and "_" not in version
                found.setdefault(_normalised(name), []).append(version if ok else None)
            elif not child.startswith((".", "_")):
                modules.add(_normalised(child.partition(".")[0]))
        for name, versions in found.items():
            out.setdefault(name, versions[0] if len(versions) == 1 else None)
        for name in modules - found.keys():
            out.setdefault(name, None)
    return out
