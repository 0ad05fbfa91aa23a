"""Where the wall time of ``dronewpt mission`` (default mission, five figures) goes, process by process.

Runs the command in a fresh interpreter (``python -c`` calling ``mission_sim.cli.main``, the same code as the
console script) with timestamps added from outside (wrappers set before ``main`` runs; the code measured is
not changed): the parent's start-up, the figure worker's fork, its matplotlib import, the data's arrival,
each figure written (by the worker or its helper), the parent's run and exit. Each event is appended to a
file as ``process event seconds-since-launch cpu-seconds system-seconds minor-page-faults`` (the last three
of that process so far: ``getrusage``; a forked process starts from zero). ``--repeat N`` runs, the
median of each event's time printed, with the load.

    python benchmarks/timeline_mission.py [--repeat 5] [--root DIR] [-- extra mission args]

The bytecode cache is bench_startup.py's (``PYTHONPYCACHEPREFIX=/tmp/dronewpt-bench-pyc``, PYTHONDONTWRITEBYTECODE
dropped), the warm-up run fills it.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_startup import _bytecode_env  # noqa: E402 - the bytecode cache as a user's install has it

#: the measured processes' bytecode cache (as bench_startup.py's default: the trees' modules are not compiled
#: from source in every run where PYTHONDONTWRITEBYTECODE is set)
PYC = "/tmp/dronewpt-bench-pyc"

_CHILD = r"""
import os, sys, time
T0 = float(os.environ["TL_T0"]); LOG = os.environ["TL_LOG"]
def ev(who, what):
    import resource
    r = resource.getrusage(resource.RUSAGE_SELF)
    line = f"{who} {what} {time.time() - T0:.4f} {r.ru_utime + r.ru_stime:.4f} {r.ru_stime:.4f} {r.ru_minflt}\n"
    fd = os.open(LOG, os.O_WRONLY | os.O_APPEND | os.O_CREAT)
    os.write(fd, line.encode()); os.close(fd)
ev("parent", "interpreter")
import mission_sim.cli as cli
ev("parent", "cli-imported")
import mission_sim.figures.worker as W
if os.environ.get("TL_HELPER") in ("on", "off"):   # --helper: the figure helper forced on / off (inherited by the fork)
    W.core_free = (lambda: True) if os.environ["TL_HELPER"] == "on" else (lambda: False)
_init = W.FigureWorker.__init__
def init(self):
    _init(self)
    ev("parent", "worker-forked")
W.FigureWorker.__init__ = init
_draw_once = W._draw_once
def draw_once(conn):
    who = "worker"
    wpid = os.getpid()
    ev(who, "start")
    getattr(W, "matplotlib_without_docstrings", lambda: None)()   # as _draw_once does first (where it exists)
    from mission_sim.figures import mission as M
    ev(who, "matplotlib-imported")
    _recv = conn.recv
    def recv():
        r = _recv(); ev(who, "data-received"); return r
    conn.recv = recv
    for name in ("_plot_trajectory", "_plot_lm", "_plot_i2", "_plot_soc", "_plot_power"):
        f = getattr(M, name)
        def wrap(*a, _f=f, _n=name, **k):
            p = _f(*a, **k); ev("worker" if os.getpid() == wpid else "helper", "wrote" + _n[5:]); return p
        setattr(M, name, wrap)
    _draw_once(conn)
    ev(who, "done")
W._draw_once = draw_once
import mission_sim.cli.mission as CM   # (imported by mission_sim.cli already: nothing imported early)
_fs = CM._figures_and_summary
def fs(*a, **k):
    ev("parent", "simulated")   # and the Parquet file closed: the figures asked for next
    r = _fs(*a, **k); ev("parent", "summary-written"); return r
CM._figures_and_summary = fs
code = cli.main(sys.argv[1:])
ev("parent", "main-returned")
sys.exit(code)
"""


def _one(root: Path, extra, out: str, helper: str = "auto") -> list[tuple]:
    with tempfile.NamedTemporaryFile("r", suffix=".log", delete=False) as f:
        log = f.name
    env = _bytecode_env({**os.environ, "PYTHONPATH": str(root), "TL_LOG": log, "TL_HELPER": helper}, PYC)
    argv = [sys.executable, "-c", _CHILD, "mission", "--no-progress", "--out", out, *extra]
    env["TL_T0"] = repr(time.time())
    r = subprocess.run(argv, cwd=root, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    end = time.time() - float(env["TL_T0"])
    if r.returncode != 0:
        raise SystemExit(r.stderr.decode(errors="replace")[-600:])
    rows = [(w, e, float(t), float(c), float(s), int(f))
            for w, e, t, c, s, f in (line.split() for line in Path(log).read_text().splitlines())]
    os.unlink(log)
    return rows + [("launcher", "exited", end, 0.0, 0.0, 0)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--root", type=Path, default=ROOT)
    ap.add_argument("--helper", choices=("auto", "on", "off"), default="auto",
                    help="the figure helper as the worker decides (core_free), or forced on / off")
    ap.add_argument("extra", nargs="*")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        _one(a.root, a.extra, f"{tmp}/m", a.helper)   # warm-up, not counted
        load0 = os.getloadavg()[0]
        runs = [_one(a.root, a.extra, f"{tmp}/m", a.helper) for _ in range(a.repeat)]
        load1 = os.getloadavg()[0]
    keys = []
    for run in runs:
        for w, e, *_ in sorted(run, key=lambda row: row[2]):
            if (w, e) not in keys:
                keys.append((w, e))
    print(f"{a.root} (helper {a.helper}): n = {a.repeat}, load {load0:.2f} -> {load1:.2f}; seconds since launch (median [range]), "
          "CPU s of that process so far")
    for who, what in keys:
        got = [row[2:] for run in runs for row in run if row[:2] == (who, what)]
        ts, cs, ss, fs = (list(x) for x in zip(*got))
        print(f"  {who:9s} {what:22s} {statistics.median(ts):6.3f} [{min(ts):.3f}, {max(ts):.3f}]  cpu {statistics.median(cs):.3f}"
              f" (sys {statistics.median(ss):.3f}, minor faults {statistics.median(fs):,.0f})  (n={len(ts)})")


if __name__ == "__main__":
    main()
