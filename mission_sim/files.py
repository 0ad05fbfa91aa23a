"""Writing output files so that an interrupted run never leaves a truncated file under its final name."""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

__all__ = ["atomic_output"]


@contextmanager
def atomic_output(path):
    """Yield a temporary path beside ``path`` (same folder, same suffix, so writers that go by the
    extension still work); on success rename it to ``path`` (``os.replace``: atomic on one file
    system), on any exception (Ctrl-C included) remove it and re-raise."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
