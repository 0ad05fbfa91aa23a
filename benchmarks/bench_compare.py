"""``dronewpt compare --episodes 100 --scenarios nominal --no-plot`` end to end (issue 22's goal: <= 2.5 s),
this tree against a peer tree in the same run, and where its time goes.

End to end: the ``dronewpt`` console script in a fresh process (default policies, the MPC and the
shipped seed rows included), this tree's command and the peer's (``--peer DIR``, e.g. ``git archive``
of an older commit unpacked into DIR) alternating, ``--repeat`` times each after one untimed warm-up
round each (numba's caches, the disk cache); median and range of the wall time and of the CPU time
(user + system of the command and of the processes it reaped: the forked MPC child included);
``os.getloadavg()`` before and after. Both trees' ``.py`` files are compiled to ``.pyc`` first
(``compileall``): with ``PYTHONDONTWRITEBYTECODE`` set, as on the machine this was written on, a tree
without ``__pycache__`` compiles its ~60 modules in every run. The printed tables of the two trees are
compared (they must be the same text).

Critical path (``--timeline N``): N runs of the same command, each a fresh interpreter calling ``main()`` (this
tree's, and the peer's alternating when ``--peer`` is given), the CPU time of the parent
before the fork (imports, numba's start-up), of the parent after it (its batched env), of the forked
child (the MPC and the share of the other runs ``policies.compare._split`` gives it) and the wall times of those
points: which process finished first and by how much, and (Linux) how long each waited for a CPU, runnable
(``/proc/self/schedstat``: on a shared machine the part of the wall time that is other processes' turn). On 2 free
cores the wall time is about ``before-fork + max(parent after, child) + tail``.

    python benchmarks/bench_compare.py [--repeat 5] [--peer DIR] [--timeline N] [--link modal|envelope] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from bench_startup import _console_script as _cli, _cpu_children   # the same script lookup and child CPU

ROOT = Path(__file__).resolve().parents[1]
ARGS = ["compare", "--episodes", "100", "--scenarios", "nominal", "--no-plot", "--no-progress"]
PACKAGES = ("wpt_receiver", "mission_sim", "envs", "policies")


def _run(tree: Path) -> tuple[float, float, str]:
    """(wall s, CPU s, stdout) of one command on ``tree`` in a fresh process."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    c0, t0 = _cpu_children(), time.perf_counter()
    r = subprocess.run([*_cli(), *ARGS], cwd=tree, env=env, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, _cpu_children() - c0
    if r.returncode != 0:
        raise SystemExit(f"{tree}: dronewpt compare failed ({r.returncode}): {r.stderr.strip()[-400:]}")
    return wall, cpu, r.stdout


def _stats(xs: list[float]) -> dict:
    return {"median": statistics.median(xs), "min": min(xs), "max": max(xs), "n": len(xs)}


def end_to_end(repeat: int, peer: Path | None) -> dict:
    trees = {"this tree": ROOT} | ({f"peer ({peer})": peer.resolve()} if peer is not None else {})
    for tree in trees.values():
        subprocess.run([sys.executable, "-m", "compileall", "-q", *[str(tree / p) for p in PACKAGES]],
                       check=True, stdout=subprocess.DEVNULL)
    res = {k: ([], []) for k in trees}
    text = {}
    for name, tree in trees.items():   # warm-up round (numba's cache, disk cache, .pyc)
        text[name] = _run(tree)[2]
    load0 = os.getloadavg()
    for _ in range(repeat):
        for name, tree in trees.items():
            w, c, _ = _run(tree)
            res[name][0].append(w)
            res[name][1].append(c)
    load1 = os.getloadavg()
    out = {"load_before": load0, "load_after": load1, "command": " ".join(["dronewpt", *ARGS]),
           "same_table": len(set(text.values())) == 1}
    for name, (w, c) in res.items():
        out[name] = {"wall_s": _stats(w), "cpu_s": _stats(c)}
    return out


_TIMELINE = r'''
import contextlib, io, json, os, resource, sys, tempfile, time
T0 = time.perf_counter()
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
def runq():   # seconds this process was runnable but waited for a CPU (Linux schedstat; None elsewhere)
    try:
        return int(open("/proc/self/schedstat").read().split()[1]) / 1e9
    except (OSError, IndexError, ValueError):
        return None
marks = {}
def mark(k):
    marks[k] = (time.perf_counter() - T0, cpu(), runq())
import policies.compare as pc
import policies.forked as pf
init, result, forked_runs = pf.Forked.__init__, pf.Forked.result, getattr(pc, "_forked_runs", None)
CHILD = tempfile.mktemp(suffix=".json")
def _init(self, *a, **k):
    mark("fork"); init(self, *a, **k)
def _result(self):
    mark("parent done, waits for the child"); r = result(self); mark("child's result received"); return r
def _forked_runs(*a, **k):   # in the child: its own start and end (perf_counter is the same clock in both)
    w0, c0, q0 = time.perf_counter() - T0, cpu(), runq()
    r = forked_runs(*a, **k)
    q = runq()
    with open(CHILD, "w") as f:
        json.dump({"start": w0, "end": time.perf_counter() - T0, "cpu": cpu() - c0,
                   "runq": None if q is None or q0 is None else q - q0}, f)
    return r
pf.Forked.__init__, pf.Forked.result = _init, _result
if forked_runs is not None:   # (a peer tree older than compare's _forked_runs: no child marks)
    pc._forked_runs = _forked_runs
from mission_sim.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    main(sys.argv[1:])   # with argv: returns (the command line's main() ends the process)
mark("end")
r = resource.getrusage(resource.RUSAGE_CHILDREN)
child = json.load(open(CHILD)) if os.path.exists(CHILD) else None
print(json.dumps({"marks": marks, "child_cpu_s": r.ru_utime + r.ru_stime, "child": child, "load": os.getloadavg()}))
'''


def timeline(tree: Path = ROOT) -> dict:
    """One in-process run on ``tree``: the wall and CPU times of the parent at the fork, when its own runs are
    done, when the child's result arrives and at the end; the child's CPU time."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    r = subprocess.run([sys.executable, "-c", _TIMELINE, *ARGS], cwd=tree, env=env, check=True, capture_output=True,
                       text=True)
    return {"tree": str(tree), **json.loads(r.stdout.splitlines()[-1])}


def _print(r: dict) -> None:
    e = r["end_to_end"]
    print(f"{e['command']}: end to end, fresh process; load average (1 min) before {e['load_before'][0]:.2f}, "
          f"after {e['load_after'][0]:.2f}; the same table from every tree: {e['same_table']}")
    for name, s in e.items():
        if isinstance(s, dict):
            w, c = s["wall_s"], s["cpu_s"]
            print(f"  {name:<40} wall median {w['median']:.2f} s ({w['min']:.2f}-{w['max']:.2f}, n={w['n']}); "
                  f"CPU {c['median']:.2f} s ({c['min']:.2f}-{c['max']:.2f})")
    for t in r.get("timeline", []):
        m = t["marks"]
        f_w, f_c = m["fork"][:2]
        d_w, d_c = m["parent done, waits for the child"][:2]
        got = m["child's result received"][0]
        who = "" if t.get("tree", str(ROOT)) == str(ROOT) else f" {t['tree']}"
        print(f"  in process{who} (load {t['load'][0]:.2f}): before the fork {f_c:.2f} s CPU ({f_w:.2f} s wall); parent after "
              f"it {d_c - f_c:.2f} s CPU (done at {d_w:.2f} s wall); child {t['child_cpu_s']:.2f} s CPU (result at "
              f"{got:.2f} s wall); end {m['end'][0]:.2f} s wall, {m['end'][1]:.2f} s CPU in the parent")
        c, q = t.get("child"), [v[2] for v in (m["fork"], m["parent done, waits for the child"])]
        if c is not None:   # who finished first, and the time each process waited for a CPU (the machine's share)
            print(f"    child's runs {c['start']:.2f}-{c['end']:.2f} s wall, {c['cpu']:.2f} s CPU; the "
                  f"{'parent' if c['end'] < d_w else 'child'} finished {abs(d_w - c['end']):.2f} s later"
                  + ("" if None in q or c["runq"] is None else
                     f"; waited for a CPU: parent {q[0]:.2f} s before the fork, {q[1] - q[0]:.2f} s after it, "
                     f"child {c['runq']:.2f} s"))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--peer", type=Path, default=None, help="another code tree run alternately (e.g. an older commit's "
                    "`git archive`)")
    ap.add_argument("--timeline", type=int, default=0, metavar="N", help="also N in-process runs of the critical path")
    ap.add_argument("--link", choices=("modal", "envelope"), default=None,
                    help="the command's --link (default: none given, the env's default link)")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    if a.link is not None:
        ARGS.extend(["--link", a.link])
    r = {"end_to_end": end_to_end(a.repeat, a.peer)}
    trees = [ROOT] + ([a.peer.resolve()] if a.peer is not None else [])
    r["timeline"] = [timeline(tree) for _ in range(a.timeline) for tree in trees]   # alternating with the peer
    if a.json:
        print(json.dumps(r, indent=1))
    else:
        _print(r)


if __name__ == "__main__":
    main()
