"""Time of the oracle's floor and of one budgeted solve on the exact-mode env (``link_model="modal"``): the
compiled replay (:func:`envs.modal_step.step_kernel` in :mod:`envs.rollout`'s loop) against the env stepped
from Python (``DutyRollout(..., compiled=False)``, the replay before 2026-11-26), alternately per window, in
one process, with the load average; the two results must be the same to the bit (same rollouts).

    nice -n 10 python benchmarks/bench_oracle_modal_replay.py [--windows nominal:1000,detuned:1001]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def _solve(kind, scenario, seed, cfg, compiled, base):
    from envs.rollout import DutyRollout
    from policies.oracle import _FloorProblem, _Problem
    roll = DutyRollout(scenario, seed, cfg, compiled=compiled)
    t0, c0 = time.perf_counter(), time.process_time()
    if kind == "floor":
        r = _FloorProblem(roll, base, np.inf).solve()
    else:
        r = _Problem(roll, base, kind).solve()
    return r, time.perf_counter() - t0, time.process_time() - c0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", default="nominal:1000,nominal:1001,nominal:1002,detuned:1001")
    ap.add_argument("--above", type=float, default=0.01,
                    help="the budgeted solve's budget above the window's floor (fraction; started from the floor's duties)")
    args = ap.parse_args(argv)
    from envs import EnvConfig
    from policies.oracle import policy_duties
    cfg = EnvConfig(link_model="modal")
    # warm: numba compiles (or loads) both replays once before timing
    _solve("floor", "nominal", 0, cfg, True, policy_duties("model_based", "nominal", 0, cfg)[0])
    for w in args.windows.split(","):
        scen, seed = w.split(":")
        seed = int(seed)
        base = policy_duties("model_based", scen, seed, cfg)[0]
        floor = None
        for kind in ("floor", "budget"):
            res = {}
            for compiled in (False, True):
                if kind == "floor":
                    r, wall, cpu = _solve("floor", scen, seed, cfg, compiled, base)
                    floor = r
                else:
                    kind = floor.overshoot + args.above
                    r, wall, cpu = _solve(kind, scen, seed, cfg, compiled, floor.duties)
                res[compiled] = r
                print(f"{scen}:{seed} {'floor' if kind == 'floor' else f'b={kind:.4f}'} "
                      f"{'compiled' if compiled else 'python  '} wall {wall:7.2f} s cpu {cpu:7.2f} s "
                      f"load {os.getloadavg()[0]:.2f} overshoot {100 * r.overshoot:.4f} % "
                      f"E {r.energy_after_stop_j:.5f} J", flush=True)
            same = np.array_equal(res[False].duties, res[True].duties) and \
                res[False].energy_after_stop_j == res[True].energy_after_stop_j
            print(f"  identical: {same}", flush=True)


if __name__ == "__main__":
    main()
