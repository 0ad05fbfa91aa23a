"""What dronewpt tells its user without being asked: the warning class of a run that goes on but may not be
what was meant, and the one notice when numba compiles a kernel (a first run spends ~40 s there, silently
otherwise). One source for the library and the ``dronewpt`` command line.

* :class:`DronewptWarning` (a ``RuntimeWarning``): raised with :func:`warnings.warn` at setup time (a mission's
  config, an env's link), never inside a loop. The command line prints each as one line
  ``dronewpt COMMAND: warning: ...`` on stderr (``mission_sim.cli``), once per distinct message.
* The compilation notice: numba fires its ``numba:compile`` event only on a cache miss (a kernel loaded from
  its disk cache is silent). numba is imported lazily, so :func:`listen_for_compilation` (called when
  ``wpt_receiver`` is imported) waits for numba's import with a ``sys.meta_path`` hook, then listens. The
  first compilation of one of dronewpt's kernels in a process is logged once, ``logging.getLogger("dronewpt")
  .warning(NOTICE)``: shown by Python's last-resort handler when nothing configured logging, and by a logging
  configuration that shows warnings (``logging.basicConfig()``: ``WARNING:dronewpt:compiling ...``). Silenced by
  ``logging.getLogger("dronewpt").setLevel(logging.ERROR)`` or ``DRONEWPT_COMPILE_NOTICE=0`` (read when the notice
  would fire). The command line replaces that sink while a command runs (:func:`set_compile_sink`): a line above
  its progress bars on a terminal, nothing otherwise; the processes it starts (a sweep's workers) stay silent.
"""

from __future__ import annotations

import importlib.util
import os
import sys

__all__ = ["DronewptWarning", "warn", "NOTICE", "NOTICE_VAR", "LOGGER_NAME", "OUR_PACKAGES", "listen_for_compilation",
           "set_compile_sink"]

NOTICE = ("compiling numba kernels once (~40 s on 2 cores; cached afterwards, "
          "`dronewpt warmup` does it ahead) ...")

#: the logger of the library's notices
LOGGER_NAME = "dronewpt"

#: the packages whose kernels the library's notice is about (a user's own ``@njit`` compiles silently)
OUR_PACKAGES = ("wpt_receiver", "mission_sim", "envs", "policies")


class DronewptWarning(RuntimeWarning):
    """A run that goes on but may not give what its user meant (a link outside the range where its model was
    checked, a pad the route never comes near, ...): one line naming the value, the range and what to do."""


#: the folders of :data:`OUR_PACKAGES` (a warning points at the first frame outside them: the user's call)
_OUR_DIRS = tuple(os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), p) + os.sep
                  for p in OUR_PACKAGES)

#: the libraries whose frames also lie between the user's call and ours (``gymnasium.make`` / ``make_vec`` -> env;
#: stable-baselines3's ``make_vec_env`` and the like): skipped too, by module name (nothing imported for it)
PASSED_THROUGH = ("gymnasium", "stable_baselines3")


def _passed(frame) -> bool:
    return (frame.f_code.co_filename.startswith(_OUR_DIRS)
            or str(frame.f_globals.get("__name__", "")).partition(".")[0] in PASSED_THROUGH)


def warn(text: str) -> None:
    """``warnings.warn(text, DronewptWarning)`` pointed at the first caller outside dronewpt's packages and the
    libraries that call into them (:data:`PASSED_THROUGH`; Python 3.12's ``skip_file_prefixes``, by hand: the
    depth of those frames varies, e.g. ``gymnasium.make`` -> env -> plant part)."""
    import warnings
    level, frame = 2, sys._getframe(1)
    while frame is not None and _passed(frame):
        frame, level = frame.f_back, level + 1
    warnings.warn(text, DronewptWarning, stacklevel=level)


def _log_notice(text: str) -> None:
    import logging   # (imported here: ~2 ms that a run loading every kernel from the cache does not need)
    logging.getLogger(LOGGER_NAME).warning(text)


#: ``DRONEWPT_COMPILE_NOTICE=0``: no notice from the library (read when it would fire; the command line sets it while
#: a command runs, for the processes it starts, e.g. a sweep's workers, which stayed silent before the notice)
NOTICE_VAR = "DRONEWPT_COMPILE_NOTICE"

#: ``sink``: called once with :data:`NOTICE`; ``ours_only``: only a kernel of :data:`OUR_PACKAGES` counts
_state = {"registered": False, "announced": False, "ours_only": True, "sink": _log_notice}


def set_compile_sink(sink, ours_only: bool = False):
    """From now on the notice goes to ``sink(NOTICE)`` (None: nowhere), at the first compilation of any kernel
    (``ours_only`` False, the command line's: it runs only dronewpt's) or of one of dronewpt's; listens if it
    did not yet. Returns a function that puts the previous sink back."""
    before = _state["sink"], _state["ours_only"]
    _state["sink"], _state["ours_only"] = sink, ours_only
    listen_for_compilation()

    def restore() -> None:
        _state["sink"], _state["ours_only"] = before
    return restore


def _fire() -> None:
    """The notice, once per process, to the sink; the library's own (logged) one unless ``DRONEWPT_COMPILE_NOTICE=0``
    now (read here, not at import: a user may set it after importing dronewpt)."""
    _state["announced"] = True
    sink = _state["sink"]
    if sink is None or (sink is _log_notice and os.environ.get(NOTICE_VAR) == "0"):
        return
    sink(NOTICE)


def _ours(ev) -> bool:
    func = getattr((getattr(ev, "data", None) or {}).get("dispatcher"), "py_func", None)
    return str(getattr(func, "__module__", "") or "").partition(".")[0] in OUR_PACKAGES


def _listener_class():
    from numba.core import event

    class _Notice(event.Listener):
        def on_start(self, ev):
            if _state["announced"] or (_state["ours_only"] and not _ours(ev)):
                return
            _fire()

        def on_end(self, ev):
            pass

    return _Notice


def _register() -> None:
    if _state["registered"]:
        return
    from numba.core import event
    event.register("numba:compile", _listener_class()())
    _state["registered"] = True


class _AfterNumbaImport:
    """Meta-path finder: lets numba import as usual, then registers the listener and leaves
    ``sys.meta_path``. (A mere ``importlib.util.find_spec("numba")``, which asks the finders without
    importing, leaves it in place.)"""

    busy = False

    def find_spec(self, name, path=None, target=None):
        if name != "numba" or self.busy:
            return None
        self.busy = True
        try:
            spec = importlib.util.find_spec("numba")  # the finders after this one
        finally:
            self.busy = False
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        exec_module = spec.loader.exec_module

        def exec_then_register(module):
            exec_module(module)
            _register()
            if self in sys.meta_path:
                sys.meta_path.remove(self)
        spec.loader.exec_module = exec_then_register
        return spec


def listen_for_compilation() -> None:
    """From now on, give the notice (once per process) when numba compiles a kernel (module docstring)."""
    if "numba" in sys.modules:
        _register()
    elif not any(isinstance(f, _AfterNumbaImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterNumbaImport())
