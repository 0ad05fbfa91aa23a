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

* **Key.** The module's name carries :func:`build_key`: a hash of every source compiled in
  (:func:`sources`, this file included), numba's, llvmlite's and numpy's versions, the interpreter, the
  extension suffix and this machine's CPU (:func:`cpu_id`: the module is compiled for the host CPU like the
  JIT, so a cache copied to another machine must not load it: an unsupported instruction kills the process).
  A changed source means another name: the old file is never loaded (a successful build removes the other
  keys' modules). The module also returns the key from ``aot_key()``, checked on load.
* **One file, its digest in its name.** The module is ``<name>-<sha256[:16]>`` + the extension suffix,
  renamed into place in one step: concurrent builders and readers never see half a module or a module
  beside another build's digest. Before loading, the file's SHA-256 must match its name (a truncated or
  changed shared object can crash the process that loads it); a file that does not match is removed, so
  ``dronewpt warmup`` builds it again.
* **Fail safe.** A missing, broken, stale or unloadable module gives None here and the mission runs on
  numba's JIT as before, with identical results; a build that fails leaves a ``.failed`` note with its error.
* **Who builds, who uses it.** Only ``dronewpt warmup`` builds it (:func:`build`; a child process: numba,
  ``numba.pycc``, which needs setuptools, and a C compiler; 16 s after the loop's kernels are in numba's
  cache, 77-113 s when they had to be compiled, load ~5): a mission never waits for a build. Only a process
  that called :func:`enable` (``dronewpt mission``) loads it, and only for a policy with a
  :meth:`kernel_spec` named in :data:`ENTRIES` (:func:`.fastpath.run`); library calls of
  :func:`~.runner.run_mission`, sweeps and tests run on the JIT unless they enable it. ``$DRONEWPT_AOT=0``
  (or ``NUMBA_DISABLE_JIT=1``) turns it off.
* ``numba.pycc`` has been "pending deprecation" since numba 0.57 (still in 0.68): without it the build fails,
  leaves its note, and missions keep the JIT with the same bits.
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

__all__ = ["ENTRIES", "ENV_VAR", "enable", "enabled", "covers", "advance", "build", "build_key", "module_dir",
           "module_file", "find_module", "sources", "failed_note", "policy_entry", "cpu_id"]

#: the policies whose compiled kernel gets an entry ``advance_<name>`` (the default mission's policy; each entry
#: compiles the whole loop once more: ~30 s of CPU)
ENTRIES = ("model_based",)

#: ``0`` (or ``off``, ``no``, ``false``): never load the built module; anything else: load it when built
ENV_VAR = "DRONEWPT_AOT"

_ROOT = Path(__file__).resolve().parents[2]   # the folder holding mission_sim/, wpt_receiver/, policies/
_state = {"enabled": False, "module": None, "loaded": False}


def enable() -> bool:
    """Let this process run missions on the ahead-of-time build (unless ``$DRONEWPT_AOT=0`` or
    ``NUMBA_DISABLE_JIT`` is set); True if enabled."""
    _state["enabled"] = os.environ.get(ENV_VAR, "").strip().lower() not in ("0", "off", "no", "false") and os.environ.get("NUMBA_DISABLE_JIT", "0") in ("", "0")
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


def _version(package: str) -> bytes:
    """``package``'s installed version (without importing it), or its name: from its ``.dist-info`` folder's name
    when that is unambiguous (:func:`wpt_receiver.diskcache.installed_version`: one such folder in the first path
    entry with metadata for it, the same string as :mod:`importlib.metadata` gives), else from
    :mod:`importlib.metadata` as before, whose import alone (the email parser, zip and socket modules) took ~15 ms of
    every ``dronewpt mission``'s start-up, its three look-ups ~5 ms more."""
    from wpt_receiver.diskcache import installed_version
    found = installed_version(package)
    if found is not None:
        return f"{package}=={found}".encode()
    from importlib import metadata
    try:
        return f"{package}=={metadata.version(package)}".encode()
    except Exception:  # noqa: BLE001 - not installed as a distribution: still a key
        return package.encode()


def cpu_id() -> bytes:
    """What identifies this machine's CPU for compiled code: the first processor's model and feature flags
    from ``/proc/cpuinfo`` (Linux: ``model name``, ``flags``; ARM: ``CPU implementer``, ``CPU part``,
    ``Features``), else the platform's machine and processor names."""
    import platform
    keys = ("vendor_id", "model name", "flags", "cpu implementer", "cpu architecture", "cpu part", "features")
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            first = f.read().split("\n\n")[0]
        lines = sorted(ln.strip() for ln in first.splitlines() if ln.split(":")[0].strip().lower() in keys)
        if lines:
            return "\n".join(lines).encode()
    except OSError:
        pass
    return f"{platform.machine()}|{platform.processor()}".encode()


def build_key() -> str:
    """15 hex digits over :func:`sources`, the compiler's and numpy's versions, the interpreter, the platform
    and the CPU (:func:`cpu_id`)."""
    h = hashlib.sha256()
    for p in sources():
        h.update(p.name.encode())
        h.update(p.read_bytes())
    for part in (_version("numba"), _version("llvmlite"), _version("numpy"), sys.version.encode(),
                 importlib.machinery.EXTENSION_SUFFIXES[0].encode(), ",".join(ENTRIES).encode(), cpu_id()):
        h.update(part)
    return h.hexdigest()[:15]


def _name(key: str) -> str:
    return f"dronewpt_mission_aot_{key}"


def module_dir() -> Path | None:
    """The folder of the built modules (the disk cache's ``aot``); None when the disk cache is off."""
    from wpt_receiver.diskcache import cache_dir
    d = cache_dir()
    return None if d is None else d / "aot"


def _key() -> str | None:
    try:
        return build_key()
    except OSError:   # an install without its .py files: no key, so no module
        return None


def module_file(key: str, digest: str) -> Path | None:
    """The file of ``key``'s module whose SHA-256 starts with ``digest`` (16 hex digits)."""
    d = module_dir()
    return None if d is None else d / f"{_name(key)}-{digest[:16]}{importlib.machinery.EXTENSION_SUFFIXES[0]}"


def failed_note(key: str | None = None) -> Path | None:
    """The note a failed build of ``key`` (default: the current sources') leaves (its error)."""
    d, key = module_dir(), key or _key()
    return None if d is None or key is None else d / f"{_name(key)}.failed"


def find_module(key: str | None = None) -> Path | None:
    """The built module of ``key`` (default: the current sources') whose bytes match the digest in its name;
    files of that key that do not match are removed (a later build replaces them). None if there is none."""
    d, key = module_dir(), key or _key()
    if d is None or key is None or not d.is_dir():
        return None
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    for path in sorted(d.glob(f"{_name(key)}-*{suffix}")):
        digest = path.name[len(_name(key)) + 1:-len(suffix)]
        try:
            if len(digest) == 16 and hashlib.sha256(path.read_bytes()).hexdigest()[:16] == digest:
                return path
            path.unlink()   # truncated or changed since the build: never loaded, built again by warmup
        except OSError:
            continue
    return None


def _load():
    """The built module of the current sources, loaded once per process; None if absent or unusable."""
    if _state["loaded"]:
        return _state["module"]
    _state.update(loaded=True, module=None)   # not an earlier module if this load fails
    try:
        key = build_key()
        path = find_module(key)
        if path is None:
            return None
        spec = importlib.util.spec_from_file_location(_name(key), path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        if mod.aot_key() != int(key, 16):
            return None
    except Exception:  # noqa: BLE001 - unloadable (another platform, ...): numba's JIT instead
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
    the cache is off or the build failed (its error in :func:`failed_note`). ``force=False`` returns a valid
    existing module's path without building. A successful build removes the modules of other keys."""
    key = _key()
    d = module_dir()
    if key is None or d is None:
        return None
    if not force and (found := find_module(key)) is not None:
        return found
    note = failed_note(key)
    try:
        d.mkdir(parents=True, exist_ok=True)
        if importlib.util.find_spec("setuptools") is None:
            raise RuntimeError("numba.pycc needs setuptools, which is not installed (pip install setuptools)")
        with tempfile.TemporaryDirectory(dir=d, prefix=".build-") as tmp:
            env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(_ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
            env.pop("NUMBA_DISABLE_JIT", None)
            r = subprocess.run([sys.executable, "-c", _BUILD, tmp, _name(key), str(int(key, 16)), *ENTRIES],
                               cwd=tmp, env=env, capture_output=True, text=True, timeout=timeout_s)
            built = list(Path(tmp).glob(_name(key) + "*" + importlib.machinery.EXTENSION_SUFFIXES[0]))
            if r.returncode != 0 or len(built) != 1:
                raise RuntimeError(f"exit status {r.returncode}: {(r.stderr or r.stdout).strip()[-2000:]}")
            path = module_file(key, hashlib.sha256(built[0].read_bytes()).hexdigest())
            os.replace(built[0], path)   # one rename: the module and its digest (in its name) arrive together
        note.unlink(missing_ok=True)
    except (OSError, RuntimeError, subprocess.SubprocessError) as exc:
        try:
            note.write_text(f"{exc}\n")
        except OSError:
            pass
        return None
    for old in d.glob(_name("*")):   # other keys' modules and notes, and older builds of this key
        if old != path and old.is_file():
            old.unlink(missing_ok=True)
    _state["loaded"] = False   # a later covers() loads the new module
    return path
