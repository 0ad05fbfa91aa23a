"""Start-up: ``dronewpt --help`` and ``dronewpt mission`` (default mission, figures included) end to
end, each a fresh process, against the bare interpreter (``python -c pass``) in the same run.

Each command runs ``--repeat`` times, the three interleaved so load changes hit them alike;
median and range of the wall time (the goal's measure) and of the process's CPU time (user +
system, less sensitive to a shared machine), and ``os.getloadavg()`` before and after. The mission writes
to a temporary folder; the coupling table and coil inductances come from the disk cache (one
untimed warm-up run fills it, as any earlier run on the machine would have).

    python benchmarks/bench_startup.py [--repeat 7] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _cpu_children() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _wall(args, env, cpu: list | None = None) -> float:
    """Wall time of one run of ``python ARGS``; its CPU time (user + system) appended to ``cpu``."""
    c0, t0 = _cpu_children(), time.perf_counter()
    subprocess.run([sys.executable, *args], cwd=ROOT, env=env, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    if cpu is not None:
        cpu.append(_cpu_children() - c0)
    return wall


def run(repeat: int = 7) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    with tempfile.TemporaryDirectory() as tmp:
        cmds = {"python -c pass": ["-c", "pass"],
                "dronewpt --help": ["-m", "mission_sim.cli", "--help"],
                "dronewpt mission": ["-m", "mission_sim.cli", "mission", "--out", str(Path(tmp) / "m")]}
        _wall(cmds["dronewpt mission"], env)  # warm-up: disk caches (coupling table, .pyc)
        load0 = os.getloadavg()
        times = {k: [] for k in cmds}
        cpus = {k: [] for k in cmds}
        for _ in range(repeat):
            for name, args in cmds.items():
                times[name].append(_wall(args, env, cpus[name]))
        load1 = os.getloadavg()
    out = {"load_before": load0, "load_after": load1}
    for name, ts in times.items():
        c = cpus[name]
        out[name] = {"median_s": statistics.median(ts), "min_s": min(ts), "max_s": max(ts), "n": len(ts),
                     "cpu_median_s": statistics.median(c), "cpu_min_s": min(c), "cpu_max_s": max(c)}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    r = run(a.repeat)
    if a.json:
        print(json.dumps(r, indent=1))
        return
    print(f"load average before {r['load_before'][0]:.2f}, after {r['load_after'][0]:.2f} (1 min)")
    base = r["python -c pass"]["median_s"]
    for name, goal in (("python -c pass", ""), ("dronewpt --help", "goal <= 0.3 s"),
                       ("dronewpt mission", "goal <= 2.0 s")):
        s = r[name]
        print(f"{name:<17} median {s['median_s']:.3f} s (range {s['min_s']:.3f}-{s['max_s']:.3f}, n={s['n']}); "
              f"{s['median_s'] / base:.1f}x the bare interpreter; CPU {s['cpu_median_s']:.3f} s "
              f"(range {s['cpu_min_s']:.3f}-{s['cpu_max_s']:.3f})  {goal}")


if __name__ == "__main__":
    main()
