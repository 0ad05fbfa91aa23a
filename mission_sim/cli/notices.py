"""The command line's side of :mod:`wpt_receiver.notices`: the one line on stderr when numba starts compiling
a kernel (the first run on a machine spends ~40 s there, silently otherwise), shown only where the progress
bars are (a terminal, no ``--no-progress``), nothing otherwise (:func:`compile_notices`); and the library's
``DronewptWarning`` as one line ``dronewpt COMMAND: warning: ...`` each (:func:`warning_lines`).

Nothing of ``wpt_receiver`` is imported on the quiet path (piped output; ``sweep --status`` and the like): the
library's notice is off by an environment variable (:data:`NOTICE_VAR`, read when the notice would fire), and a
warning's category is recognised by its module and name. Both are undone when the command returns (a notebook
calling :func:`mission_sim.cli.main` keeps its own environment, notice and warning filters)."""

from __future__ import annotations

import contextlib
import os
import sys
import warnings

__all__ = ["compile_notices", "warning_lines", "say_warning", "flag_words", "FLAG_WORDS", "is_dronewpt_warning", "NOTICE_VAR"]

#: :data:`wpt_receiver.notices.NOTICE_VAR` (spelt here: this module does not import the library)
NOTICE_VAR = "DRONEWPT_COMPILE_NOTICE"
_WARNING_CLASS = ("wpt_receiver.notices", "DronewptWarning")


def is_dronewpt_warning(category) -> bool:
    """``issubclass(category, wpt_receiver.notices.DronewptWarning)``, without importing it."""
    return isinstance(category, type) and any((c.__module__, c.__name__) == _WARNING_CLASS
                                              for c in category.__mro__)


def _above_bars(notice: str) -> None:
    from tqdm import tqdm
    tqdm.write(f"dronewpt: {notice}", file=sys.stderr)  # above an active progress bar


@contextlib.contextmanager
def compile_notices(show: bool):
    """Within: the processes the command starts (a sweep's workers) give no notice of their own, as before the
    library had one (``DRONEWPT_COMPILE_NOTICE=0`` in the environment); this one prints the notice above its
    progress bars when ``show`` (a terminal), else nothing (the same variable: the library's logged notice off).
    Afterwards the environment and the library's notice are as before."""
    before = os.environ.get(NOTICE_VAR)
    os.environ[NOTICE_VAR] = "0"
    restore = None
    if show:
        from wpt_receiver.notices import set_compile_sink
        restore = set_compile_sink(_above_bars)
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(NOTICE_VAR, None)
        else:
            os.environ[NOTICE_VAR] = before
        if restore is not None:
            restore()


@contextlib.contextmanager
def warning_lines(command: str):
    """Within: each distinct ``DronewptWarning`` printed once as ``dronewpt COMMAND: warning: MESSAGE`` on stderr
    (one line); any other warning as Python shows it. The user's warning filters (``-W``, ``PYTHONWARNINGS``,
    ``warnings.filterwarnings``) come first: ``-W ignore::RuntimeWarning`` silences it, ``-W error`` raises it
    (:func:`mission_sim.cli.main` then prints one line and exits 2)."""
    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if not is_dronewpt_warning(category):
            return shown(message, category, filename, lineno, file, line)
        say_warning(command, str(message))

    _seen.append(set())
    try:
        with warnings.catch_warnings():
            # Python's own default for a RuntimeWarning, appended after the user's filters: a no-op but for
            # resetting the registries of warnings already shown (an earlier main() here), so each shows again
            warnings.filterwarnings("default", category=RuntimeWarning, append=True)
            warnings.showwarning = show
            yield
    finally:
        _seen.pop()


#: the warnings printed by the commands running (:func:`warning_lines`), innermost last
_seen: list[set] = []


#: the library's words -> the flags the user typed, per command: (regular expression, replacement) applied in order
#: to each warning :func:`say_warning` prints and to some errors (``f_hz`` is ``--link f_hz`` where ``--link`` sets it; a mission's
#: warnings already say ``link.f_hz``, its ``--set`` key)
_LINK_F = (r"(?<![\w.-])f_hz\b", "--link f_hz")
FLAG_WORDS = {
    "paper": (_LINK_F, (r"t_end_s=", "--t-end "), (r"\(default 31e-3 s\)", "(--t-end, default 0.031 s)"),
              (r"model='switching'", "--model switching")),
    "netlist": (_LINK_F,),
    "export-controller": (_LINK_F,),
    "coupling": ((r"dz_m=", "--dz "), (r"hypot\(dx_m, dy_m\)", "hypot(--dx, --dy)")),
    "train": ((r"(?<![\w.-])history=", "--history "),),
}


def flag_words(command: str, text: str) -> str:
    """``text`` (a library warning) in ``dronewpt COMMAND``'s flag words (:data:`FLAG_WORDS`)."""
    import re
    for pattern, flag in FLAG_WORDS.get(command, ()):
        text = re.sub(pattern, flag, text)
    return text


def say_warning(command: str, text: str) -> None:
    """``dronewpt COMMAND: warning: TEXT`` on stderr (one line), the library's words in the command's flags
    (:func:`flag_words`), unless the command printed it already (e.g. a summary's ``warnings`` that the library also
    raised as a ``DronewptWarning``)."""
    text = flag_words(command, " ".join(str(text).split()))
    if _seen:
        if text in _seen[-1]:
            return
        _seen[-1].add(text)
    print(f"dronewpt {command}: warning: {text}", file=sys.stderr)
