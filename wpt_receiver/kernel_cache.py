"""numba's on-disk cache of a module whose compiled functions call into other modules, kept in step with them.

numba keys a ``cache=True`` function's cache on its own source file: code it compiles in from another
module (a called ``@njit`` function, a global constant such as a named slot) is frozen into the
cached machine code, and a change to that other file does not invalidate it (numba's documentation,
"Cache invalidation fails to recognize changes in symbols defined in a different file"; numba issues
#1833, #9304). :func:`drop_stale_cache` closes the gap for a dependent module: called at its import,
before any of its functions is compiled or loaded, it compares a hash of its dependencies' sources
with a stamp kept beside numba's cache files and, when they differ, deletes the dependent module's
``.nbi`` / ``.nbc`` files (numba then compiles afresh and caches again) and writes the new stamp.

Used by :mod:`mission_sim.world.loop_kernel` (on :mod:`wpt_receiver.modal_kernel`),
:mod:`envs.vector_kernel` and :mod:`envs.rollout`'s replay loop.

:func:`place_numba_cache` keeps numba's cache out of ``site-packages`` for an installed (not editable) copy:
numba writes its cache files into a ``__pycache__`` beside each source it can write to, ``pip uninstall`` (or
the ``pip install -e .`` that replaces the copy) removes only the files it installed, and the package folders
left behind with those caches alone are namespace packages that shadow an editable install of the same
packages (``ImportError: ... (unknown location)``: the README's two quickstart lines run in one venv did this).
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

#: numba's variable for a user-chosen cache root (numba mirrors each source's folder under it)
NUMBA_CACHE_VAR = "NUMBA_CACHE_DIR"
_INSTALL_DIRS = ("site-packages", "dist-packages")


def _usable(folder: Path) -> Path | None:
    """``folder``, made if missing, when a file can be written in it (numba's own test); else ``None``."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".probe.{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError:
        return None
    return folder


def _private_temporary() -> Path | None:
    """``<tmp>/dronewpt-numba-<uid>`` when it is this user's alone (numba's cache files hold pickles: never one
    another user could have written), else a new folder of this process's (``tempfile.mkdtemp``); ``None`` if
    neither can be made."""
    import tempfile
    uid = os.getuid() if hasattr(os, "getuid") else None
    if uid is not None:
        shared = Path(tempfile.gettempdir()) / f"dronewpt-numba-{uid}"
        try:
            shared.mkdir(mode=0o700, exist_ok=True)
            st = shared.lstat()
            if shared.is_dir() and not shared.is_symlink() and st.st_uid == uid and not st.st_mode & 0o022:
                return _usable(shared)
        except OSError:
            pass
    try:
        return Path(tempfile.mkdtemp(prefix="dronewpt-numba-"))
    except OSError:
        return None


_state: dict = {"fallback": None}


def numba_fallback() -> Path | None:
    """The private temporary folder :func:`place_numba_cache` gave numba's cache because dronewpt's cache folder could
    not be written, or None."""
    return _state["fallback"]


def place_numba_cache(package_dir) -> Path | None:
    """For an installed copy (``package_dir``'s parent is a ``site-packages`` / ``dist-packages`` folder) and no
    ``NUMBA_CACHE_DIR`` of the user's: numba's cache root becomes ``<dronewpt's disk cache>/numba`` (the process's
    environment, inherited by its workers, and numba's config when numba is imported already); returns it, or
    ``None`` when nothing changed (a checkout or an editable install keeps numba's ``__pycache__`` beside its
    sources, a ``NUMBA_CACHE_DIR`` set by the user is kept, and ``DRONEWPT_CACHE_DIR=""`` leaves numba as it is). A
    cache folder that cannot be written (numba would decline it and fall back to ``site-packages``) is replaced by
    a private one in the temporary folder; a relative ``DRONEWPT_CACHE_DIR`` is made absolute."""
    from .diskcache import cache_dir
    if Path(package_dir).resolve().parent.name not in _INSTALL_DIRS or os.environ.get(NUMBA_CACHE_VAR):
        return None
    root = cache_dir()
    if root is None:
        return None
    folder = _usable(root.absolute() / "numba")   # absolute: workers started in another folder find the same
    if folder is None:   # numba would decline it and write beside the sources again: a private temporary one
        folder = _private_temporary()
        if folder is None:
            return None
        _state["fallback"] = folder      # (said by diskcache.warn_unusable, once)
    os.environ[NUMBA_CACHE_VAR] = str(folder)
    config = sys.modules.get("numba.core.config")
    if config is not None and not getattr(config, "CACHE_DIR", ""):
        config.CACHE_DIR = str(folder)      # numba read its environment already; its locators read this
    return folder


__all__ = ["drop_stale_cache", "dependency_hash", "place_numba_cache", "numba_fallback"]


def dependency_hash(modules) -> str:
    """sha256 over the source files of ``modules`` (module objects or file paths), in the given order."""
    h = hashlib.sha256()
    for m in modules:
        path = Path(m if isinstance(m, (str, os.PathLike)) else m.__file__)
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def drop_stale_cache(here, modules) -> bool:
    """Delete the numba cache of the module that defines the plain function ``here`` when the sources of
    ``modules`` (what its compiled functions call or read) changed since the stamp; True if it did.

    The cache folder is numba's own choice for that module (its cache locators, as for a ``cache=True``
    function defined there: its
    ``__pycache__``, or ``NUMBA_CACHE_DIR``); the stamp is ``<module>.deps`` there. Nothing happens when
    numba has no usable cache folder; a folder that cannot be written leaves the cache as it is."""
    from numba.core.caching import CompileResultCacheImpl
    try:
        folder = Path(CompileResultCacheImpl(here).locator.get_cache_path())
    except RuntimeError:      # no cache locator applies (numba would not cache either)
        return False
    stem = Path(here.__code__.co_filename).stem
    stamp = folder / f"{stem}.deps"
    digest = dependency_hash(modules)
    try:
        if stamp.read_text() == digest:
            return False
    except OSError:
        pass
    try:
        for f in folder.glob(f"{stem}.*"):
            if f.suffix in (".nbi", ".nbc"):
                f.unlink(missing_ok=True)
        folder.mkdir(parents=True, exist_ok=True)
        tmp = folder / f"{stem}.deps.{os.getpid()}.tmp"
        tmp.write_text(digest)
        os.replace(tmp, stamp)
    except OSError:
        return False
    return True
