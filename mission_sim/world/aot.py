"""The mission loop built ahead of time (``numba.pycc``): ``dronewpt mission`` without numba in the process.

numba's start-up (its import, runtime and the cached kernels' loads) is the largest fixed cost of a short
``dronewpt mission`` (docs/performance.md). This module compiles the one loop source,
:func:`.loop_kernel._advance`, with a shipped policy's compiled kernel bound in (:data:`ENTRIES`: AOT cannot
take the policy as a first-class function argument) into a CPython extension module in the disk cache
(:func:`wpt_receiver.diskcache.cache_dir` ``/aot``), which imports in ~1 ms with numpy alone. Nothing is
written twice: the build compiles the same functions numba's JIT compiles (the records and status codes of
:mod:`.loop_records`, the link layout of :mod:`wpt_receiver.modal_link`, the policy's kernel from
:mod:`policies.kernels`), for this machine's CPU like the JIT, and the results are the same to the bit
(``tests/test_mission_aot.py``).

* **Key.** The module's name (and file) carries :func:`build_key`: a hash of every source compiled in
  (:func:`sources`, this file included), numba's and llvmlite's version files, numpy's version, the
  interpreter and the extension suffix. A changed source means another name: the old file is never loaded
  (stale entries are left to the cache's owner; each is ~1 MB). The module also returns the key from
  ``aot_key()``, checked on load.
* **Fail safe.** A missing, changed or truncated (its SHA-256, written after it, checked before loading: a
  broken shared object can crash the process that loads it), unloadable or mismatched module gives None here and
  the mission runs on numba's JIT as before, with identical results; a build that fails leaves a
  ``.failed`` note with its error (no retry on every run; ``dronewpt warmup`` retries).
* **Who uses it.** Only a process that called :func:`enable` (``dronewpt mission``) and only for a policy
  with a :meth:`kernel_spec` named in :data:`ENTRIES` (:func:`.fastpath.run`); library calls of
  :func:`~.runner.run_mission`, sweeps and tests run on the JIT unless they enable it. ``$DRONEWPT_AOT``:
  ``0`` never, ``use`` load only (never build), anything else (the default) also builds after a
  ``dronewpt mission`` that missed it (once, said on stderr: 16 s after a first run that compiled the loop's
  kernels into numba's cache, 77-113 s when they had to be compiled again; load ~5); ``NUMBA_DISABLE_JIT=1`` never.
* **Build.** :func:`build` runs the compiler in a child process (numba, ``numba.pycc``, a C compiler) into
  a temporary folder beside the entry and renames the module into place: concurrent builders and readers
  never see half a file.
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import os
import subprocess
import sys
import tempfile
from pathlib import Path

__all__ = ["ENTRIES", "ENV_VAR", "enable", "enabled", "covers", "advance", "build", "build_key", "module_path",
           "sources", "failed_note", "digest_note", "build_if_missing", "policy_entry"]

#: the policies whose compiled kernel gets an entry ``advance_<name>`` (the default mission's policy; each entry
#: compiles the whole loop once more: ~30 s of CPU)
ENTRIES = ("model_based",)

#: ``0``: never; ``use``: load when built, never build; otherwise: load, and build after a mission that missed it
ENV_VAR = "DRONEWPT_AOT"

_ROOT = Path(__file__).resolve().parents[2]   # the folder holding mission_sim/, wpt_receiver/, policies/
_state = {"enabled": False, "module": None, "loaded": False}


def _mode() -> str:
    return os.environ.get(ENV_VAR, "auto").strip().lower() or "auto"


def enable() -> bool:
    """Let this process run missions on the ahead-of-time build (unless ``$DRONEWPT_AOT=0`` or
    ``NUMBA_DISABLE_JIT`` is set); True if enabled."""
    _state["enabled"] = _mode() not in ("0", "off", "no", "false") and os.environ.get("NUMBA_DISABLE_JIT", "0") in ("", "0")
    return _state["enabled"]


def enabled() -> bool:
    """True after :func:`enable` (and not switched off)."""
    return _state["enabled"]


def sources() -> list[Path]:
    """The source files compiled into the module (their bytes enter the key)."""
    w = Path(__file__).resolve().parent
    return [w / "aot.py", w / "loop_kernel.py", w / "loop_records.py", w.parent / "contract.py",
            _ROOT / "wpt_receiver" / "modal_kernel.py", _ROOT / "wpt_receiver" / "modal_link.py",
            _ROOT / "policies" / "kernels.py"]


def _version_file(package: str) -> bytes:
    """The bytes of ``package``'s ``_version.py`` (found without importing the package), or its name."""
    try:
        spec = importlib.util.find_spec(package)
        return Path(spec.origin).with_name("_version.py").read_bytes()
    except Exception:  # noqa: BLE001 - not installed or laid out otherwise: still a key
        return package.encode()


def build_key() -> str:
    """16 hex digits over :func:`sources`, the compiler's versions, numpy's, the interpreter and the platform."""
    import numpy as np
    h = hashlib.sha256()
    for p in sources():
        h.update(p.name.encode())
        h.update(p.read_bytes())
    for part in (_version_file("numba"), _version_file("llvmlite"), np.__version__.encode(), sys.version.encode(),
                 importlib.machinery.EXTENSION_SUFFIXES[0].encode(), ",".join(ENTRIES).encode()):
        h.update(part)
    return h.hexdigest()[:15]


def _name(key: str) -> str:
    return f"dronewpt_mission_aot_{key}"


def module_path(key: str | None = None) -> Path | None:
    """Where the module of ``key`` (default: the current sources') lives; None when the disk cache is off or
    the sources cannot be read (an install without its ``.py`` files: no key, so no module)."""
    from wpt_receiver.diskcache import cache_dir
    d = cache_dir()
    if d is None:
        return None
    if key is None:
        try:
            key = build_key()
        except OSError:
            return None
    return d / "aot" / (_name(key) + importlib.machinery.EXTENSION_SUFFIXES[0])


def failed_note(path: Path) -> Path:
    """The note a failed build leaves beside ``path`` (its error)."""
    return path.with_name(path.name.split(".")[0] + ".failed")


def digest_note(path: Path) -> Path:
    """The SHA-256 of the module at ``path``, written after it: checked before the module is loaded."""
    return path.with_name(path.name.split(".")[0] + ".sha256")


def _load():
    """The built module of the current sources, loaded once per process; None if absent or unusable."""
    if _state["loaded"]:
        return _state["module"]
    _state["loaded"] = True
    try:
        key = build_key()
        path = module_path(key)
        if path is None or not path.is_file():
            return None
        if hashlib.sha256(path.read_bytes()).hexdigest() != digest_note(path).read_text().strip():
            return None   # truncated or changed since the build (loading a broken shared object can crash)
        spec = importlib.util.spec_from_file_location(_name(key), path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        if mod.aot_key() != int(key, 16):
            return None
    except Exception:  # noqa: BLE001 - unloadable (truncated, another platform, ...): numba's JIT instead
        return None
    _state["module"] = mod
    return mod


def policy_entry(policy) -> str | None:
    """The name of ``policy``'s compiled kernel (its ``kernel_name()``, the name :meth:`kernel_spec` gives) if
    :data:`ENTRIES` has it, else None."""
    name = getattr(policy, "kernel_name", None)
    name = name() if callable(name) else None
    return name if name in ENTRIES else None


def covers(policy_name: str | None) -> bool:
    """True if this process runs ``policy_name`` on the built loop (enabled, an entry, the module loads)."""
    return enabled() and policy_name in ENTRIES and _load() is not None


def advance(policy_name: str):
    """The built loop for ``policy_name``'s kernel with :func:`.loop_kernel.advance`'s arguments (``fn``
    ignored: the kernel is bound in), or None (not enabled, no entry, not built, not loadable)."""
    if not covers(policy_name):
        return None
    entry = getattr(_state["module"], f"advance_{policy_name}", None)
    if entry is None:
        return None

    def run(k_stop, s, c, smp, rows, noise, obs, fn, params, pstate, lc, tab, lw):
        return entry(k_stop, s, c, smp, rows, noise, obs, params, pstate, lc, tab, lw)
    return run


_BUILD = r'''
import sys, warnings
warnings.simplefilter("ignore")
import llvmlite.binding as ll
from numba import njit, types
from numba.pycc import CC
from mission_sim.world import loop_kernel as lk
from policies.kernels import KERNELS
out, name, key = sys.argv[1], sys.argv[2], int(sys.argv[3])
cc = CC(name)
cc.output_dir = out
cc.target_cpu = ll.get_host_cpu_name()      # as numba's JIT compiles for this machine
g = {"adv": njit(lk._advance)}
for pol in sys.argv[4:]:
    g["kern_" + pol] = KERNELS[pol]
    exec(f"def advance_{pol}(k_stop, s, c, smp, rows, noise, obs, params, pstate, lc, tab, lw):\n"
         f"    return adv(k_stop, s, c, smp, rows, noise, obs, kern_{pol}, params, pstate, lc, tab, lw)\n", g)
    cc.export(f"advance_{pol}", types.int64(*lk._ARGS, lk._F8, lk._F8, *lk._LINK))(g[f"advance_{pol}"])
exec(f"def aot_key():\n    return {key}\n", g)
cc.export("aot_key", "int64()")(g["aot_key"])
cc.compile()
'''


def build(force: bool = True, timeout_s: float = 1800.0) -> Path | None:
    """Build the module of the current sources into the disk cache (a child process); its path, or None when
    the cache is off or the build failed (its error in :func:`failed_note`). ``force=False`` returns the
    existing module's path, or None after an earlier failure, without building."""
    try:
        key = build_key()
    except OSError:   # the sources are not there to compile: nothing to build
        return None
    path = module_path(key)
    if path is None:
        return None
    note = failed_note(path)
    if not force and (path.is_file() or note.is_file()):
        return path if path.is_file() else None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=path.parent, prefix=".build-") as tmp:
            env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(_ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
            env.pop("NUMBA_DISABLE_JIT", None)
            r = subprocess.run([sys.executable, "-c", _BUILD, tmp, _name(key), str(int(key, 16)), *ENTRIES],
                               cwd=tmp, env=env, capture_output=True, text=True, timeout=timeout_s)
            built = list(Path(tmp).glob(_name(key) + "*" + importlib.machinery.EXTENSION_SUFFIXES[0]))
            if r.returncode != 0 or len(built) != 1:
                raise RuntimeError(f"exit status {r.returncode}: {(r.stderr or r.stdout).strip()[-2000:]}")
            digest = hashlib.sha256(built[0].read_bytes()).hexdigest()
            os.replace(built[0], path)
            tmp_note = Path(tmp) / "digest"
            tmp_note.write_text(digest + "\n")
            os.replace(tmp_note, digest_note(path))
        note.unlink(missing_ok=True)
    except (OSError, RuntimeError, subprocess.SubprocessError) as exc:
        try:
            note.write_text(f"{exc}\n")
        except OSError:
            pass
        return None
    _state["loaded"] = False   # a later covers() loads the new module
    return path


def build_if_missing(policy_name: str, say=None) -> Path | None:
    """After a mission that ran ``policy_name`` on the JIT because the module was missing: build it once
    (not with ``$DRONEWPT_AOT=use``/``0``, not after an earlier failure, not when the cache is off); ``say``
    gets one line before the build. The path built, or None."""
    if not enabled() or _mode() == "use" or policy_name not in ENTRIES or _load() is not None:
        return None
    path = module_path()
    if path is None or failed_note(path).is_file():
        return None
    if say is not None:
        say("dronewpt mission: compiling the mission loop ahead of time once (~15-120 s; later runs start "
            "without numba; DRONEWPT_AOT=use skips this)")
    return build(force=False)
