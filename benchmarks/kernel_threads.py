"""The vector env's compiled step (``plant.step``: :func:`envs.vector_kernel.env_step`) on one thread and on two,
inside ``venv.step`` (eq. 4's link, ``nominal``, random actions, the kernel timed in place): wall ns per env-step, the
least, the 10th percentile and the median over the steps of several rounds, the three set-ups alternating
(one thread; two threads with dynamic chunks, the env's setting; two threads with numba's static split). On a
machine shared with other work the median is what a contended pool gives and the low percentiles what the step
takes when both cores are free.

    PYTHONPATH=<tree> python benchmarks/kernel_threads.py N [ROUNDS]
"""

from __future__ import annotations

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
    rounds = int(args[1]) if len(args) > 1 else 6
    modes = {"1 thread": (1, None), "2 threads, dynamic chunks": (2, 1), "2 threads, static split": (2, 0)}
    envs_ = {m: SbarChargingVectorEnv(n, scenario="nominal", config=EnvConfig(link_model="envelope"), num_threads=th)
             for m, (th, _) in modes.items()}
    rng = np.random.default_rng(1)
    acts = [rng.uniform(-1, 1, (n, 1)).astype(np.float32) for _ in range(20)]
    own = V._set_threads
    res = {m: [] for m in modes}
    load0 = os.getloadavg()[0]
    try:
        for _ in range(rounds):
            for m, e in envs_.items():
                th, chunk = modes[m]

                def set_threads(k, chunk=chunk):
                    numba.set_num_threads(k)
                    numba.set_parallel_chunksize(chunk)

                V._set_threads = own if chunk is None else set_threads
                e.reset(seed=0)
                times = []
                step = e.parts.plant.step

                def timed(*a, step=step, times=times):
                    t0 = time.perf_counter()
                    step(*a)
                    times.append(time.perf_counter() - t0)

                e.parts.plant.step = timed
                for i in range(120):
                    e.step(acts[i % 20])
                e.parts.plant.step = step
                res[m] += times[5:]
    finally:
        V._set_threads = own
    print(f"N = {n}, kernel wall ns per env-step over {rounds} rounds of 115 steps; load {load0:.2f} -> "
          f"{os.getloadavg()[0]:.2f}")
    for m, v in res.items():
        v = np.array(v) * 1e9 / n
        print(f"{m:<27} least {v.min():7.1f}   10th percentile {np.percentile(v, 10):7.1f}   median {np.median(v):7.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
