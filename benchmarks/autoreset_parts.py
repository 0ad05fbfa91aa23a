"""Thread CPU of the vector env's full autoreset (``_start`` of every window, as when all windows end together) and
of its parts, eq. 4's link, ``nominal``: ns per env-step of a (n_steps + 1)-step episode and us per window restart,
medians over repeated autoresets; one JSON line. The parts are wrapped in place: the scenario part (of it the
compiled draws and the command profile), the plant's plans (of it ``envs.core._initial_state``), the objective
and the first observation.

    PYTHONPATH=<tree> python benchmarks/autoreset_parts.py N THREADS [REPEATS]

Run it on two trees alternately, several processes each, and quote the load (thread CPU is inflated on a loaded
machine too)."""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np


def main(argv=None):
    import gymnasium as gym

    import envs
    import envs.core as core
    import envs.scenario as scenario_module
    from envs import EnvConfig

    args = sys.argv[1:] if argv is None else argv
    n, threads = int(args[0]), int(args[1])
    reps = int(args[2]) if len(args) > 2 else 15
    venv = gym.make_vec(envs.ENV_ID, num_envs=n, vectorization_mode="vector_entry_point",
                        config=EnvConfig(link_model="envelope"), num_threads=threads).unwrapped
    venv.reset(seed=0)
    rng = np.random.default_rng(1)
    for _ in range(5):
        venv.step(rng.uniform(-1, 1, (n, 1)).astype(np.float32))
    times: dict = {}

    def timed(f, key):
        def g(*a, **k):
            c = time.thread_time()
            r = f(*a, **k)
            times.setdefault(key, []).append(time.thread_time() - c)
            return r
        return g

    sc, plant, objective, observation = venv.parts
    sc.reset, plant.reset = timed(sc.reset, "scenario"), timed(plant.reset, "plans")
    objective.reset, observation.reset = timed(objective.reset, "objective"), timed(observation.reset, "observation")
    if sc.fill is not None:
        sc.fill = timed(sc.fill, "scenario: draws")
    scenario_module.command_profile = timed(scenario_module.command_profile, "scenario: command profile")
    core._initial_state = timed(core._initial_state, "plans: _initial_state")
    venv._start = timed(venv._start, "autoreset")
    rows = np.arange(n)
    for _ in range(2):
        venv._start(rows)
    times.clear()
    for _ in range(reps):
        venv._start(rows)
    per_step = 1e9 / (n * (venv._T + 1))
    out = {"N": n, "threads": threads, "repeats": reps, "load": os.getloadavg()[0]}
    for key, v in times.items():
        med = float(np.median(v))
        out[key] = {"ns_per_env_step": round(med * per_step, 2), "us_per_window": round(med * 1e6 / n, 3)}
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
