"""numba's start-up without the ``scipy.linalg`` package: its BLAS probe answered by the one module it asks for.

When numba loads its typing and lowering registries (the first compile or cache load of a process),
``numba.np.arraymath`` checks that a BLAS is available for ``np.dot`` (``numba.np.linalg.ensure_blas``):
it imports ``scipy.linalg.cython_blas``, and Python imports the parent package ``scipy.linalg`` first.
That package's ``__init__`` imports most of scipy.linalg, ``scipy._lib._array_api`` and its array-API
shim, which clones numpy's namespace and so imports ``numpy.f2py`` and ``numpy.testing``: about a third
of numba's start-up (0.3-0.35 s of CPU at load ~5, measured), for one extension module whose C function
pointers numba reads (its helper library imports the same module by name at run time).

:func:`prepare` loads that extension module alone, under its own name, so the probe finds it in
``sys.modules``; the numbers are the same (the same BLAS, found the same way: ``_HAVE_BLAS`` stays True).
A later ``import scipy.linalg`` in the same process runs the package's ``__init__`` as usual; a one-shot
import hook (:class:`_Attach`) then sets the package's ``cython_blas`` attribute to the loaded module, as
importing it after the package would have. Nothing happens when numba's registries are loaded already, when
``scipy.linalg`` (or the module) is imported already, or when the extension is not where scipy's
layout puts it (then numba imports it as before).

:func:`cache_loads_without_registries` goes further for a process that only *loads* compiled kernels from
numba's cache (``compare``, ``mission``, ``paper``, ``sizing``, ``replay``, the sweep workers' warm-up): numba's ``Cache.load_overload`` refreshes the target context before it reads an
entry, i.e. imports and installs every typing and lowering registry numba has (``numba.cpython.*``,
``numba.np.arraymath``, ``linalg``, ``random``, ``typed``, ...: ~0.3 s of CPU under load, much of
numba's start-up), although a cached entry is machine code that needs none of them, only numba's runtime
(NRT) linked in. With the hook a cache load initialises the runtime alone; anything that compiles (a cache
miss, a new signature) still refreshes both contexts first (numba's compiler does that itself), so what runs
is the same machine code either way (``tests/test_compare_startup.py``).
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import sys

__all__ = ["prepare", "cache_loads_without_registries", "BLAS_MODULE"]

#: the module numba's BLAS probe imports
BLAS_MODULE = "scipy.linalg.cython_blas"


def prepare() -> bool:
    """Load :data:`BLAS_MODULE` without its package (module notes) unless numba's registries or
    ``scipy.linalg`` are loaded already; True if it loaded it now. Idempotent, never raises."""
    if BLAS_MODULE in sys.modules or "scipy.linalg" in sys.modules or "numba.np.arraymath" in sys.modules:
        return False
    try:
        spec = importlib.util.find_spec("scipy")   # finds the package without importing it
        if spec is None or not spec.submodule_search_locations:
            return False
        folder = os.path.join(next(iter(spec.submodule_search_locations)), "linalg")
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = os.path.join(folder, "cython_blas" + suffix)
            if os.path.isfile(path):
                break
        else:
            return False
        mod_spec = importlib.util.spec_from_file_location(BLAS_MODULE, path)
        module = importlib.util.module_from_spec(mod_spec)
        sys.modules[BLAS_MODULE] = module
        try:
            mod_spec.loader.exec_module(module)
        except BaseException:
            sys.modules.pop(BLAS_MODULE, None)
            raise
    except Exception:  # noqa: BLE001 - any surprise: numba imports the package itself, as before
        return False
    sys.meta_path.insert(0, _Attach())
    return True


class _Attach:
    """Import hook: when ``scipy.linalg`` is imported, its module gets the attribute ``cython_blas`` (the
    module :func:`prepare` loaded) after its ``__init__`` ran; the hook removes itself when that import
    executes the package (a mere ``find_spec`` probe leaves it in place). It finds nothing itself: the real
    finders find and load the package."""

    def find_spec(self, name, path=None, target=None):
        if name != "scipy.linalg" or self not in sys.meta_path:
            return None
        at = sys.meta_path.index(self)
        sys.meta_path.remove(self)   # the real finders only, for the inner lookup
        try:
            spec = importlib.util.find_spec(name)
        finally:
            sys.meta_path.insert(at, self)
        if spec is not None and spec.loader is not None:
            spec.loader = _AttachLoader(spec.loader, self)
        return spec


class _AttachLoader:
    """``loader`` that sets ``module.cython_blas`` after executing the package (see :class:`_Attach`)."""

    def __init__(self, loader, hook):
        self._loader, self._hook = loader, hook

    def create_module(self, spec):
        return self._loader.create_module(spec)

    def exec_module(self, module):
        if self._hook in sys.meta_path:
            sys.meta_path.remove(self._hook)
        self._loader.exec_module(module)
        blas = sys.modules.get(BLAS_MODULE)
        if blas is not None and not hasattr(module, "cython_blas"):
            module.cython_blas = blas

    def __getattr__(self, name):   # get_filename, get_code, is_package, ... of the real loader
        return getattr(self._loader, name)


def cache_loads_without_registries() -> bool:
    """Make numba's cache loads skip the registries' refresh (module notes); True if installed now. Imports
    numba (call it where numba is used anyway). Installed only over numba's own ``Cache.load_overload`` of the
    known shape (a refresh, then ``_load_overload`` inside ``_guard_against_spurious_io_errors``): another
    numba version keeps its own. Idempotent, never raises."""
    try:
        from numba.core import caching

        load = caching.Cache.load_overload
        if getattr(load, "_dronewpt_lazy", False):
            return False
        names = set(getattr(getattr(load, "__code__", None), "co_names", ()))
        if not {"refresh", "_load_overload", "_guard_against_spurious_io_errors"} <= names:
            return False
    except Exception:  # noqa: BLE001 - numba missing or laid out otherwise: nothing to do
        return False

    def load_overload(self, sig, target_context):
        from numba.core.runtime import rtsys

        rtsys.initialize(target_context)   # what a cached entry needs of the refresh: numba's runtime (NRT)
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)

    load_overload._dronewpt_lazy = True
    load_overload.__doc__ = load.__doc__
    caching.Cache.load_overload = load_overload
    return True
