"""Sweep engine at scale, and sweep throughput on real missions.

``scale`` (default): a 100,000-case study with a trivial case runner (``y = 2 x``, ~1 us), so
what is measured is the engine itself. Every measurement runs in a fresh process (its peak RSS is
the driver's own; the Dask workers are other processes):

- cost per case: wall time / cases of the sweep (cluster already up) with 2 Dask workers and
  serially in-process, against the bare runner loop measured in the same run (the baseline);
- driver peak memory (``ru_maxrss``) of the 100,000-case run against a 1,000-case run;
- compaction at the end of the run (``SweepResult.compact_s``);
- resume when all is done (the same sweep again: store read, every case id checked, no cluster);
- crash and resume: a run killed with SIGKILL half way, then resumed: the time before the first
  case is submitted (cleanup, store read, skipping the stored cases), and the final compaction.

``throughput``: cases per second on the example study (real missions), serial and with 1 and 2
worker processes (speed-up against 1 worker).

    python benchmarks/bench_sweep.py [scale] [--cases 100000] [--small 1000] [--workers 2] [--repeat 3]
    python benchmarks/bench_sweep.py throughput [--study examples/study_small.toml] [--workers 1 2]

Medians with the range over ``--repeat`` runs, and the machine's 1-min load average (the CPU is
shared: other processes compete with the workers and the driver).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mission_sim.studies.study import case_space, parse_study  # noqa: E402
from mission_sim.studies.sweep import CaseStore, dask_client, run_sweep  # noqa: E402


class Trivial:
    """The trivial case runner (picklable by value from ``__main__``)."""

    def __call__(self, params: dict) -> dict:
        return {"y": 2.0 * params["x"], "k2": params["k"] * 2}


def bench_cases(n: int):
    """A grid of ``n`` cases (n/10 points of a linspace axis x 10 values of k)."""
    st = parse_study({"study": {"name": f"bench{n}"},
                      "grid": {"x": {"linspace": [0.0, 1.0, max(n // 10, 1)]}, "k": list(range(10))}})
    return case_space(st, "bench")


# ----------------------------------------------------------------------------- child processes
def child(mode: str, n: int, workers: int, out: str) -> dict:
    """One measurement in this (fresh) process; prints a JSON line."""
    cases = bench_cases(n)
    t_first = {}

    def factory():
        t_first.setdefault("t", time.perf_counter())  # the first pending case is known: cluster starts now
        return dask_client(None, workers)

    if mode == "loop":
        run, t0 = Trivial(), time.perf_counter()
        for c in cases:
            run(c.params)
        return {"wall_s": time.perf_counter() - t0, "n": n}
    t0 = time.perf_counter()
    if mode == "serial" or workers == 0:
        res = run_sweep(cases, Trivial(), out, progress=False)
        t_start = t0
    else:
        with dask_client(None, workers) if mode == "run" else contextlib.nullcontext() as client:
            t_start = time.perf_counter()
            res = run_sweep(cases, Trivial(), out, client=client, client_factory=None if client else factory,
                            progress=False)
    wall = time.perf_counter() - t_start
    return {"wall_s": wall, "n": n, "n_run": res.n_run, "n_skipped": res.n_skipped, "n_ok": res.n_ok,
            "compact_s": res.compact_s, "setup_s": t_first.get("t", time.perf_counter()) - t0,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def _spawn(mode: str, n: int, workers: int, out: str) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, __file__, "_child", mode, str(n), str(workers), out],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            start_new_session=True)


def measure(mode: str, n: int, workers: int, out: str) -> dict:
    proc = _spawn(mode, n, workers, out)
    stdout, stderr = proc.communicate(timeout=3600)
    if proc.returncode != 0:
        raise RuntimeError(f"{mode} {n}: exit {proc.returncode}: {stderr[-2000:]}")
    return {**json.loads(stdout.strip().splitlines()[-1]), "stderr": stderr.strip()}


def crash_half_way(n: int, workers: int, out: str) -> int:
    """Start a sweep of ``n`` cases, SIGKILL it (and its workers) once half are stored; rows stored."""
    proc = _spawn("run", n, workers, out)
    store = CaseStore(out)
    try:
        while proc.poll() is None:
            time.sleep(0.5)
            with contextlib.suppress(OSError):
                if store.state().n_done >= n // 2:
                    break
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    return store.state().n_done


# ----------------------------------------------------------------------------- scale
def scale_round(n: int, small: int, workers: int) -> dict:
    """One round of every measurement (fresh folders); returns the numbers."""
    r = {"load": [os.getloadavg()[0]]}
    with tempfile.TemporaryDirectory() as tmp:
        r["loop"] = measure("loop", n, workers, "")
        r["small"] = measure("run", small, workers, f"{tmp}/small")
        r["big"] = measure("run", n, workers, f"{tmp}/big")
        r["serial"] = measure("serial", n, 0, f"{tmp}/serial")
        r["done"] = measure("resume", n, workers, f"{tmp}/big")
        r["crash_rows"] = crash_half_way(n, workers, f"{tmp}/crash")
        r["files_after_crash"] = len(CaseStore(f"{tmp}/crash").files())
        r["resume"] = measure("resume", n, workers, f"{tmp}/crash")
        r["final_rows"] = CaseStore(f"{tmp}/crash").state().n_done
    r["load"].append(os.getloadavg()[0])
    assert r["big"]["n_ok"] == n and r["done"]["n_run"] == 0 and r["final_rows"] == n, r
    assert r["resume"]["n_skipped"] + r["resume"]["n_run"] == n, r
    return r


def _stat(values, fmt="{:.3g}") -> str:
    med = statistics.median(values)
    if len(values) == 1:
        return fmt.format(med)
    return f"{fmt.format(med)} ({fmt.format(min(values))} - {fmt.format(max(values))})"


def report_scale(rounds: list[dict], n: int, small: int, workers: int) -> None:
    def col(*path):
        out = []
        for r in rounds:
            v = r
            for p in path:
                v = v[p]
            out.append(v)
        return out

    us = lambda key: [1e6 * r[key]["wall_s"] / r[key]["n"] for r in rounds]  # noqa: E731
    loop = us("loop")
    print(f"sweep engine, trivial runner, {n:,} cases, {workers} Dask workers, {os.cpu_count()} CPUs, "
          f"{len(rounds)} rounds: median (min - max)")
    print(f"  bare runner loop (baseline)        {_stat(loop)} us/case")
    for key, label in (("serial", "serial engine (no Dask)"), ("big", f"Dask, {workers} workers")):
        ratio = [a / b for a, b in zip(us(key), loop)]
        print(f"  {label:<34} {_stat(us(key))} us/case = {_stat(ratio, '{:.0f}')}x the bare loop")
    mem = [b / s for b, s in zip(col("big", "peak_rss_mb"), col("small", "peak_rss_mb"))]
    print(f"  driver peak RSS, {small:,} cases       {_stat(col('small', 'peak_rss_mb'), '{:.0f}')} MB")
    print(f"  driver peak RSS, {n:,} cases     {_stat(col('big', 'peak_rss_mb'), '{:.0f}')} MB = "
          f"{_stat(mem, '{:.2f}')}x")
    print(f"  compaction at the end of the run   {_stat(col('big', 'compact_s'))} s")
    print(f"  resume when all done               {_stat(col('done', 'wall_s'))} s (no cluster started)")
    print(f"  crash half way (SIGKILL): stored {_stat(col('crash_rows'), '{:.0f}')} rows in "
          f"{_stat(col('files_after_crash'), '{:.0f}')} files")
    print(f"  resume after the crash: {_stat(col('resume', 'setup_s'))} s before the first case is submitted, "
          f"compaction {_stat(col('resume', 'compact_s'))} s, whole resume {_stat(col('resume', 'wall_s'))} s")
    loads = [x for r in rounds for x in r["load"]]
    print(f"  machine 1-min load average during the rounds: {min(loads):.1f} - {max(loads):.1f}")
    noisy = [r[k]["stderr"] for r in rounds for k in ("small", "big", "done", "resume") if r[k]["stderr"]]
    print(f"  stderr of the sweeps: {'empty' if not noisy else noisy[0][:500]}")


# ----------------------------------------------------------------------------- throughput
def throughput_run(study_path: Path, workers: int) -> dict:
    import policies
    from mission_sim.studies.study import load_study
    from mission_sim.studies.sweep import prepare_study

    runner, cases, _ = prepare_study(load_study(study_path), policies.make, policies.available())
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        with contextlib.nullcontext(None) if workers == 0 else dask_client(None, workers) as client:
            t_up = time.perf_counter() - t0
            res = run_sweep(cases, runner, tmp, client=client, progress=False)
            busy = float(res.results["case_wall_s"].sum()) / (max(workers, 1) * res.wall_s)
        wall = time.perf_counter() - t0
    return {"workers": workers, "cases": len(cases), "startup_s": t_up, "sweep_s": res.wall_s,
            "cases_per_s": res.cases_per_s, "end_to_end_s": wall, "busy": busy,
            "load": 0.5 * (load0 + os.getloadavg()[0])}


def report_throughput(rows: list[dict], study: Path) -> None:
    base = next((r["cases_per_s"] for r in rows if r["workers"] == 1), rows[0]["cases_per_s"])
    print(f"study {study.name}, {rows[0]['cases']} cases, {os.cpu_count()} CPUs")
    print(f"{'workers':>8} {'start-up':>9} {'sweep':>8} {'cases/s':>8} {'vs 1 worker':>12} {'end-to-end':>11} "
          f"{'workers busy':>13} {'load avg':>9}")
    for r in rows:
        label = "serial" if r["workers"] == 0 else str(r["workers"])
        print(f"{label:>8} {r['startup_s']:>7.2f} s {r['sweep_s']:>6.2f} s {r['cases_per_s']:>8.2f} "
              f"{r['cases_per_s'] / base:>11.2f}x {r['end_to_end_s']:>9.2f} s {100 * r['busy']:>11.0f} % "
              f"{r['load']:>9.1f}")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["_child"]:
        mode, n, workers, out = argv[1], int(argv[2]), int(argv[3]), argv[4]
        print(json.dumps(child(mode, n, workers, out)))
        return None
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", nargs="?", choices=("scale", "throughput"), default="scale")
    ap.add_argument("--cases", type=int, default=100_000)
    ap.add_argument("--small", type=int, default=1_000)
    ap.add_argument("--study", type=Path, default=ROOT / "examples" / "study_small.toml")
    ap.add_argument("--workers", type=int, nargs="+", default=None)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    if args.what == "throughput":
        rows = [max((throughput_run(args.study, w) for _ in range(args.repeat)), key=lambda r: r["cases_per_s"])
                for w in [0, *(args.workers or [1, 2])]]
        report_throughput(rows, args.study)
        return rows
    workers = (args.workers or [2])[0]
    rounds = [scale_round(args.cases, args.small, workers) for _ in range(args.repeat)]
    report_scale(rounds, args.cases, args.small, workers)
    return rounds


if __name__ == "__main__":
    main()
