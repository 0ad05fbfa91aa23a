"""One line on stderr when numba starts compiling a kernel (the first run on a machine spends ~40 s
there, silently otherwise): "compiling kernels once (~40 s), cached afterwards".

numba is imported lazily (not by the CLI itself), so :func:`announce_compilation` waits for its
import with a ``sys.meta_path`` hook and then listens to numba's ``numba:compile`` event, which
numba fires only on a cache miss (a kernel loaded from its disk cache is silent). Shown only where
the progress bars are (a terminal, no ``--no-progress``).
"""

from __future__ import annotations

import importlib.util
import sys

__all__ = ["announce_compilation", "NOTICE"]

NOTICE = ("compiling numba kernels once (~40 s on 2 cores; cached afterwards, "
          "`dronewpt warmup` does it ahead) ...")

_state = {"registered": False, "announced": False}


def _listener_class():
    from numba.core import event

    class _Notice(event.Listener):
        def on_start(self, ev):
            if not _state["announced"]:
                _state["announced"] = True
                from tqdm import tqdm
                tqdm.write(f"dronewpt: {NOTICE}", file=sys.stderr)  # above an active progress bar

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


def announce_compilation() -> None:
    """From now on, print the notice (once per process) when numba compiles a kernel."""
    if "numba" in sys.modules:
        _register()
    elif not any(isinstance(f, _AfterNumbaImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterNumbaImport())
