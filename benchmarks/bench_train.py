"""PPO training throughput: the batched SB3 adapter (``envs.sb3_vec.SbarSB3VecEnv``, train's
default) against SB3's ``make_vec_env`` path (``DummyVecEnv`` looping over single envs, each with
``Monitor`` and gymnasium's default wrappers), measured in the same run.

Both train the same PPO (``policies.train.DEFAULT_HYPERPARAMS["ppo"]``: 64 envs x 128 steps per
rollout, 5 epochs of 1024-sample minibatches, torch on one thread) behind ``VecNormalize`` for the
same number of environment steps; the throughput is env-steps per second of wall time of
``model.learn`` (rollouts *and* gradient updates). A second measurement times the part the adapter
replaces: ``VecEnv.step`` of the same wrapped stacks (VecNormalize included) with random actions, no
network. Rounds alternate between the two paths after one unmeasured warm-up round (numba and torch
first-call costs); the report gives the median with the range of each, their ratio and the load average.

    OMP_NUM_THREADS=1 python benchmarks/bench_train.py [--steps 65536] [--rounds 5] [--n-envs 64] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _env(path: str, n_envs: int):
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    import envs
    from envs.sb3_vec import EPISODE_KEYS, SbarSB3VecEnv

    if path == "batched":
        venv = VecMonitor(SbarSB3VecEnv(n_envs, "random"), info_keywords=EPISODE_KEYS)
        venv.seed(0)
    else:
        venv = make_vec_env(envs.ENV_ID, n_envs=n_envs, seed=0, env_kwargs={"scenario": "random"},
                            monitor_kwargs={"info_keywords": ("episode_cost", "overshoot", "reached_short_mode")})
    return VecNormalize(venv, gamma=0.98)


def _rate(path: str, n_envs: int, steps: int) -> float:
    import stable_baselines3 as sb3

    from policies.train import DEFAULT_HYPERPARAMS

    venv = _env(path, n_envs)
    model = sb3.PPO("MlpPolicy", venv, seed=0, device="cpu", verbose=0, **DEFAULT_HYPERPARAMS["ppo"])
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    dt = time.perf_counter() - t0
    venv.close()
    return model.num_timesteps / dt


def _step_rate(path: str, n_envs: int, steps: int) -> float:
    """env-steps/s of the wrapped VecEnv alone (random actions, same stack as training)."""
    import numpy as np

    venv = _env(path, n_envs)
    rng = np.random.default_rng(0)
    venv.reset()
    n_calls = max(1, steps // n_envs)
    acts = rng.uniform(-1.0, 1.0, (n_calls, n_envs, 1)).astype(np.float32)
    t0 = time.perf_counter()
    for a in acts:
        venv.step(a)
    dt = time.perf_counter() - t0
    venv.close()
    return n_calls * n_envs / dt


def _summary(rates: dict) -> dict:
    med = {p: statistics.median(v) for p, v in rates.items()}
    return {"median_env_steps_per_s": med, "range": {p: [min(v), max(v)] for p, v in rates.items()},
            "ratio_batched_over_make_vec_env": med["batched"] / med["make_vec_env"]}


def _print(label: str, res: dict, rounds: int) -> None:
    print(label)
    for p, med in res["median_env_steps_per_s"].items():
        lo, hi = res["range"][p]
        print(f"  {p:>13}: median {med:,.0f} env-steps/s (range {lo:,.0f} .. {hi:,.0f}) over {rounds} rounds")
    print(f"  ratio batched / make_vec_env: {res['ratio_batched_over_make_vec_env']:.1f}x")


def main(argv=None) -> int:
    import torch

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=65_536)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--n-envs", type=int, default=64)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    for path in ("batched", "make_vec_env"):   # warm-up, not measured
        _rate(path, args.n_envs, 4 * args.n_envs * 128)
    load0 = os.getloadavg()
    rates = {"batched": [], "make_vec_env": []}
    steps_only = {"batched": [], "make_vec_env": []}
    for _ in range(args.rounds):
        for path in rates:
            rates[path].append(_rate(path, args.n_envs, args.steps))
            steps_only[path].append(_step_rate(path, args.n_envs, args.steps))
    res = {"steps_per_round": args.steps, "n_envs": args.n_envs, "rounds": args.rounds,
           "ppo_learn": _summary(rates), "vecenv_step_only": _summary(steps_only),
           "loadavg_before": load0, "loadavg_after": os.getloadavg()}
    if args.json:
        print(json.dumps(res, indent=1))
        return 0
    _print("PPO model.learn (rollouts + updates):", res["ppo_learn"], args.rounds)
    _print("VecEnv.step alone (random actions, same wrappers):", res["vecenv_step_only"], args.rounds)
    print(f"load average before {load0[0]:.2f}, after {res['loadavg_after'][0]:.2f} (2 cores)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
