"""Sweep of real default missions on 2 local Dask workers against a plain Python loop (issue 22).

``--cases`` default missions (the embedded default, one per ``seed``: its wind gusts differ) are run
``--repeat`` times each way, alternating, every measurement in a fresh process, after ``--warmup``
untimed rounds of both (numba's and the OS's caches warm):

* ``loop``: :class:`~mission_sim.studies.mission_cases.MissionCaseRunner` called in a plain ``for``
  loop (the same summary-only case as a sweep runs), after the runner's own warm-up case;
* ``sweep``: ``run_sweep`` into a fresh store on ``dask_client(None, --workers)`` (``sweep`` counts
  from the store's lock, the cluster already up: worker warm-up, every chunk and the end-of-run
  compaction included; ``end-to-end`` adds the cluster's start).

Besides cases/s (median [min, max] over the repeats, and the pairwise sweep / loop ratio) it
prints where the CPU goes, which is what a loaded machine does not distort: CPU per case of the
loop, of the workers (summed) and of the driver (the process that also hosts Dask's scheduler and
nannies), the driver's share of all the sweep's CPU, and the *CPU-bound ratio*
``workers x loop CPU / (workers' + driver CPU)``: what the sweep / loop ratio would be on an idle
machine with one core per worker, if CPU were all that limits it (measured under load it is
pessimistic: Dask's housekeeping costs CPU per second of wall time, and a loaded machine stretches
the wall time per case). Under load the cases/s ratio itself says little: with the kernel's
autogroup scheduling (``/proc/sys/kernel/sched_autogroup_enabled``) the benchmark's process tree
gets one share of the CPU however many processes it runs. Also the driver's peak RSS
(``ru_maxrss`` of the sweep process; the workers are other processes) and the 1-minute load
average before every measurement and at the end.

``--overhead`` measures the engine's per-task CPU instead (one case per task, a no-op runner):
what ``mission_sim.studies.sweep.TASK_OVERHEAD_S`` is set from.

    PYTHONPATH=$PWD python benchmarks/bench_sweep_missions.py [--cases 1000] [--workers 2] [--repeat 3]
    PYTHONPATH=$PWD python benchmarks/bench_sweep_missions.py --cases 100 --repeat 1   # a quick look
    PYTHONPATH=$PWD python benchmarks/bench_sweep_missions.py --overhead [--cases 1000]
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


def _cases(n: int):
    from mission_sim.studies.study import case_space, parse_study
    st = parse_study({"study": {"name": f"seeds{n}"}, "grid": {"seed": list(range(n))}})
    return case_space(st, "bench")


def _runner():
    import policies
    from mission_sim.config import config_to_dict, load_config
    from mission_sim.studies.mission_cases import MissionCaseRunner
    return MissionCaseRunner(config_to_dict(load_config()), policies.make, policies.available())


def _cpu_s(proc) -> float:
    t = proc.cpu_times()
    return t.user + t.system


def _loop(n: int) -> dict:
    cases, runner = _cases(n), _runner()
    runner.warm()
    c0, t0 = time.process_time(), time.perf_counter()
    for c in cases:
        runner(c.params)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"cases_per_s": n / wall, "wall_s": wall, "cpu_ms_per_case": 1e3 * cpu / n}


def _sweep(n: int, workers: int, overhead: bool) -> dict:
    import psutil

    from mission_sim.studies import sweep
    from mission_sim.studies.sweep import dask_client, run_sweep
    cases, runner = _cases(n), (dict if overhead else _runner())
    if overhead:
        sweep._MAX_CHUNK = 1  # one case per task: the engine's per-task cost alone
    me = psutil.Process()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        with dask_client(None, workers) as client:
            procs = [psutil.Process(pid) for pid in client.run(os.getpid).values()]
            w0, d0 = [_cpu_s(p) for p in procs], _cpu_s(me)
            res = run_sweep(cases, runner, tmp, client=client, progress=False)
            w1, d1 = [_cpu_s(p) for p in procs], _cpu_s(me)
        e2e = time.perf_counter() - t0
        task_cpu = float(res.results["case_cpu_s"].sum())
    wcpu, dcpu = sum(w1) - sum(w0), d1 - d0
    return {"cases_per_s": res.n_run / res.wall_s, "wall_s": res.wall_s, "e2e_cases_per_s": n / e2e,
            "n_ok": res.n_ok, "driver_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "workers_cpu_ms_per_case": 1e3 * wcpu / n, "driver_cpu_ms_per_case": 1e3 * dcpu / n,
            "task_cpu_ms_per_case": 1e3 * task_cpu / n,
            "driver_cpu_share": dcpu / (wcpu + dcpu), "driver_core_pct": 100 * dcpu / res.wall_s}


def child(mode: str, n: int, workers: int) -> dict:
    if mode == "loop":
        return _loop(n)
    return _sweep(n, workers, overhead=mode == "overhead")


def _measure(mode: str, n: int, workers: int) -> dict:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    r = subprocess.run([sys.executable, __file__, "_child", mode, str(n), str(workers)], capture_output=True,
                       text=True, env=env, timeout=7200)
    if r.returncode != 0:
        raise RuntimeError(f"{mode}: exit {r.returncode}: {r.stderr[-2000:]}")
    out = json.loads(r.stdout.strip().splitlines()[-1])
    out["load"] = os.getloadavg()[0]
    return out


def _fmt(vals, nd=1):
    return f"{statistics.median(vals):.{nd}f} [{min(vals):.{nd}f}, {max(vals):.{nd}f}]"


def _report(args, loops, sweeps, loads) -> None:
    lc, sc = [r["cases_per_s"] for r in loops], [r["cases_per_s"] for r in sweeps]
    ec = [r["e2e_cases_per_s"] for r in sweeps]
    lcpu = [r["cpu_ms_per_case"] for r in loops]
    wcpu, dcpu = [r["workers_cpu_ms_per_case"] for r in sweeps], [r["driver_cpu_ms_per_case"] for r in sweeps]
    bound = [args.workers * statistics.median(lcpu) / (w + d) for w, d in zip(wcpu, dcpu)]
    print(f"{args.cases} default missions (seeds 0..{args.cases - 1}), {args.workers} workers, {os.cpu_count()} CPUs, "
          f"{args.repeat} repeats after {args.warmup} warm-up round(s), all ok: "
          f"{all(r['n_ok'] == args.cases for r in sweeps)}")
    print(f"loop        {_fmt(lc)} cases/s")
    print(f"sweep       {_fmt(sc)} cases/s (cluster up; to the compacted store)  ratio "
          f"{statistics.median(sc) / statistics.median(lc):.2f}x  (pairwise {_fmt([s / x for s, x in zip(sc, lc)], 2)})")
    print(f"end-to-end  {_fmt(ec)} cases/s (cluster start-up and worker warm-up included)  ratio "
          f"{statistics.median(ec) / statistics.median(lc):.2f}x")
    print(f"CPU per case: loop {_fmt(lcpu)} ms; sweep workers {_fmt(wcpu)} ms, driver {_fmt(dcpu, 2)} ms "
          f"(driver share of the sweep's CPU {_fmt([100 * r['driver_cpu_share'] for r in sweeps])} %, "
          f"{_fmt([r['driver_core_pct'] for r in sweeps])} % of a core)")
    tcpu = [r["task_cpu_ms_per_case"] for r in sweeps]
    print(f"  of the workers' CPU: the cases themselves {_fmt(tcpu)} ms, the rest (worker warm-up, Dask's housekeeping, which grows "
          f"with wall time, and per-task work) {_fmt([w - t for w, t in zip(wcpu, tcpu)])} ms")
    print(f"CPU-bound ratio ({args.workers} cores, CPU all that limits): {_fmt(bound, 2)}x; with the cases' CPU "
          f"alone (no overhead at all): {_fmt([args.workers * statistics.median(lcpu) / t for t in tcpu], 2)}x")
    print(f"driver peak RSS {_fmt([r['driver_rss_mb'] for r in sweeps], 0)} MB")
    print(f"load average (1 min) before each measurement and at the end: {_fmt(loads, 2)} "
          f"({', '.join(f'{x:.1f}' for x in loads)}; {os.cpu_count()} cores)")


def _overhead(args) -> None:
    r = [_measure("overhead", args.cases, args.workers) for _ in range(args.repeat)]
    print(f"engine per-task CPU, {args.cases} one-case tasks of a no-op runner, {args.workers} workers: driver "
          f"{_fmt([x['driver_cpu_ms_per_case'] for x in r], 2)} ms, workers {_fmt([x['workers_cpu_ms_per_case'] for x in r], 2)} ms"
          f" per task; {_fmt([x['cases_per_s'] for x in r], 0)} tasks/s; load {_fmt([x['load'] for x in r], 2)}")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["_child"]:
        print(json.dumps(child(argv[1], int(argv[2]), int(argv[3]))))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=1000, help="missions per measurement (default 1000)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--warmup", type=int, default=1, help="untimed rounds of min(20, cases) missions each way")
    ap.add_argument("--overhead", action="store_true", help="the engine's per-task CPU (no-op runner)")
    args = ap.parse_args(argv)
    if args.overhead:
        _overhead(args)
        return
    for _ in range(args.warmup):
        _measure("loop", min(20, args.cases), args.workers)
        _measure("sweep", min(20, args.cases), args.workers)
    loads, loops, sweeps = [], [], []
    for _ in range(args.repeat):
        loads.append(os.getloadavg()[0])
        loops.append(_measure("loop", args.cases, args.workers))
        loads.append(os.getloadavg()[0])
        sweeps.append(_measure("sweep", args.cases, args.workers))
    loads.append(os.getloadavg()[0])
    _report(args, loops, sweeps, loads)


if __name__ == "__main__":
    main()
