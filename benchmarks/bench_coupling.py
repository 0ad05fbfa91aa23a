"""Coupling table lookup: ``CouplingModel.lm_h`` on 10^5 random poses (in-process), medians with ranges.

Poses: |dx|, |dy| <= 0.5 m, tilt in [-0.3, 0.3] rad about a random horizontal axis, and dz in
[0.06, 0.6] m ("inside": every receiver point inside the table, the compiled lookup alone) or in
[0.03, 0.6] m ("some_below": ~1.5 % of the poses dip below the table's floor, z_min = 0.02 m, and take the
exact field at those points; before issue 22 one such pose sent the whole batch to numpy). One warm-up call (numba
import and its cache load, the table from the disk cache) before the timed repeats; wall and this
process's CPU time (less sensitive to a shared machine) per call, ``os.getloadavg()`` before and
after. ``compiled=False`` and ``compiled=True`` are both timed: before issue 22 the first was the
numpy lookup, since then the flag is ignored (one compiled lookup), so both rows measure it.

    python benchmarks/bench_coupling.py [--n 100000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import statistics
import time

import numpy as np

from wpt_receiver.coupling import default_coupling


def poses(n: int, dz_min_m: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    return (rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n), rng.uniform(dz_min_m, 0.6, n),
            rng.uniform(-0.3, 0.3, n), rng.uniform(0, 2 * math.pi, n))


def measure(n: int, repeat: int) -> dict:
    model = default_coupling()
    out = {"n_poses": n, "repeat": repeat, "load_before": os.getloadavg()}
    for (name, dz_min), compiled in itertools.product((("inside", 0.06), ("some_below", 0.03)), (False, True)):
        dx, dy, dz, tilt, axis = poses(n, dz_min)
        model.lm_h(dx[:10], dy[:10], dz[:10], tilt[:10], tilt_axis_rad=axis[:10], compiled=compiled)  # warm-up
        walls, cpus = [], []
        for _ in range(repeat):
            w, c = time.perf_counter(), time.process_time()
            lm = model.lm_h(dx, dy, dz, tilt, tilt_axis_rad=axis, compiled=compiled)
            walls.append(time.perf_counter() - w)
            cpus.append(time.process_time() - c)
        out[f"{name} compiled={compiled}"] = {
            "wall_median_s": statistics.median(walls), "wall_range_s": [min(walls), max(walls)],
            "cpu_median_s": statistics.median(cpus), "cpu_range_s": [min(cpus), max(cpus)],
            "sum_lm_h": float(np.sum(lm)), "poses_below_table": int(np.sum(dz - 0.12 * np.sin(np.abs(tilt)) < 0.02))}
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
