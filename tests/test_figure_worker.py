"""``dronewpt mission``'s figures drawn by a forked process (mission_sim.figures.worker): the same PNG
bytes as drawn in process, errors reach the command as one line, nothing outlives the command, and
the command's own process imports neither matplotlib nor (with ``--no-plot``) multiprocessing."""

import errno
import multiprocessing
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mission_sim.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _children_of(pid: int) -> list[int]:
    """Live child processes of ``pid`` (Linux /proc)."""
    kids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            fields = stat.rsplit(")", 1)[1].split()
            if int(fields[1]) == pid and fields[0] != "Z":
                kids.append(int(d.name))
    return kids


_BEFORE: set[int] = set()


@pytest.fixture(autouse=True)
def _children_before():
    """This process's children before the test: another test file run earlier in the same process (pytest-xdist
    puts several on one worker) may have left multiprocessing's session-long forkserver and resource tracker
    (Dask's workers start them); those are not the command's."""
    _BEFORE.clear()
    _BEFORE.update(_children_of(os.getpid()))


def _left() -> list[int]:
    """Child processes of this test process started during the test and still alive."""
    return [k for k in _children_of(os.getpid()) if k not in _BEFORE]


@pytest.mark.parametrize("helper", [False, True])
def test_worker_draws_the_same_figures_as_in_process_and_leaves_no_process(tmp_path, monkeypatch, capsys, helper):
    """The real mission figures drawn by the forked worker (alone, or with its helper as on a machine with a
    free core) are the PNG bytes drawn in one process, and no process is left behind."""
    import mission_sim.cli.mission as cm
    from mission_sim.figures import worker as fw
    monkeypatch.setattr(fw, "core_free", lambda: helper)      # inherited by the forked worker
    assert main(["mission", "--out", str(tmp_path / "w"), "--no-progress"]) == 0
    assert multiprocessing.active_children() == [] and _left() == []
    monkeypatch.setattr(cm, "FIGURE_WORKER_MAX_ROWS", -1)        # drawn in this process
    assert main(["mission", "--out", str(tmp_path / "p"), "--no-progress"]) == 0
    pngs = sorted(p.name for p in (tmp_path / "w").glob("*.png"))
    assert pngs == ["i2_envelope.png", "lm.png", "power.png", "soc.png", "trajectory.png"]
    for name in pngs:
        assert (tmp_path / "w" / name).read_bytes() == (tmp_path / "p" / name).read_bytes(), name
    assert sorted(p.name for p in (tmp_path / "w").iterdir()) == sorted(p.name for p in (tmp_path / "p").iterdir())
    out = capsys.readouterr().out
    assert out.count("wrote: ") == 2 * 7


def test_a_worker_that_dies_is_replaced_by_drawing_in_process(tmp_path, monkeypatch, capsys):
    """The figure process killed (SIGKILL: out of memory, a user's kill) before it draws: the command still
    writes every figure, in-process, exit 0, no traceback and no process left."""
    import signal

    import mission_sim.figures.worker as fw
    real_init = fw.FigureWorker.__init__

    def killed(self):
        real_init(self)
        os.kill(self._proc.pid, signal.SIGKILL)
        self._proc.join()
    monkeypatch.setattr(fw.FigureWorker, "__init__", killed)
    out = tmp_path / "k"
    assert main(["mission", "--out", str(out), "--no-progress"]) == 0
    assert sorted(p.name for p in out.glob("*.png")) == ["i2_envelope.png", "lm.png", "power.png", "soc.png",
                                                         "trajectory.png"]
    assert (out / "summary.json").exists() and "Traceback" not in capsys.readouterr().err
    assert _left() == []


def test_a_full_disk_in_the_worker_is_one_line_naming_the_file(tmp_path, monkeypatch, capsys):
    """The worker's storage error comes back as the command's: exit 4, the PNG named, no temporary file,
    no summary.json (the set is incomplete)."""
    import mission_sim.figures.common as fc
    from mission_sim.files import OutputError
    real = fc.atomic_output

    def full(path, *a, **k):
        if str(path).endswith("soc.png"):
            raise OutputError(path, errno.ENOSPC, "no space left on device")
        return real(path, *a, **k)
    monkeypatch.setattr(fc, "atomic_output", full)               # inherited by the forked worker
    out = tmp_path / "m"
    assert main(["mission", "--out", str(out), "--no-progress"]) == 4
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"cannot write {str(out / 'soc.png')!r}: no space left on device" in err[0], err
    assert not (out / "summary.json").exists()
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []
    assert _left() == []


def _imported(code: str, names) -> list[str]:
    probe = f"{code}\nimport json, sys\nprint(json.dumps([m for m in {list(names)!r} if m in sys.modules]))"
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, cwd=ROOT,
                         timeout=300, check=True)
    return __import__("json").loads(out.stdout.strip().splitlines()[-1])


def test_mission_no_plot_imports_no_plotting_and_forks_nothing(tmp_path):
    code = ("import contextlib, io\nfrom mission_sim.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    main(['mission', '--out', {str(tmp_path / 'n')!r}, '--no-plot', '--no-progress'])")
    assert _imported(code, ("matplotlib", "mission_sim.figures.mission", "multiprocessing", "pandas",
                            "pyarrow.csv")) == []


def test_mission_with_figures_leaves_matplotlib_to_the_worker(tmp_path):
    """The command's process imports no matplotlib (the forked worker does, during the run); the five
    figures are written."""
    code = ("import contextlib, io\nfrom mission_sim.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    main(['mission', '--out', {str(tmp_path / 'm')!r}, '--no-progress'])")
    assert _imported(code, ("matplotlib", "pandas")) == []
    assert len(list((tmp_path / "m").glob("*.png"))) == 5


def test_sigterm_during_the_run_ends_the_worker_too(tmp_path):
    """A command terminated while it simulates: exit 143, one line, and its figure worker is gone with it
    (nothing outlives the command), no temporary file."""
    out = tmp_path / "m"
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    # a run of a few seconds that still takes the worker path (estimated rows under the worker's limit)
    proc = subprocess.Popen([sys.executable, "-m", "mission_sim.cli", "mission", "--out", str(out), "--no-progress",
                             "--set", "sim.traj_dt_s=0.01"], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    # the worker is forked first thing; the run streams its rows to a temporary Parquet file
    while not (out / ".mission.lock").exists() or not _children_of(proc.pid) or \
            not any(p.name.startswith(".timeseries.tmp") for p in out.iterdir()):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    kids = _children_of(proc.pid)
    proc.terminate()
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143 and err == "dronewpt mission: interrupted (SIGTERM)\n", err
    assert all(not Path(f"/proc/{k}").exists() or "Z" in Path(f"/proc/{k}/stat").read_text().rsplit(")", 1)[1][:3]
               for k in kids)
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []


def test_long_missions_draw_in_process(tmp_path, monkeypatch):
    """Above FIGURE_WORKER_MAX_ROWS the worker (forked first thing) is ended before the run, which then
    draws in process (a long run's memory is not held twice); nothing is asked of it, no process is left."""
    import mission_sim.cli.mission as cm
    import mission_sim.figures.worker as fw
    monkeypatch.setattr(cm, "FIGURE_WORKER_MAX_ROWS", 3000)     # the default mission: ~4,500 rows estimated
    events = []
    real_close = fw.FigureWorker.close
    monkeypatch.setattr(fw.FigureWorker, "draw", lambda self, *a: events.append("draw"))
    monkeypatch.setattr(fw.FigureWorker, "close", lambda self, **k: (events.append(("close", k)),
                                                                     real_close(self, **k))[-1])
    import mission_sim.world.runner as runner
    run_mission = runner.run_mission
    monkeypatch.setattr(runner, "run_mission", lambda *a, **k: (events.append("run"), run_mission(*a, **k))[-1])
    assert main(["mission", "--out", str(tmp_path / "m"), "--no-progress", "--format", "json"]) == 0
    assert events[:2] == [("close", {"wait_s": 0.0}), "run"] and "draw" not in events
    assert len(list((tmp_path / "m").glob("*.png"))) == 5 and _left() == []


def test_a_refused_out_folder_ends_the_figure_process(tmp_path, monkeypatch, capsys):
    """A second mission on an ``--out`` another one is writing is refused (exit 2, one line): the figure
    process, forked first thing, is ended at once (not waited for), nothing is drawn, no process is left."""
    import mission_sim.figures.worker as fw
    from mission_sim.cli.mission import MISSION_LOCK
    from mission_sim.files import folder_lock
    closed = []
    real_close = fw.FigureWorker.close
    monkeypatch.setattr(fw.FigureWorker, "draw", lambda self, *a: closed.append("draw"))
    monkeypatch.setattr(fw.FigureWorker, "close", lambda self, **k: (closed.append(k), real_close(self, **k))[-1])
    out = tmp_path / "busy"
    out.mkdir()
    with folder_lock(out, MISSION_LOCK, "busy"):
        assert main(["mission", "--out", str(out), "--no-progress"]) == 2
    assert closed == [{"wait_s": 0.0}] and _left() == []
    assert "another mission is writing there" in capsys.readouterr().err
    assert list(out.iterdir()) == []


_FORK_RACE = r"""
import os, sys
from mission_sim.figures.worker import FigureWorker
from mission_sim.signals import interrupts_raised
pid0, codes = os.getpid(), []
with interrupts_raised():            # the command's handlers: SIGTERM raises in the process that takes it
    for _ in range(int(sys.argv[1])):
        try:
            w = FigureWorker()
            w.close(wait_s=0.0)      # what a bad input does right after the fork: terminate at once
        except BaseException as exc:  # noqa: BLE001
            if os.getpid() != pid0:
                os._exit(3)          # a child that escaped the worker's code with the parent's stack
            raise
        if os.getpid() != pid0:
            os._exit(3)
        codes.append(w._proc.exitcode)
print(sorted(set(codes)))
"""


def test_a_worker_terminated_right_after_the_fork_never_runs_the_parents_code():
    """SIGTERM sent the instant after the fork (a bad input closes the worker with ``wait_s=0``) must end the
    child inside the worker's code: it is blocked across the fork and unblocked only inside ``_serve``. Before,
    a child that took it before reaching ``_serve``'s ``try`` raised the command's interrupt up the parent's
    stack: in a pytest-xdist worker that copy went on running the test session (a hang in CI)."""
    r = subprocess.run([sys.executable, "-c", _FORK_RACE, "60"], cwd=ROOT, capture_output=True, text=True, timeout=600,
                       env={**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])})
    assert r.returncode == 0, r.stderr[-2000:]
    codes = eval(r.stdout.strip().splitlines()[-1])   # noqa: S307 - our own printed list of ints
    assert 3 not in codes and set(codes) <= {0, -15}, codes


_DRAW_IN_PROCESS = r"""
import contextlib, io, json, sys
from mission_sim.figures.worker import matplotlib_without_docstrings
applied = matplotlib_without_docstrings() if sys.argv[2] == "lean" else None
import mission_sim.cli.mission as cm
from mission_sim.cli import main
cm.FIGURE_WORKER_MAX_ROWS = -1   # drawn in this process, the one whose matplotlib import was (not) lean
with contextlib.redirect_stdout(io.StringIO()):
    rc = main(["mission", "--out", sys.argv[1], "--no-progress"])
from matplotlib.lines import Line2D
print(json.dumps([rc, applied, "Properties:" in (Line2D.set.__doc__ or "")]))
"""


def test_matplotlib_without_docstrings_draws_the_same_bytes(tmp_path):
    """The figure worker's lean matplotlib import (no ``set()`` docstrings or signatures built for the artist
    classes) really skips them where it applies, and the five PNGs are the bytes of a process that imported
    matplotlib as usual. A matplotlib without its private hooks (a later release; CI takes the latest) gets the
    usual import: then the docstrings are built and the bytes must still agree."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    got = {}
    for mode in ("lean", "usual"):
        r = subprocess.run([sys.executable, "-c", _DRAW_IN_PROCESS, str(tmp_path / mode), mode], capture_output=True,
                           text=True, env=env, cwd=ROOT, timeout=600)
        assert r.returncode == 0, r.stderr[-2000:]
        got[mode] = __import__("json").loads(r.stdout.strip().splitlines()[-1])
    assert got["usual"] == [0, None, True]
    assert got["lean"] in ([0, True, False], [0, False, True])   # applied and skipped, or no hooks: as usual
    pngs = sorted(p.name for p in (tmp_path / "lean").glob("*.png"))
    assert len(pngs) == 5
    for name in pngs:
        assert (tmp_path / "lean" / name).read_bytes() == (tmp_path / "usual" / name).read_bytes(), name


def test_matplotlib_without_docstrings_is_a_no_op_once_artists_exist():
    """In a process whose matplotlib artists are defined already (a test process that drew before) nothing is
    patched: False, and ``kwdoc`` is matplotlib's own."""
    r = subprocess.run([sys.executable, "-c", "import matplotlib.lines, matplotlib.artist as a\n"
                        "from mission_sim.figures.worker import matplotlib_without_docstrings as m\n"
                        "k = a.kwdoc\nprint(m(), a.kwdoc is k)"], capture_output=True, text=True, cwd=ROOT, timeout=300,
                       env={**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")})
    assert r.returncode == 0 and r.stdout.split() == ["False", "True"], r.stderr[-2000:]


_AT_FORK = r"""
import contextlib, io, json, sys
import mission_sim.figures.worker as fw
from wpt_receiver.coupling import default_coupling
seen = []
real_init = fw.FigureWorker.__init__
def init(self):
    seen.append(["numpy" in sys.modules, "mission_sim.config" in sys.modules, default_coupling.cache_info().currsize,
                 "matplotlib" in sys.modules])
    real_init(self)
fw.FigureWorker.__init__ = init
from mission_sim.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    rc = main(["mission", "--out", sys.argv[1], "--no-progress"])
print(json.dumps([rc, seen]))
"""


def test_what_both_processes_need_is_loaded_once_before_the_fork(tmp_path):
    """numpy, the config module (unpickling the result needs it) and the coil model are loaded before the figure
    worker is forked, so the worker does not load them again; matplotlib is not (the worker's alone)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    r = subprocess.run([sys.executable, "-c", _AT_FORK, str(tmp_path / "m")], capture_output=True, text=True, env=env,
                       cwd=ROOT, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert __import__("json").loads(r.stdout.strip().splitlines()[-1]) == [0, [[True, True, 1, False]]]
    assert len(list((tmp_path / "m").glob("*.png"))) == 5


class _Conn:
    """A pipe end whose result is (not yet) waiting; the parent then ends (EOF) before sending anything."""

    def __init__(self, waiting: bool):
        self.waiting = waiting

    def poll(self, timeout=0.0):
        return self.waiting

    def recv(self):
        raise EOFError


@pytest.mark.parametrize("waiting", [False, True])
def test_the_worker_warms_up_only_while_it_waits_for_the_result(monkeypatch, waiting):
    """With a low load the worker draws its warm-up figure only when the result is not in its pipe yet: with the
    result there, the warm-up would only delay the figures."""
    from mission_sim.figures import mission
    from mission_sim.figures import worker as fw
    calls = []
    monkeypatch.setattr(fw, "matplotlib_without_docstrings", lambda: False)   # this test process's matplotlib as is
    monkeypatch.setattr(fw, "_load_low", lambda: True)
    monkeypatch.setattr(mission, "warm_up", lambda: calls.append("warm_up"))
    fw._draw_once(_Conn(waiting))
    assert calls == ([] if waiting else ["warm_up"])
