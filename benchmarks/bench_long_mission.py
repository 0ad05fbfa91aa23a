"""A long mission streamed (issue 22): peak RSS, wall time against the bare simulation, output size.

The default mission's pads repeated ``--repeats`` times (835x: ~50 h simulated). Each run is a fresh
process, so its figures are its own: peak RSS is the child's ``ru_maxrss`` from ``os.wait4`` (what
``/usr/bin/time -v`` reports as "Maximum resident set size"), CPU its user + system time. Two
variants alternate, ``--repeat`` times each, after one warm-up of each (numba cache, page cache):

* ``bare``: the same kernel over the same samples without output: ``run_mission(cfg, policy,
  frame=False)`` (the summary on the fly, nothing stored, no figures), in a process that imports
  only what that needs;
* ``cli``: ``dronewpt mission --out DIR --format json`` end to end (argument parsing, policy,
  run-size estimate, the default ``--every``, Parquet row groups, the five figures, summary.json)
  through ``mission_sim.cli.main``; the config file's 100-pad limit is bypassed by handing the CLI
  the repeated config (``mission_config`` patched), nothing else differs from the command.

Printed: per variant the process wall (end to end, interpreter start included) and the in-process
time of the run (``run_mission`` for bare; the command for cli), medians with [min, max]; the
ratio cli / bare of both (pairwise, run i against run i); peak RSS; output bytes and rows stored;
``os.getloadavg()`` before, after and the median of the per-run samples (2 shared cores: under
load wall times scatter, CPU times and RSS much less).

    PYTHONPATH=$PWD nice -n 10 python benchmarks/bench_long_mission.py [--repeats 835] [--repeat 3] [--no-plot]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_BARE = r"""
import dataclasses, json, sys, time
from mission_sim.config import load_config, policy_context
from mission_sim.world.runner import run_mission
import policies
cfg = load_config()
cfg = dataclasses.replace(cfg, pads=cfg.pads * int(sys.argv[1]))
pol = policies.make("model_based", policy_context(cfg))
t0 = time.perf_counter()
s = run_mission(cfg, pol, frame=False).summary
print(json.dumps({"run_s": time.perf_counter() - t0, "sim_s": s["sim_time_s"], "depleted": s["battery_depleted"],
                  "min_soc": s["min_soc"], "final_soc": s["final_soc"], "peak_i2_a": s["peak_i2_a"]}))
"""

_CLI = r"""
import dataclasses, io, json, sys, time, contextlib
from pathlib import Path
from mission_sim.config import load_config
import mission_sim.cli.mission as cm
from mission_sim.cli import main
n, out, plots = int(sys.argv[1]), sys.argv[2], sys.argv[3] == "1"
cfg = load_config()
cfg = dataclasses.replace(cfg, pads=cfg.pads * n)
cm.mission_config = lambda args: cfg          # the repeated pads (beyond the config file's 100-pad limit)
buf = io.StringIO()
t0 = time.perf_counter()
with contextlib.redirect_stdout(buf):
    rc = main(["mission", "--out", out, "--format", "json"] + ([] if plots else ["--no-plot"]))
run_s = time.perf_counter() - t0
s = json.loads(buf.getvalue().strip().splitlines()[-1])
files = [Path(f) for f in s["files"]]
import pyarrow.parquet as pq
rows = pq.ParquetFile(Path(out) / "timeseries.parquet").metadata.num_rows
print(json.dumps({"run_s": run_s, "rc": rc, "bytes": sum(f.stat().st_size for f in files),
                  "parquet_bytes": (Path(out) / "timeseries.parquet").stat().st_size, "rows_stored": rows,
                  "sim_s": s["sim_time_s"], "final_soc": s["final_soc"], "peak_i2_a": s["peak_i2_a"]}))
"""


def _child(code: str, args: list[str]) -> dict:
    """Run ``code`` in a fresh interpreter; its JSON line plus process wall, peak RSS and CPU
    (``os.wait4``: the child's own rusage, reaped here rather than by ``subprocess``)."""
    with tempfile.TemporaryFile("w+") as err:
        t0 = time.perf_counter()
        p = subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE, stderr=err, text=True)
        load = os.getloadavg()[0]
        out = p.stdout.read()
        _, status, ru = os.wait4(p.pid, 0)
        wall = time.perf_counter() - t0
        p.returncode = os.waitstatus_to_exitcode(status)
        p.stdout.close()
        if p.returncode != 0:
            err.seek(0)
            raise RuntimeError(f"child failed ({p.returncode}): {err.read()[-2000:]}")
    res = json.loads(out.strip().splitlines()[-1])
    res.update(wall_s=wall, load=load, rss_mb=ru.ru_maxrss / 1024, cpu_s=ru.ru_utime + ru.ru_stime)
    return res


def _run(mode: str, n: int, plots: bool) -> dict:
    if mode == "bare":
        return _child(_BARE, [str(n)])
    with tempfile.TemporaryDirectory() as tmp:
        return _child(_CLI, [str(n), str(Path(tmp) / "out"), "1" if plots else "0"])


def _fmt(vals, unit, nd=1):
    return f"{statistics.median(vals):.{nd}f} {unit} [{min(vals):.{nd}f}, {max(vals):.{nd}f}]"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=835, help="times the default pads are repeated (835: ~50 h)")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each variant (alternating)")
    ap.add_argument("--no-plot", action="store_true", help="the CLI without figures")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()
    _run("bare", 1, False), _run("cli", 1, not args.no_plot)   # warm-up: numba cache, page cache
    res = {"bare": [], "cli": []}
    for _ in range(args.repeat):
        for mode in res:
            res[mode].append(_run(mode, args.repeats, not args.no_plot))
    load1 = os.getloadavg()
    b, c = res["bare"], res["cli"]
    print(f"default pads x {args.repeats}: {b[0]['sim_s'] / 3600:.1f} h simulated, depleted: {b[0]['depleted']}, "
          f"min SoC {b[0]['min_soc']:.3f}; summaries equal (final SoC, peak I2): "
          f"{all(x['final_soc'] == y['final_soc'] and x['peak_i2_a'] == y['peak_i2_a'] for x, y in zip(b, c))}")
    for mode, rs in res.items():
        print(f"{mode:4s} process wall {_fmt([r['wall_s'] for r in rs], 's')}  in-process {_fmt([r['run_s'] for r in rs], 's')}"
              f"  CPU {_fmt([r['cpu_s'] for r in rs], 's')}  peak RSS {_fmt([r['rss_mb'] for r in rs], 'MB', 0)}")
    print(f"cli output {c[0]['bytes'] / 1e6:.1f} MB in all, timeseries.parquet {c[0]['parquet_bytes'] / 1e6:.1f} MB "
          f"({c[0]['rows_stored']:,} rows stored)")
    for key, label in (("wall_s", "process wall"), ("run_s", "in-process"), ("cpu_s", "CPU")):
        print(f"cli / bare {label} (pairwise): {_fmt([x[key] / y[key] for x, y in zip(c, b)], 'x', 2)}")
    print(f"load average before {load0[0]:.2f}, after {load1[0]:.2f}, at the runs' starts "
          f"{_fmt([r['load'] for r in b + c], '', 2)} (2 cores)")


if __name__ == "__main__":
    main()
