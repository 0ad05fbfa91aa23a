"""Sweep of real default missions on 2 local Dask workers against a plain Python loop (issue 22).

``--cases`` default missions (the embedded default, one per ``seed``: its wind gusts differ) are run
``--repeat`` times each way, alternating, every measurement in a fresh process:

* ``loop``: :class:`~mission_sim.studies.mission_cases.MissionCaseRunner` called in a plain ``for``
  loop (the same summary-only case as a sweep runs), after one warm-up case;
* ``sweep``: ``run_sweep`` into a fresh store on ``dask_client(None, --workers)`` (cluster start-up,
  worker warm-up and the end-of-run compaction counted in ``end-to-end``; ``sweep`` counts from the
  first submitted case to the compacted store, the cluster already up).

Prints cases/s (median [min, max]), the sweep / loop ratio of the medians, the driver's peak RSS
(``ru_maxrss`` of the sweep process; the workers are other processes) and ``os.getloadavg()``.

    PYTHONPATH=$PWD python benchmarks/bench_sweep_missions.py [--cases 1000] [--workers 2] [--repeat 3]
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


def child(mode: str, n: int, workers: int) -> dict:
    cases = _cases(n)
    runner = _runner()
    if mode == "loop":
        runner.warm()
        t0 = time.perf_counter()
        for c in cases:
            runner(c.params)
        wall = time.perf_counter() - t0
        return {"cases_per_s": n / wall, "wall_s": wall}
    from mission_sim.studies.sweep import dask_client, run_sweep
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        with dask_client(None, workers) as client:
            res = run_sweep(cases, runner, tmp, client=client, progress=False)
        e2e = time.perf_counter() - t0
        ok = res.n_ok
    return {"cases_per_s": res.n_run / res.wall_s, "wall_s": res.wall_s, "e2e_cases_per_s": n / e2e, "n_ok": ok,
            "driver_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def _measure(mode: str, n: int, workers: int) -> dict:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    r = subprocess.run([sys.executable, __file__, "_child", mode, str(n), str(workers)], capture_output=True,
                       text=True, env=env, timeout=7200)
    if r.returncode != 0:
        raise RuntimeError(f"{mode}: exit {r.returncode}: {r.stderr[-2000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def _fmt(vals, nd=1):
    return f"{statistics.median(vals):.{nd}f} [{min(vals):.{nd}f}, {max(vals):.{nd}f}]"


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["_child"]:
        print(json.dumps(child(argv[1], int(argv[2]), int(argv[3]))))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    loads, loops, sweeps = [os.getloadavg()[0]], [], []
    for _ in range(args.repeat):
        loops.append(_measure("loop", args.cases, args.workers))
        sweeps.append(_measure("sweep", args.cases, args.workers))
        loads.append(os.getloadavg()[0])
    lc = [r["cases_per_s"] for r in loops]
    sc = [r["cases_per_s"] for r in sweeps]
    ec = [r["e2e_cases_per_s"] for r in sweeps]
    print(f"{args.cases} default missions (seeds 0..{args.cases - 1}), {args.workers} workers, {os.cpu_count()} CPUs, "
          f"{args.repeat} repeats, all ok: {all(r['n_ok'] == args.cases for r in sweeps)}")
    print(f"loop        {_fmt(lc)} cases/s")
    print(f"sweep       {_fmt(sc)} cases/s (cluster up; to the compacted store)  ratio {statistics.median(sc) / statistics.median(lc):.2f}x"
          f"  (pairwise {_fmt([s / x for s, x in zip(sc, lc)], 2)})")
    print(f"end-to-end  {_fmt(ec)} cases/s (cluster start-up and worker warm-up included)  ratio "
          f"{statistics.median(ec) / statistics.median(lc):.2f}x")
    print(f"driver peak RSS {_fmt([r['driver_rss_mb'] for r in sweeps], 0)} MB")
    print(f"load average (1 min) over the run: {_fmt(loads, 2)} (2 cores)")


if __name__ == "__main__":
    main()
