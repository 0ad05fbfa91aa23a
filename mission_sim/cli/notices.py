"""The command line's side of :mod:`wpt_receiver.notices`: the one line on stderr when numba starts compiling
a kernel (the first run on a machine spends ~40 s there, silently otherwise), shown only where the progress
bars are (a terminal, no ``--no-progress``; :func:`announce_compilation`), nothing otherwise
(:func:`quiet_compilation`); and the library's :class:`~wpt_receiver.notices.DronewptWarning` as one line
``dronewpt COMMAND: warning: ...`` each (:func:`warning_lines`)."""

from __future__ import annotations

import contextlib
import os
import sys
import warnings

from wpt_receiver.notices import NOTICE, NOTICE_VAR, DronewptWarning, set_compile_sink

__all__ = ["announce_compilation", "quiet_compilation", "warning_lines", "NOTICE"]


def _above_bars(line: str) -> None:
    from tqdm import tqdm
    tqdm.write(line, file=sys.stderr)  # above an active progress bar


def _children_quiet() -> None:
    """The processes this command starts (a sweep's workers) give no notice of their own, as before the library
    had one (:data:`wpt_receiver.notices.NOTICE_VAR`)."""
    os.environ[NOTICE_VAR] = "0"


def announce_compilation() -> None:
    """From now on, print the notice (once per process) when numba compiles a kernel."""
    set_compile_sink(_above_bars)
    _children_quiet()


def quiet_compilation() -> None:
    """No notice (piped output, ``--no-progress``): the library's logged notice is off too."""
    set_compile_sink(None)
    _children_quiet()


@contextlib.contextmanager
def warning_lines(command: str):
    """Within: each distinct :class:`~wpt_receiver.notices.DronewptWarning` printed once as ``dronewpt COMMAND:
    warning: MESSAGE`` on stderr (one line); any other warning as Python shows it."""
    seen = set()
    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, DronewptWarning):
            return shown(message, category, filename, lineno, file, line)
        text = " ".join(str(message).split())
        if text not in seen:
            seen.add(text)
            print(f"dronewpt {command}: warning: {text}", file=sys.stderr)

    with warnings.catch_warnings():
        warnings.simplefilter("always", DronewptWarning)   # (dedup here: by message, not by code location)
        warnings.showwarning = show
        yield
