"""The vector env's compiled step (``plant.step``, timed in place inside ``venv.step``; eq. 4's link, ``nominal``,
random actions) on one thread, on two with dynamic chunks (the env's setting) and on two with numba's static split,
alternating blocks of 20 steps: **process CPU** (all threads) and wall ns per env-step, median and least over the
blocks; one JSON line. Run it with ``OMP_WAIT_POLICY=passive`` so that an idle OpenMP worker sleeps instead of
spinning (spinning would count as CPU). What the two-thread CPU adds over the one-thread CPU is the parallel step's
own overhead (fork-join, cache lines moving between the cores: with dynamic chunks a window's data may be stepped
by either core from one step to the next); the wall columns say how the step scales, and only on free cores.

    OMP_WAIT_POLICY=passive PYTHONPATH=<tree> python benchmarks/kernel_cpu_threads.py N [ROUNDS]
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np


def main(argv=None):
    import numba

    import envs.vector as V
    from envs import EnvConfig
    from envs.vector import SbarChargingVectorEnv

    args = sys.argv[1:] if argv is None else argv
    n = int(args[0])
    rounds = int(args[1]) if len(args) > 1 else 8
    env = SbarChargingVectorEnv(n, config=EnvConfig(link_model="envelope"), num_threads=2)
    rng = np.random.default_rng(3)
    acts = [rng.uniform(-1, 1, (n, 1)).astype(np.float32) for _ in range(20)]
    env.reset(seed=1)
    plant = env.parts.plant
    kern = plant.kernel
    mode = {"chunks": 1, "static": False}
    acc = [0.0, 0.0]

    def timed(*a):
        a = list(a)
        a[-1] = mode["chunks"]
        if mode["chunks"] > 1:
            V._set_threads(2)
            numba.set_parallel_chunksize(0 if mode["static"] else 1)
        p, w = time.process_time(), time.perf_counter()
        r = kern(*a)
        acc[0] += time.process_time() - p
        acc[1] += time.perf_counter() - w
        return r

    plant.kernel = timed
    for i in range(40):
        env.step(acts[i % 20])
    setups = {"1 thread": (1, False), "2 threads, dynamic chunks": (8, False), "2 threads, static split": (8, True)}
    res = {k: [] for k in setups}
    for _ in range(rounds):
        for key, (chunks, static) in setups.items():
            mode.update(chunks=chunks, static=static)
            acc[:] = [0.0, 0.0]
            for i in range(20):
                env.step(acts[i % 20])
            res[key].append((acc[0] / (20 * n) * 1e9, acc[1] / (20 * n) * 1e9))
    out = {"N": n, "rounds": rounds, "load": os.getloadavg()[0]}
    for key, v in res.items():
        a = np.array(v)
        out[key] = {"process_cpu_ns": [round(float(np.median(a[:, 0])), 1), round(float(a[:, 0].min()), 1)],
                    "wall_ns": [round(float(np.median(a[:, 1])), 1), round(float(a[:, 1].min()), 1)]}
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
