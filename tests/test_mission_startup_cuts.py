"""The start-up cuts of ``dronewpt mission`` (issue 22): numba's BLAS probe answered without importing the
``scipy.linalg`` package (:mod:`wpt_receiver.numba_start`), and the figure worker's forked helper
(:func:`mission_sim.figures.worker._draw_split`): every figure drawn once, in order, also when the
helper dies or fails."""

import json
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from mission_sim.figures import worker as fw

ROOT = Path(__file__).resolve().parents[1]


def _run(code: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT,
                         timeout=300, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_numba_finds_blas_without_the_scipy_linalg_package_and_dot_is_blas():
    """After prepare(): numba's registries load with BLAS available (np.dot compiles to the BLAS call,
    equal to numpy's product), the package scipy.linalg is not imported; importing it later gives the
    package with its cython_blas attribute (the same module) and working functions."""
    code = """
import json, sys
import numpy as np
from wpt_receiver.numba_start import prepare
first, again = prepare(), prepare()
from numba import njit
@njit
def dot(a, b):
    return np.dot(a, b)
rng = np.random.default_rng(3)
a, b = rng.random((40, 30)), rng.random((30, 20))
err = float(np.max(np.abs(dot(a, b) - a @ b)))
import numba.np.arraymath as am
before = "scipy.linalg" in sys.modules
import scipy.linalg
same = scipy.linalg.cython_blas is sys.modules["scipy.linalg.cython_blas"]
from scipy.linalg import cython_blas
e = float(scipy.linalg.expm(np.array([[0.0, 1.0], [-1.0, 0.0]]))[0, 1])
print(json.dumps([first, again, am._HAVE_BLAS, err, before, same, cython_blas is scipy.linalg.cython_blas, e]))
"""
    first, again, have_blas, err, before, same, same2, e = _run(code)
    assert first is True and again is False
    assert have_blas is True and err < 1e-12
    assert before is False and same and same2
    assert e == pytest.approx(np.sin(1.0), rel=1e-12)





def test_prepare_does_nothing_once_scipy_linalg_is_imported():
    assert _run("import json, scipy.linalg\nfrom wpt_receiver.numba_start import prepare\n"
                "print(json.dumps(prepare()))") is False


def _fake_mission(tmp_path, plot):
    names = ("trajectory", "lm", "i2", "soc", "power")
    return types.SimpleNamespace(FIGURES=names, plot_mission=plot), names


class _Conn:
    def close(self):
        pass


def _writer(tmp_path, log):
    parent = os.getpid()

    def plot(result, out, which=None):
        paths = []
        for n in which:
            p = Path(out) / f"{n}.txt"
            p.write_text(f"{n} {result}")
            paths.append(str(p))
            with open(log, "a") as f:
                f.write(f"{n} {'worker' if os.getpid() == parent else 'helper'}\n")
        return paths
    return plot


def test_split_draws_every_figure_once_in_order_half_in_the_helper(tmp_path):
    log = tmp_path / "log"
    mission, names = _fake_mission(tmp_path, _writer(tmp_path, log))
    files = fw._draw_split(mission, "R", tmp_path, _Conn())
    assert files == [str(tmp_path / f"{n}.txt") for n in names]
    who = dict(line.split() for line in log.read_text().splitlines())
    assert sorted(who) == sorted(names)   # each once
    assert {n for n, w in who.items() if w == "helper"} == set(fw.HELPER_FIGURES)
    assert all((tmp_path / f"{n}.txt").read_text() == f"{n} R" for n in names)


def test_a_helper_that_dies_is_replaced_by_the_worker(tmp_path):
    log = tmp_path / "log"
    parent = os.getpid()
    write = _writer(tmp_path, log)

    def plot(result, out, which=None):
        if os.getpid() != parent:
            os._exit(9)          # the helper killed before it answers
        return write(result, out, which)
    mission, names = _fake_mission(tmp_path, plot)
    files = fw._draw_split(mission, "R", tmp_path, _Conn())
    assert files == [str(tmp_path / f"{n}.txt") for n in names]
    assert sorted(line.split()[1] for line in log.read_text().splitlines()) == ["worker"] * len(names)


def test_an_error_in_the_helper_is_raised_by_the_worker(tmp_path):
    parent = os.getpid()
    write = _writer(tmp_path, tmp_path / "log")

    def plot(result, out, which=None):
        if os.getpid() != parent:
            raise OSError(28, "no space left on device", str(Path(out) / "soc.png"))
        return write(result, out, which)
    mission, _ = _fake_mission(tmp_path, plot)
    with pytest.raises(OSError, match="no space left"):
        fw._draw_split(mission, "R", tmp_path, _Conn())


def test_mission_command_line_ends_without_teardown_but_with_its_output_status_and_atexit(tmp_path):
    """``dronewpt mission`` from the command line ends with os._exit after the command (no module teardown),
    yet its piped output is complete, the atexit handlers ran, the status is the command's (3: a depleted
    battery) and every file is in place; a caller's main(argv) returns as before (the other tests)."""
    marker = tmp_path / "atexit_ran"
    out = tmp_path / "m"
    code = (f"import atexit, sys\natexit.register(lambda: open({str(marker)!r}, 'w').write('yes'))\n"
            f"sys.argv = ['dronewpt', 'mission', '--out', {str(out)!r}, '--no-plot', '--no-progress', "
            "'--set', 'battery.capacity_ah=0.01']\n"
            "import mission_sim.cli as cli\n"
            "real = cli._exit_now\n"
            "def spy(status):\n"
            "    print('quick exit', status, flush=True)\n"
            "    real(status)\n"
            "    print('not reached', flush=True)\n"
            "cli._exit_now = spy\n"
            "sys.exit(cli.console_main())")
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
    assert r.returncode == 3, r.stderr
    lines = r.stdout.splitlines()
    assert lines[-1] == "quick exit 3" and "not reached" not in r.stdout
    assert lines[-2] == f"wrote: {out / 'summary.json'}"
    assert marker.read_text() == "yes"
    assert json.loads((out / "summary.json").read_text())["battery_depleted"] is True
    assert "battery depleted" in r.stderr


def test_without_a_free_core_no_helper_is_forked(tmp_path, monkeypatch):
    log = tmp_path / "log"
    mission, names = _fake_mission(tmp_path, _writer(tmp_path, log))
    monkeypatch.setattr(os, "fork", lambda: pytest.fail("forked"))
    files = fw._draw_split(mission, "R", tmp_path, _Conn(), ())
    assert files == [str(tmp_path / f"{n}.txt") for n in names]
    assert [line.split()[1] for line in log.read_text().splitlines()] == ["worker"] * len(names)


def test_core_free_follows_the_load_average(monkeypatch):
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(os, "getloadavg", lambda: (1.2, 1.0, 1.0))
    assert fw.core_free() is True
    monkeypatch.setattr(os, "getloadavg", lambda: (1.6, 1.0, 1.0))
    assert fw.core_free() is False


def test_numba_start_survives_a_find_spec_probe_and_fails_safe_without_the_extension():
    """A ``find_spec('scipy.linalg')`` probe before the import leaves the hook in place (the package still gets
    its ``cython_blas``), and with the extension missing ``prepare`` does nothing (numba imports as before)."""
    code = ("import importlib.util, sys\nfrom wpt_receiver import numba_start\n"
            "assert numba_start.prepare()\nimportlib.util.find_spec('scipy.linalg')\n"
            "import scipy.linalg\nassert scipy.linalg.cython_blas is sys.modules['scipy.linalg.cython_blas']\n"
            "print('ok')\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert r.stdout.strip() == "ok", r.stderr
    code = ("import importlib.machinery, sys\nimportlib.machinery.EXTENSION_SUFFIXES[:] = ['.nonexistent']\n"
            "from wpt_receiver import numba_start\nassert numba_start.prepare() is False\n"
            "assert 'scipy.linalg.cython_blas' not in sys.modules\nprint('ok')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert r.stdout.strip() == "ok", r.stderr
