"""The mission loop built ahead of time (mission_sim.world.aot): ``dronewpt mission`` on it gives the bits of
numba's JIT (summary and Parquet bytes) without importing numba, and every way the built module can be
missing, broken, stale or unbuildable falls back to the JIT with the same bits."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from mission_sim.world import aot

ROOT = Path(__file__).resolve().parents[1]

_RUN = r"""
import json, sys
from mission_sim.cli import main
status = main(["mission", "--no-plot", "--no-progress", "--format", "json", "--out", sys.argv[1]])
print(json.dumps({"status": status, "numba": "numba" in sys.modules}))
"""


def _mission(out: Path, cache: Path, mode: str) -> dict:
    """The default mission by the CLI in a fresh process (disk cache ``cache``, ``DRONEWPT_AOT=mode``): the
    summary without its wall-time keys, the Parquet bytes, whether numba was imported."""
    env = {**os.environ, "DRONEWPT_CACHE_DIR": str(cache), "DRONEWPT_AOT": mode,
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    env.pop("NUMBA_DISABLE_JIT", None)
    r = subprocess.run([sys.executable, "-c", _RUN, str(out)], env=env, cwd=ROOT, capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    lines = r.stdout.strip().splitlines()
    got = json.loads(lines[-1])
    summary = json.loads(lines[-2])
    summary = {k: v for k, v in summary.items() if k not in ("wall_s", "realtime_factor", "files")}
    return {"summary": summary, "parquet": (out / "timeseries.parquet").read_bytes(), "numba": got["numba"],
            "status": got["status"], "stderr": r.stderr}


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """A disk cache with the module built (a child process: ~30-110 s of CPU) and the JIT's reference run
    (which also fills the cache's tables and the Lm along the default path)."""
    cache = tmp_path_factory.mktemp("aot-cache")
    old = os.environ.get("DRONEWPT_CACHE_DIR")
    os.environ["DRONEWPT_CACHE_DIR"] = str(cache)
    try:
        path = aot.build(force=True)
        assert path is not None, aot.failed_note().read_text()
    finally:
        if old is None:
            os.environ.pop("DRONEWPT_CACHE_DIR", None)
        else:
            os.environ["DRONEWPT_CACHE_DIR"] = old
        aot._state.update(loaded=False, module=None)
    jit = _mission(tmp_path_factory.mktemp("jit"), cache, "0")
    assert jit["numba"] and jit["status"] == 0
    return cache, path, jit


def test_the_built_loop_gives_the_jits_bits_without_numba(built, tmp_path):
    cache, _, jit = built
    got = _mission(tmp_path / "aot", cache, "use")
    assert not got["numba"]                      # the whole command ran without importing numba
    assert got["summary"] == jit["summary"]      # every key, to the bit (JSON floats round-trip exactly)
    assert got["parquet"] == jit["parquet"]      # the time series, byte for byte
    assert got["summary"]["fine_steps"] > 1000


def test_a_broken_module_falls_back_to_the_jit_and_is_removed(built, tmp_path):
    """A truncated module (a full disk, a killed copy) is not loaded: the run uses the JIT, same bits, and the
    file is removed (warmup builds it again); a whole module under a name whose digest is not its own, as
    well."""
    cache, path, jit = built
    other = tmp_path / "cache"
    shutil.copytree(cache, other)
    broken = other / path.relative_to(cache)
    broken.write_bytes(path.read_bytes()[:4096])
    got = _mission(tmp_path / "out", other, "use")
    assert got["numba"] and got["summary"] == jit["summary"] and got["parquet"] == jit["parquet"]
    assert not broken.exists()
    suffix = aot.importlib.machinery.EXTENSION_SUFFIXES[0]
    wrong = broken.with_name(path.name[:path.name.index("-") + 1] + "0" * 16 + suffix)
    wrong.write_bytes(path.read_bytes())                   # the module's bytes, another digest in its name
    got = _mission(tmp_path / "out2", other, "use")
    assert got["numba"] and got["summary"] == jit["summary"] and got["parquet"] == jit["parquet"]
    assert not wrong.exists()


def test_stale_foreign_or_other_cpu_modules_are_not_loaded(built, tmp_path, monkeypatch):
    """Changed sources, versions or CPU mean another key, so another file: the old one is never loaded; a module
    built for another key but found under this key's name does not load either (its init function has another
    name)."""
    cache, path, _ = built
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("DRONEWPT_AOT", "use")
    monkeypatch.setattr(aot, "_state", {"enabled": False, "module": None, "loaded": False})
    assert aot.enable()
    assert not aot.covers("model_based")                   # nothing built in this cache
    (tmp_path / "aot").mkdir()
    target = tmp_path / "aot" / path.name
    shutil.copy(path, target)
    monkeypatch.setattr(aot, "_state", {"enabled": True, "module": None, "loaded": False})
    assert aot.covers("model_based")                       # the module of these sources loads
    key = aot.build_key()
    monkeypatch.setattr(aot, "cpu_id", lambda: b"another CPU")
    assert aot.build_key() != key                          # the CPU is in the key
    monkeypatch.setattr(aot, "_state", {"enabled": True, "module": None, "loaded": False})
    assert aot.find_module() is None and not aot.covers("model_based") and target.exists()
    monkeypatch.setattr(aot, "build_key", lambda: "0123456789abcde")   # as if a compiled source had changed
    monkeypatch.setattr(aot, "_state", {"enabled": True, "module": None, "loaded": False})
    assert not aot.covers("model_based")
    digest = path.name[path.name.index("-") + 1:][:16]
    foreign = aot.module_file("0123456789abcde", digest)
    shutil.copy(path, foreign)                             # another key's module under this key's name
    assert aot.find_module() == foreign                    # its bytes match its name ...
    monkeypatch.setattr(aot, "_state", {"enabled": True, "module": None, "loaded": False})
    assert not aot.covers("model_based") and aot.advance("model_based") is None   # ... but it does not load


def test_a_failed_build_leaves_a_note_and_missions_never_build(tmp_path, monkeypatch):
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(aot, "_state", {"enabled": False, "module": None, "loaded": False})
    monkeypatch.setenv("DRONEWPT_AOT", "auto")
    monkeypatch.setattr(aot, "_BUILD", "import sys; sys.exit('no C compiler here')")
    assert aot.enable()
    assert aot.build(force=True) is None
    assert "no C compiler here" in aot.failed_note().read_text() and aot.find_module() is None
    assert not hasattr(aot, "build_if_missing")            # the mission command has nothing to call
    from mission_sim.cli import mission
    assert "build(" not in Path(mission.__file__).read_text()


def test_a_successful_build_replaces_the_failed_note_and_other_versions(tmp_path, monkeypatch):
    """Without running the compiler: a fake build that writes a module file; the note and other keys' files go."""
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(aot, "_state", {"enabled": True, "module": None, "loaded": False})
    d = tmp_path / "aot"
    d.mkdir()
    suffix = aot.importlib.machinery.EXTENSION_SUFFIXES[0]
    old = d / f"dronewpt_mission_aot_fffffffffffffff-{'1' * 16}{suffix}"
    old.write_bytes(b"old")
    aot.failed_note().write_text("earlier failure\n")
    fake = ("import sys, pathlib; out, name = sys.argv[1], sys.argv[2]; "
            f"pathlib.Path(out, name + {suffix!r}).write_bytes(b'module bytes')")
    monkeypatch.setattr(aot, "_BUILD", fake)
    path = aot.build(force=True)
    assert path is not None and path.read_bytes() == b"module bytes"
    assert aot.find_module() == path and not old.exists() and not aot.failed_note().exists()
    assert aot.build(force=False) == path                  # a valid module: nothing to build


def test_what_turns_it_off(monkeypatch):
    monkeypatch.setattr(aot, "_state", {"enabled": False, "module": None, "loaded": False})
    cases = (([("DRONEWPT_AOT", "0")], False), ([("DRONEWPT_AOT", "use"), ("NUMBA_DISABLE_JIT", "1")], False),
             ([("DRONEWPT_AOT", "use"), ("NUMBA_DISABLE_JIT", "0")], True))
    for env, on in cases:
        for k, v in env:
            monkeypatch.setenv(k, v)
        assert aot.enable() is on and aot.enabled() is on
    assert not aot.covers("step") and aot.advance("hysteresis") is None    # no entry: the JIT runs them
    monkeypatch.setattr(aot, "_state", {"enabled": False, "module": None, "loaded": False})
    assert aot.advance("model_based") is None                              # a process that did not enable it


@pytest.mark.parametrize("name", ["step", "ramp", "model_based"])
def test_kernel_spec_is_the_kernel_hook_without_numba(name):
    import numpy as np

    import policies
    from mission_sim.contract import PolicyContext
    from policies.kernels import KERNELS
    pol = policies.make(name, PolicyContext())
    spec, hook = pol.kernel_spec(), pol.kernel()
    assert spec[0] == name and hook[0] is KERNELS[name]
    assert np.array_equal(spec[1], hook[1]) and np.array_equal(spec[2], hook[2])
    assert aot.policy_entry(pol) == (name if name in aot.ENTRIES else None)


def test_the_key_covers_every_source_compiled_in():
    """Every compiled function the loop and the entries' policy kernels call comes from a file in
    :func:`aot.sources` (a source left out would not invalidate a stale module)."""
    import numba.core.registry

    import mission_sim.world.loop_kernel as lk
    import policies.kernels as pk
    import wpt_receiver.modal_kernel as mk
    files = {p.resolve() for p in aot.sources()}
    for mod in (lk, pk, mk):
        for v in vars(mod).values():
            if isinstance(v, numba.core.registry.CPUDispatcher):
                assert Path(v.py_func.__code__.co_filename).resolve() in files, v
    for mod in (lk, mk, pk):
        assert Path(mod.__file__).resolve() in files
    assert Path(aot.__file__).resolve() in files and len(files) == len(aot.sources())
