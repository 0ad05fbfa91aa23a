"""numba's cache of a kernel that compiles in another module's function is dropped when that module
changes (wpt_receiver.kernel_cache; numba alone keys the cache on the caller's file and would load the
stale machine code). Checked on a two-module package in a temporary folder, in fresh processes."""

import os
import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("numba")

DEP = """
from numba import njit

@njit(cache=True)
def increment():
    return {value}
"""

CALLER = """
from numba import njit

import dep
from wpt_receiver.kernel_cache import drop_stale_cache


def _here():
    pass


if {guard}:
    drop_stale_cache(_here, (dep,))


@njit(cache=True)
def total(x):
    return x + dep.increment()
"""


@pytest.mark.parametrize("guard", [False, True], ids=["numba-alone", "drop_stale_cache"])
def test_a_changed_dependency_reaches_the_cached_caller(tmp_path, guard):
    from pathlib import Path

    import wpt_receiver
    root = Path(wpt_receiver.__file__).resolve().parents[1]
    sys_path0 = str(root)
    folder = tmp_path / "pkg"
    folder.mkdir()

    def run(value):
        (folder / "dep.py").write_text(textwrap.dedent(DEP.format(value=value)))
        # each version its own whole-second mtime: Python's .pyc keys on (int mtime, size), and "return 1" /
        # "return 2" have one size, so two writes within a second loaded the stale bytecode (a flaky 11 == 12)
        os.utime(folder / "dep.py", (1_700_000_000 + 10 * value,) * 2)
        (folder / "caller.py").write_text(textwrap.dedent(CALLER.format(guard=guard)))
        out = subprocess.run([sys.executable, "-c", "import caller; print(caller.total(10))"], cwd=folder,
                             capture_output=True, text=True, env={"PYTHONPATH": f"{folder}:{sys_path0}",
                                                                  "PATH": "/usr/bin:/bin"}, check=True)
        return int(out.stdout.strip())

    assert run(1) == 11
    assert list((folder / "__pycache__").glob("caller.*.nbi"))   # cached
    got = run(2)
    if guard:
        assert got == 12                                      # recompiled with the new dependency
        assert (folder / "__pycache__" / "caller.deps").exists()
        assert run(2) == 12                                   # and cached again (the stamp matches)
    else:
        assert got == 11                                      # numba's documented limitation: stale


def test_the_env_replays_stamp_covers_what_the_env_kernel_compiles_in(monkeypatch):
    """:mod:`envs.rollout`'s replay loop compiles in :mod:`envs.vector_kernel`'s step, and with it every envs module
    that kernel imports (``envs/duty_sine.py``'s sine is inlined there): its stamp lists them all, so a change to
    any of them drops the replay's cache (it once lacked ``duty_sine.py``)."""
    import ast
    from pathlib import Path

    import envs.rollout as rollout
    from wpt_receiver import kernel_cache

    src = Path(rollout.__file__).with_name("vector_kernel.py")
    needed = {src.name} | {f"{n.module}.py" for n in ast.walk(ast.parse(src.read_text()))
                           if isinstance(n, ast.ImportFrom) and n.level == 1}
    seen = []
    monkeypatch.setattr(kernel_cache, "drop_stale_cache", lambda here, deps: seen.extend(Path(d).name for d in deps))
    monkeypatch.setattr(rollout, "_CHECKED", [])
    rollout._drop_stale()
    assert needed <= set(seen), needed - set(seen)
