"""Thread CPU per env-step of the vector env's ``step`` over whole episodes (autoresets included), and of its
autoreset (``_start``) alone, on eq. 4's link (``nominal``, random actions, ``gym.make_vec``): one JSON line.

With one thread every part of the step runs on the calling thread, so its thread CPU is the step's work; with two,
the calling thread's CPU is the step's critical path on two free cores (its chunks of the parallel kernel plus the
serial parts), the process CPU adds the second thread's (including OpenMP's spinning between steps). Run it on two
trees alternately (``PYTHONPATH=<tree> python benchmarks/step_cpu.py N THREADS``, several processes each) and quote
the load: a loaded machine inflates CPU times too.
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np


def main(argv=None):
    import gymnasium as gym

    import envs
    from envs import EnvConfig

    args = sys.argv[1:] if argv is None else argv
    n, threads = int(args[0]), int(args[1])
    venv = gym.make_vec(envs.ENV_ID, num_envs=n, vectorization_mode="vector_entry_point",
                        config=EnvConfig(link_model="envelope"), num_threads=threads).unwrapped
    rng = np.random.default_rng(1)
    acts = [rng.uniform(-1, 1, (n, 1)).astype(np.float32) for _ in range(20)]
    venv.reset(seed=0)
    for i in range(30):   # warm-up (compile or cache load, first touch)
        venv.step(acts[i % 20])
    venv.reset(seed=0)
    starts = []
    start = venv._start

    def timed_start(*a, **k):
        c = time.thread_time()
        r = start(*a, **k)
        starts.append(time.thread_time() - c)
        return r

    venv._start = timed_start
    T = venv._T + 1   # an episode: T - 1 steps, then the step that restarts it
    blocks = []
    for _ in range(3):
        c, w, p = time.thread_time(), time.perf_counter(), time.process_time()
        for i in range(T):
            venv.step(acts[i % 20])
        per = 1e9 / (T * n)
        blocks.append(((time.thread_time() - c) * per, (time.perf_counter() - w) * per, (time.process_time() - p) * per))
    med = [float(np.median([b[i] for b in blocks])) for i in range(3)]
    print(json.dumps({"N": n, "threads": threads, "step_thread_cpu_ns": med[0], "step_wall_ns": med[1],
                      "step_process_cpu_ns": med[2], "n_autoresets": len(starts),
                      "autoreset_thread_cpu_ns_per_env_step": float(np.median(starts)) * 1e9 / (T * n),
                      "load": os.getloadavg()[0]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
