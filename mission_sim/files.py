"""Writing output files so that a failed or interrupted run never leaves a truncated file under its
final name nor a temporary file beside it, and one writer per output folder.

:func:`atomic_output` is the one place where temporary files are made, renamed and removed (the
mission's files, figures, the sweep's Parquet parts and merges, replay outputs); a full disk or a
file-size limit there becomes :class:`OutputError`, one line naming the file. :func:`folder_lock`
is the writer lock of ``mission --out`` and of a sweep's folder.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
from contextlib import contextmanager
from pathlib import Path

from .signals import raise_lost

__all__ = ["atomic_output", "rename_into_place", "OutputError", "storage_error", "folder_lock", "FolderBusy",
           "move_aside"]

#: errors of the storage, not of the data: reported as :class:`OutputError` naming the file
_STORAGE_ERRNOS = {errno.ENOSPC: "no space left on the device", errno.EFBIG: "file too large (the file-size "
                   "limit, ulimit -f, or the file system's)", errno.EDQUOT: "disk quota exceeded",
                   errno.EIO: "input/output error", errno.EROFS: "read-only file system"}


class OutputError(OSError):
    """An output file could not be written (disk full, file-size limit, quota, I/O error): one line
    naming the file; its temporary file has been removed, or (``kept``, the stream's .tlog) is kept and named."""

    def __init__(self, path, err: int, reason: str, kept=None):
        super().__init__(err, reason, str(path))
        self.path, self.reason = Path(path), reason
        self.kept = None if kept is None else Path(kept)

    def __str__(self) -> str:
        left = "nothing partial was left" if self.kept is None else \
            f"what was written before it is in {str(self.kept)!r}"
        return f"cannot write {str(self.path)!r}: {self.reason}; {left}"

    def __reduce__(self):   # pickled as itself (from a figure worker process), not as OSError's arguments
        return type(self), (self.path, self.errno, self.reason, self.kept)


def storage_error(exc: OSError, path, kept=None) -> OutputError | None:
    """``exc`` as an :class:`OutputError` naming ``path`` (and ``kept``, where what was written stays) if it is a
    storage error, else None."""
    reason = _STORAGE_ERRNOS.get(getattr(exc, "errno", None))
    return None if reason is None else OutputError(path, exc.errno, reason, kept)


def rename_into_place(tmp, path) -> None:
    """``os.replace(tmp, path)`` after :func:`~mission_sim.signals.raise_lost` (an interrupt a callback swallowed:
    nothing is renamed into place after it): the last step of :func:`atomic_output` and of the stream's .tlog
    (:class:`mission_sim.mavlink.telemetry.TlogWriter`)."""
    raise_lost()
    os.replace(tmp, path)


@contextmanager
def atomic_output(path, tmp_name: str | None = None, fsync: bool = False):
    """Yield a temporary path beside ``path`` (same folder, same suffix, so writers that go by the
    extension still work; or ``tmp_name`` in that folder); on success (``fsync`` it first if asked)
    rename it to ``path`` (``os.replace``: atomic on one file system). On any exception (Ctrl-C,
    SIGTERM, a full disk) the temporary file is removed and the exception re-raised - a storage error
    (ENOSPC, EFBIG, EDQUOT, EIO, EROFS) as :class:`OutputError` naming ``path``."""
    path = Path(path)
    tmp = path.with_name(tmp_name or f".{path.stem}.tmp{os.getpid()}{path.suffix}")
    try:
        yield tmp
        if fsync:
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
        rename_into_place(tmp, path)
    except OutputError:
        raise
    except OSError as exc:
        named = storage_error(exc, path)
        if named is None:
            raise
        raise named from None
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)


def move_aside(path, when: float | None = None) -> Path:
    """Rename ``path`` (a file or a folder) to a free name beside it marked with the UTC time, so that a new run
    can write its own without replacing it: ``monitor.monitor.prev-20261128T054800Z.csv`` (a file keeps its
    suffix), ``ppo_s0.prev-20261128T054800Z`` (a folder); ``-2``, ``-3``, ... appended if that name is taken.
    Returns the new path."""
    import time
    path = Path(path)
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(when))
    stem, suffix = (path.name, "") if path.is_dir() else (path.stem, path.suffix)
    for k in range(1, 1000):
        new = path.with_name(f"{stem}.prev-{stamp}{'' if k == 1 else f'-{k}'}{suffix}")
        if not new.exists():
            os.rename(path, new)
            return new
    raise FileExistsError(f"no free name to move {str(path)!r} aside")


class FolderBusy(ValueError):
    """Another process holds the folder's writer lock (a bad-input error: exit status 2)."""


@contextmanager
def folder_lock(folder, name: str, busy: str):
    """Exclusive writer lock ``folder/name`` (``flock``; released by the kernel when the process ends,
    even if killed). Raises :class:`FolderBusy` with the text ``busy`` at once if another process
    holds it. The lock file is removed on leaving (while still locked; a process that opened the old
    file meanwhile sees that it was replaced and takes the new one), so a finished run leaves no
    0-byte lock file behind."""
    from .signals import interrupts_deferred
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    fh = None
    try:
        with interrupts_deferred():   # a SIGTERM while taking the lock is raised once it is held (then removed)
            fh = _take_lock(path, busy)
        yield path
    finally:
        if fh is not None:
            with contextlib.suppress(OSError):
                path.unlink()
            fh.close()


def _take_lock(path: Path, busy: str):
    """The open, ``flock``-ed file ``path`` (see :func:`folder_lock`); :class:`FolderBusy` if held elsewhere."""
    for _ in range(20):
        fh = open(path, "a+")
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.close()
            raise FolderBusy(busy) from None
        try:
            same = os.fstat(fh.fileno()).st_ino == os.stat(path).st_ino
        except FileNotFoundError:  # removed by the previous holder between our open and our lock
            same = False
        if same:
            return fh
        fh.close()
    raise FolderBusy(busy)
