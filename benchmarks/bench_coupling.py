"""Coupling table lookup: ``CouplingModel.lm_h`` on 10^5 random poses (in-process), medians with ranges.

Poses: |dx|, |dy| <= 0.5 m, dz in [0.05, 0.6] m, tilt in [-0.3, 0.3] rad about a random horizontal
axis (all receiver points inside the table: the compiled lookup alone). One warm-up call (numba
import and its cache load, the table from the disk cache) before the timed repeats; wall and this
process's CPU time (less sensitive to a shared machine) per call, ``os.getloadavg()`` before and
after. ``compiled=False`` and ``compiled=True`` are both timed: before issue 22 the first was the
numpy lookup, since then the flag is ignored (one compiled lookup), so both rows measure it.

    python benchmarks/bench_coupling.py [--n 100000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import time

import numpy as np

from wpt_receiver.coupling import default_coupling


def poses(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    return (rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n), rng.uniform(0.05, 0.6, n),
            rng.uniform(-0.3, 0.3, n), rng.uniform(0, 2 * math.pi, n))


def measure(n: int, repeat: int) -> dict:
    model = default_coupling()
    dx, dy, dz, tilt, axis = poses(n)
    out = {"n_poses": n, "repeat": repeat, "load_before": os.getloadavg()}
    for compiled in (False, True):
        model.lm_h(dx[:10], dy[:10], dz[:10], tilt[:10], tilt_axis_rad=axis[:10], compiled=compiled)  # warm-up
        walls, cpus = [], []
        for _ in range(repeat):
            w, c = time.perf_counter(), time.process_time()
            lm = model.lm_h(dx, dy, dz, tilt, tilt_axis_rad=axis, compiled=compiled)
            walls.append(time.perf_counter() - w)
            cpus.append(time.process_time() - c)
        out[f"compiled={compiled}"] = {"wall_median_s": statistics.median(walls),
                                       "wall_range_s": [min(walls), max(walls)],
                                       "cpu_median_s": statistics.median(cpus), "cpu_range_s": [min(cpus), max(cpus)],
                                       "sum_lm_h": float(np.sum(lm))}
    out["load_after"] = os.getloadavg()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    print(json.dumps(measure(args.n, args.repeat), indent=1))


if __name__ == "__main__":
    main()
