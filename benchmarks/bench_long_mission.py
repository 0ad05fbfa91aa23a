"""A long mission streamed (issue 22): peak RSS, wall time against the bare simulation, output size.

The default mission's pads repeated ``--repeats`` times (835x: ~50 h simulated; the config file's
100-pad limit is bypassed with ``dataclasses.replace``, so this runs the CLI's code path in-process:
``run_mission(frame=False, sink=SeriesWriter)``, the default ``--every`` of ``dronewpt mission``,
the figures read back thinned and ``summary.json``). Each run is a fresh subprocess so its peak RSS
(``ru_maxrss``) is its own; the two variants alternate, ``--repeat`` times each, after one warm-up
of the numba cache:

* ``bare``: the simulation alone (``run_mission(frame=False)``: summary on the fly, nothing stored);
* ``streamed``: as ``dronewpt mission`` (Parquet row groups, figures, summary.json).

Prints medians with ranges, the ratio streamed/bare, peak RSS, output bytes, ``os.getloadavg()``.

    PYTHONPATH=$PWD python benchmarks/bench_long_mission.py [--repeats 835] [--repeat 3] [--no-plot]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

_CHILD = r"""
import dataclasses, json, resource, sys, time
from pathlib import Path
t_import = time.perf_counter()
from mission_sim.config import load_config, policy_context
from mission_sim.world.budget import estimate_run
from mission_sim.world.runner import run_mission
from mission_sim.world.stream import SeriesWriter
from mission_sim.cli.mission import _figures_and_summary, stored_every_s
import policies
mode, n, out, plots = sys.argv[1], int(sys.argv[2]), Path(sys.argv[3]), sys.argv[4] == "1"
cfg = load_config()
cfg = dataclasses.replace(cfg, pads=cfg.pads * n)
pol = policies.make("model_based", policy_context(cfg))
t0 = time.perf_counter()
if mode == "bare":
    res = run_mission(cfg, pol, frame=False)
    files = []
else:
    w = SeriesWriter(out, every_s=stored_every_s(None, estimate_run(cfg)))
    res = run_mission(cfg, pol, frame=False, sink=w)
    files = [str(p) for p in w.close()] + _figures_and_summary(res, out, plots)
wall = time.perf_counter() - t0
s = res.summary
print(json.dumps({"wall_s": wall, "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "sim_s": s["sim_time_s"], "depleted": s["battery_depleted"], "min_soc": s["min_soc"],
                  "bytes": sum(Path(f).stat().st_size for f in files), "rows_stored": w.rows_written if mode != "bare" else 0}))
"""


def _run(mode, n, plots):
    with tempfile.TemporaryDirectory() as tmp:
        r = subprocess.run([sys.executable, "-c", _CHILD, mode, str(n), tmp, "1" if plots else "0"],
                           capture_output=True, text=True, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def _fmt(vals, unit, nd=1):
    return f"{statistics.median(vals):.{nd}f} {unit} [{min(vals):.{nd}f}, {max(vals):.{nd}f}]"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=835, help="times the default pads are repeated (835: ~50 h)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-plot", action="store_true")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()
    _run("bare", 1, False)  # warm-up (numba cache)
    res = {"bare": [], "streamed": []}
    for _ in range(args.repeat):
        for mode in res:
            res[mode].append(_run(mode, args.repeats, not args.no_plot))
    load1 = os.getloadavg()
    b, st = res["bare"], res["streamed"]
    print(f"default pads x {args.repeats}: {b[0]['sim_s'] / 3600:.1f} h simulated, depleted: {b[0]['depleted']}, "
          f"min SoC {b[0]['min_soc']:.3f}")
    for mode, rs in res.items():
        print(f"{mode:9s} wall {_fmt([r['wall_s'] for r in rs], 's')}  peak RSS {_fmt([r['rss_mb'] for r in rs], 'MB', 0)}"
              + (f"  output {st[0]['bytes'] / 1e6:.1f} MB ({st[0]['rows_stored']:,} rows stored)" if mode != "bare" else ""))
    ratios = [s["wall_s"] / x["wall_s"] for s, x in zip(st, b)]
    print(f"streamed / bare wall (pairwise): {_fmt(ratios, 'x', 2)}")
    print(f"load average before {load0[0]:.2f}, after {load1[0]:.2f} (2 cores)")


if __name__ == "__main__":
    main()
