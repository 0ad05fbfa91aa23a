"""CPU of the budgeted modal MPC's ``act`` with and without the locked-phase prediction (:data:`policies.mpc._LOCK`),
alternating in one process after a warm-up: median and range over the repeats of the policy's CPU per window
(``time.process_time`` around ``act``, the env excluded), ``nice -n 10``; the load is printed.

    python benchmarks/bench_mpc_lock.py [--policies mpc:0.05,mpc:0.1] [--windows 20] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--policies", default="mpc:0.05,mpc:0.1")
    ap.add_argument("--windows", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args(argv)
    import policies.mpc as mpc
    from envs import EnvConfig
    from policies.compare import run_policy
    cfg = EnvConfig(link_model="modal")
    spent = [0.0]
    act = mpc.MPCPolicy.act

    def timed(self, obs):
        c = time.process_time()
        try:
            return act(self, obs)
        finally:
            spent[0] += time.process_time() - c

    mpc.MPCPolicy.act = timed
    res = {}
    for rep in range(a.repeats + 1):   # the first: warm-up (numba's cache, the models)
        for name in a.policies.split(","):
            for lock in (False, True):
                mpc._LOCK = lock
                spent[0] = 0.0
                run_policy(name, "nominal", a.windows, 1000, cfg)
                if rep:
                    res.setdefault((name, lock), []).append(1e3 * spent[0] / a.windows)
    print(f"load {os.getloadavg()}")
    for (name, lock), v in res.items():
        print(f"{name:9s} lock={int(lock)}: {np.median(v):6.1f} ms CPU per window (range {min(v):.1f}-{max(v):.1f}, n={len(v)})")


if __name__ == "__main__":
    main()
