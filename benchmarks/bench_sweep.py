"""Sweep throughput (cases per second) on the example study with 1 and 2 Dask workers, same run.

Each configuration runs the whole study into a fresh folder: serial in this process (baseline, no
Dask), then a local cluster with 1 and with 2 single-threaded worker processes. Reported: cases/s
of the sweep itself (cluster already up) and the end-to-end wall time including cluster start-up,
and the speed-up against 1 worker. On a 2-core machine the ideal 2-worker speed-up is 2x; other
processes on the machine lower it, so the machine's load average is printed beside each run.

    python benchmarks/bench_sweep.py [--study examples/study_small.toml] [--workers 1 2] [--repeat 1]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import policies  # noqa: E402
from mission_sim.studies.study import load_study  # noqa: E402
from mission_sim.studies.sweep import dask_client, prepare_study, run_sweep  # noqa: E402


def run(study_path: Path, workers: int) -> dict:
    st = load_study(study_path)
    runner, cases, _ = prepare_study(st, policies.make, policies.available())
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        ctx = contextlib.nullcontext(None) if workers == 0 else dask_client(None, workers)
        with ctx as client:
            t_up = time.perf_counter() - t0
            res = run_sweep(cases, runner, tmp, client=client, progress=False)
        wall = time.perf_counter() - t0
    assert res.n_run == len(cases), res
    busy = float(res.results["case_wall_s"].sum()) / (max(workers, 1) * res.wall_s)
    return {"workers": workers, "cases": len(cases), "errors": res.n_error, "startup_s": t_up,
            "sweep_s": res.wall_s, "cases_per_s": res.cases_per_s, "end_to_end_s": wall, "busy": busy,
            "load": 0.5 * (load0 + os.getloadavg()[0])}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--study", type=Path, default=ROOT / "examples" / "study_small.toml")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeat", type=int, default=1, help="runs per configuration (best is reported)")
    ap.add_argument("--no-serial", action="store_true", help="skip the serial baseline")
    args = ap.parse_args(argv)
    configs = ([] if args.no_serial else [0]) + args.workers
    rows = []
    for w in configs:
        best = max((run(args.study, w) for _ in range(args.repeat)), key=lambda r: r["cases_per_s"])
        rows.append(best)
    base = next((r["cases_per_s"] for r in rows if r["workers"] == 1), rows[0]["cases_per_s"])
    print(f"study {args.study.name}, {rows[0]['cases']} cases, {os.cpu_count()} CPUs")
    print(f"{'workers':>8} {'start-up':>9} {'sweep':>8} {'cases/s':>8} {'vs 1 worker':>12} {'end-to-end':>11} "
          f"{'workers busy':>13} {'load avg':>9}")
    for r in rows:
        label = "serial" if r["workers"] == 0 else str(r["workers"])
        print(f"{label:>8} {r['startup_s']:>7.2f} s {r['sweep_s']:>6.2f} s {r['cases_per_s']:>8.2f} "
              f"{r['cases_per_s'] / base:>11.2f}x {r['end_to_end_s']:>9.2f} s {100 * r['busy']:>11.0f} % "
              f"{r['load']:>9.1f}")
    print("workers busy = sum of per-case run times / (workers x sweep time): engine overhead shows as < 100 %;"
          "\nload avg = 1-min load average of the machine during the run (other processes compete for the CPUs)")
    return rows


if __name__ == "__main__":
    main()
