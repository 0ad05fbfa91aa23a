"""SIGTERM handled like Ctrl-C: both raise :class:`Interrupted` (a ``KeyboardInterrupt``) in the main
thread, so every ``finally`` runs (temporary files removed, sweep rows stored, clusters closed) and
the CLI ends with one line and the conventional status 128 + signal number (130 for SIGINT, 143
for SIGTERM).

:func:`interrupts_raised` installs the handlers (``dronewpt``'s ``main`` does, for every command);
:func:`interrupts_deferred` holds a signal back over a section that must not be cut in the
middle (Dask's cluster start) and raises it on leaving. A signal that lands while Python runs a callback
whose exceptions it cannot raise (a weakref callback, ``__del__``) is kept and raised at the next safe
point (:func:`raise_lost`: before a file is renamed into place, when the command returns), not lost.
A process forked by the command (:func:`blocked_across_fork`) takes them only once inside its own code
(:func:`unblock_in_child`): one taken on its way there would raise the parent's interrupt up the
parent's stack in the child, which would then run the parent's code.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

__all__ = ["Interrupted", "interrupts_raised", "interrupts_deferred", "interrupts_requested", "raise_lost", "HANDLED", "exit_status", "signal_name",
           "blocked_across_fork", "unblock_in_child"]

#: the signals turned into :class:`Interrupted`
HANDLED = (signal.SIGINT, signal.SIGTERM)


class Interrupted(KeyboardInterrupt):
    """Raised by SIGINT or SIGTERM; ``signum`` says which."""

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signum)
        self.signum = int(signum)


def signal_name(exc: BaseException) -> str:
    """``SIGINT`` / ``SIGTERM`` for an interrupt (a plain ``KeyboardInterrupt`` is a Ctrl-C)."""
    return signal.Signals(getattr(exc, "signum", signal.SIGINT)).name


def exit_status(exc: BaseException) -> int:
    """128 + the signal number, the shell's convention: 130 for SIGINT, 143 for SIGTERM."""
    return 128 + int(getattr(exc, "signum", signal.SIGINT))


def _raise(signum, frame):
    raise Interrupted(signum)


#: signals whose :class:`Interrupted` Python could not raise (it landed while a weakref callback or a
#: ``__del__`` ran - e.g. import's module-lock callback - whose exceptions are only reported as
#: "Exception ignored in ..."): kept here and raised by :func:`raise_lost` at the next safe point
_LOST: list[int] = []


def _keep_lost(old_hook):
    """A ``sys.unraisablehook`` that keeps an unraisable :class:`Interrupted` in :data:`_LOST` (silently)
    and passes anything else to ``old_hook``."""
    def hook(unraisable):
        if isinstance(unraisable.exc_value, Interrupted):
            _LOST.append(unraisable.exc_value.signum)
        else:
            old_hook(unraisable)
    return hook


def raise_lost() -> None:
    """Raise the first interrupt Python could not raise where it landed (:data:`_LOST`), if any: called
    before a file is renamed into place (:func:`mission_sim.files.atomic_output`) and when a command
    returns, so a SIGTERM/Ctrl-C is never swallowed by a callback."""
    if _LOST:
        signum = _LOST[0]
        _LOST.clear()
        raise Interrupted(signum)


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def interrupts_raised():
    """While inside, SIGINT and SIGTERM raise :class:`Interrupted` (the previous handlers are restored
    on leaving). Outside the main thread (where handlers cannot be set) it does nothing."""
    if not _in_main_thread():
        yield
        return
    old = {s: signal.signal(s, _raise) for s in HANDLED}
    old_hook = sys.unraisablehook
    sys.unraisablehook = _keep_lost(old_hook)
    try:
        yield
    finally:
        sys.unraisablehook = old_hook
        for s, h in old.items():
            signal.signal(s, h)


@contextlib.contextmanager
def interrupts_deferred():
    """While inside, SIGINT and SIGTERM are recorded, not raised; on leaving (after the body has
    finished, e.g. assigned the cluster it started so that it can be closed) the first one is raised
    as :class:`Interrupted`. Python runs handlers in the main thread whichever thread took the
    signal, so none is lost. An ignored signal (``SIG_IGN``) is left alone."""
    if not _in_main_thread():
        yield
        return
    caught: list[int] = []
    # an ignored signal (SIGINT under nohup or a shell's background job) stays ignored, not raised on leaving
    held = [s for s in HANDLED if signal.getsignal(s) is not signal.SIG_IGN]
    old = {s: signal.signal(s, lambda signum, frame: caught.append(signum)) for s in held}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    if caught:
        raise Interrupted(caught[0])


@contextlib.contextmanager
def interrupts_requested(notice: str | None = None):
    """While inside, the first SIGINT or SIGTERM is a request, not an exception: its number is appended to the
    yielded list, which the body polls to stop at a point of its choosing (``dronewpt train`` stops its SB3 run
    at the next environment step and saves the model so far); a second one raises :class:`Interrupted` at once.
    A signal whose handler is the default or ignored (SIGTERM outside ``dronewpt``) is left alone; outside the main
    thread it does nothing. The previous handlers are restored on leaving; the caller raises the request.
    ``notice``: one line written to stderr on the first signal (``{signal}`` is replaced by its name), with
    ``os.write`` (no buffered stream entered again from inside a handler)."""
    caught: list[int] = []
    if not _in_main_thread():
        yield caught
        return

    def request(signum, frame):
        if caught:
            raise Interrupted(signum)
        caught.append(signum)
        if notice:
            try:
                os.write(2, (notice.replace("{signal}", signal.Signals(signum).name) + "\n").encode())
            except OSError:   # stderr closed: the request stands
                pass
    old = {s: signal.getsignal(s) for s in HANDLED}
    old = {s: h for s, h in old.items() if h not in (signal.SIG_DFL, signal.SIG_IGN, None)}
    for s in old:
        signal.signal(s, request)
    try:
        yield caught
    finally:
        for s, h in old.items():
            signal.signal(s, h)


@contextlib.contextmanager
def blocked_across_fork():
    """SIGINT and SIGTERM blocked in this thread while a child is forked inside (the mask restored on
    leaving): the child inherits the block and takes a signal sent to it (a ``terminate()`` right after
    the fork, a Ctrl-C to the process group) only when it calls :func:`unblock_in_child`, inside the
    ``try`` that ends it, never on its way there with the parent's handlers and stack. A signal sent to
    the parent meanwhile stays pending until the mask is restored. Where threads' signal masks cannot be
    set (not POSIX) it does nothing."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, HANDLED)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def unblock_in_child() -> None:
    """In a child forked inside :func:`blocked_across_fork`, once inside the ``try`` that ends it: take
    SIGINT and SIGTERM again (one sent meanwhile is taken now)."""
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, HANDLED)
