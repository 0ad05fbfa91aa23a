"""``dronewpt tolerance`` at scale: 10,000 draws on the sweep engine, 2 local Dask workers, end to end.

Runs the CLI in a subprocess (cluster start-up, numba cache load on the workers, the store and
the summary included) into a fresh folder, ``--repeat`` times, and prints the wall times (median
and range) with ``os.getloadavg()`` before and after (the machine is shared: the target is 10^4
draws in under 2 minutes on 2 cores), plus the in-process serial time per draw for comparison.

    python benchmarks/bench_tolerance.py [--draws 10000] [--workers 2] [--repeat 3] [--json]
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


def _serial_per_draw(n: int = 500) -> float:
    from wpt_receiver import tolerance as tol
    ts = tol.TransitionSet.build()
    rows = tol.draw_scales(tol.Spreads(), n, 99)
    tol.draw_metrics(*tol.draw_link(rows[0]), ts)   # numba cache load
    t0 = time.perf_counter()
    for s in rows:
        tol.draw_metrics(*tol.draw_link(s), ts)
    return (time.perf_counter() - t0) / n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=10_000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    load0 = os.getloadavg()
    walls = []
    for _ in range(args.repeat):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "mission_sim.cli", "tolerance", "--draws", str(args.draws),
                            "--workers", str(args.workers), "--out", tmp, "--no-progress", "--format", "json"],
                           check=True, capture_output=True)
            walls.append(time.perf_counter() - t0)
    out = {"draws": args.draws, "workers": args.workers, "wall_s": walls, "median_s": statistics.median(walls),
           "serial_ms_per_draw": 1e3 * _serial_per_draw(), "load": [load0, os.getloadavg()]}
    if args.json:
        print(json.dumps(out))
        return
    print(f"{args.draws} draws, {args.workers} workers, end to end: median {out['median_s']:.1f} s "
          f"(range {min(walls):.1f}-{max(walls):.1f}); in-process serial {out['serial_ms_per_draw']:.2f} ms per draw; "
          f"load {load0} -> {os.getloadavg()}")


if __name__ == "__main__":
    main()
