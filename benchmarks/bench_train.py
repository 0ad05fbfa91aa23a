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

A third path, ``as_filed``, is the ``make_vec_env`` path of the code that issue 11 was filed against
(``--as-filed REV``, default ``AS_FILED_REV``: its single env, its wrappers), unpacked from git into a
temporary folder and trained in a subprocess with the same PPO and hyperparameters, in the same
rounds: the training speed a user had then, measured now on the same machine; ``as_filed_train_defaults``
is that code's ``dronewpt train`` at its own defaults (1 env; PPO n_steps 512, batch 256, 10 epochs:
the ~1,800 env-steps/s the issue reports), on a quarter of the steps. Skipped with a note
when the repository's git history is not there (e.g. an sdist).

    OMP_NUM_THREADS=1 python benchmarks/bench_train.py [--steps 65536] [--rounds 5] [--n-envs 64]
        [--as-filed REV | --no-as-filed] [--json]

``--links envelope,modal`` measures instead the batched adapter (train's path, train's thread settings:
torch and numba on one thread) on each named link (``EnvConfig.link_model``: ``envelope`` = eq. 4,
``modal`` = the exact-mode link, the envs' default since 2026-11-26), the links alternating in every round
after a warm-up of each; both PPO ``model.learn`` and ``VecEnv.step`` alone, as above.

    OMP_NUM_THREADS=1 python benchmarks/bench_train.py --links envelope,modal --steps 16384 --rounds 3
"""

from __future__ import annotations

import argparse
import io
import json
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: the commit issue 11 was filed against (train used make_vec_env over the single env then)
AS_FILED_REV = "322d391"

_AS_FILED_SCRIPT = """
import json, sys, time
import torch
torch.set_num_threads(1)
import stable_baselines3 as sb3
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize
import envs
assert envs.__file__.startswith(sys.argv[1]), envs.__file__
n_envs, steps = int(sys.argv[2]), int(sys.argv[3])
if sys.argv[4] == "own":  # that code's own train defaults
    from policies.train import DEFAULT_HYPERPARAMS
    hp = dict(DEFAULT_HYPERPARAMS["ppo"])
else:
    hp = json.loads(sys.argv[4])
def rate(n):
    venv = VecNormalize(make_vec_env(envs.ENV_ID, n_envs=n_envs, seed=0, env_kwargs={"scenario": "random"}), gamma=0.98)
    model = sb3.PPO("MlpPolicy", venv, seed=0, device="cpu", verbose=0, **hp)
    t0 = time.perf_counter()
    model.learn(total_timesteps=n)
    return model.num_timesteps / (time.perf_counter() - t0)
rate(2 * n_envs * hp["n_steps"])  # warm-up, not measured
print(rate(steps))
"""


def _env(path: str, n_envs: int, link: str | None = None):
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    import envs
    from envs.sb3_vec import EPISODE_KEYS, SbarSB3VecEnv

    if path == "batched":
        config = None if link is None else envs.EnvConfig(link_model=link)
        venv = VecMonitor(SbarSB3VecEnv(n_envs, "random", config=config), info_keywords=EPISODE_KEYS)
        venv.seed(0)
    else:
        venv = make_vec_env(envs.ENV_ID, n_envs=n_envs, seed=0, env_kwargs={"scenario": "random"},
                            monitor_kwargs={"info_keywords": ("episode_cost", "overshoot", "reached_short_mode")})
    return VecNormalize(venv, gamma=0.98)


def _rate(path: str, n_envs: int, steps: int, link: str | None = None) -> float:
    import stable_baselines3 as sb3

    from policies.train import DEFAULT_HYPERPARAMS

    venv = _env(path, n_envs, link)
    model = sb3.PPO("MlpPolicy", venv, seed=0, device="cpu", verbose=0, **DEFAULT_HYPERPARAMS["ppo"])
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    dt = time.perf_counter() - t0
    venv.close()
    return model.num_timesteps / dt


def _step_rate(path: str, n_envs: int, steps: int, link: str | None = None) -> float:
    """env-steps/s of the wrapped VecEnv alone (random actions, same stack as training)."""
    import numpy as np

    venv = _env(path, n_envs, link)
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


def _unpack_rev(rev: str, dest: Path) -> bool:
    """The tree of ``rev`` unpacked into ``dest`` (``git archive``); False without git history."""
    try:
        tar = subprocess.run(["git", "-C", str(ROOT), "archive", rev], capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return False
    with tarfile.open(fileobj=io.BytesIO(tar)) as tf:
        tf.extractall(dest / "tree", filter="data")
    return True


def _as_filed_rate(tree: Path, n_envs: int, steps: int, own: bool = False) -> float:
    """PPO env-steps/s on the ``make_vec_env`` path of the code in ``tree`` (a subprocess), with
    today's PPO hyperparameters or (``own``) that code's ``train`` defaults."""
    from policies.train import DEFAULT_HYPERPARAMS

    hp = "own" if own else json.dumps(DEFAULT_HYPERPARAMS["ppo"])
    env = dict(os.environ, PYTHONPATH=str(tree), OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", _AS_FILED_SCRIPT, str(tree), str(n_envs), str(steps), hp],
                         env=env, cwd=str(tree),
                         capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def _summary(rates: dict) -> dict:
    med = {p: statistics.median(v) for p, v in rates.items() if v}
    res = {"median_env_steps_per_s": med, "range": {p: [min(v), max(v)] for p, v in rates.items() if v},
           "ratio_batched_over_make_vec_env": med["batched"] / med["make_vec_env"]}
    for p in ("as_filed", "as_filed_train_defaults"):
        if p in med:
            res[f"ratio_batched_over_{p}"] = med["batched"] / med[p]
    return res


def _print(label: str, res: dict, rounds: int) -> None:
    print(label)
    for p, med in res["median_env_steps_per_s"].items():
        lo, hi = res["range"][p]
        print(f"  {p:>13}: median {med:,.0f} env-steps/s (range {lo:,.0f} .. {hi:,.0f}) over {rounds} rounds")
    print(f"  ratio batched / make_vec_env: {res['ratio_batched_over_make_vec_env']:.1f}x")
    if "ratio_batched_over_as_filed" in res:
        print(f"  ratio batched / as_filed (make_vec_env of {AS_FILED_REV}, issue 11 as filed, same PPO): "
              f"{res['ratio_batched_over_as_filed']:.1f}x")
    if "ratio_batched_over_as_filed_train_defaults" in res:
        print(f"  ratio batched / as_filed_train_defaults (`dronewpt train` of {AS_FILED_REV} at its defaults: "
              f"1 env, n_steps 512, batch 256, 10 epochs): {res['ratio_batched_over_as_filed_train_defaults']:.1f}x")


def main(argv=None) -> int:
    import torch

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=65_536)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--n-envs", type=int, default=64)
    ap.add_argument("--as-filed", default=AS_FILED_REV, metavar="REV",
                    help=f"git revision of the as-filed make_vec_env path (default {AS_FILED_REV})")
    ap.add_argument("--no-as-filed", action="store_true", help="skip the as-filed path")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--links", default=None, metavar="A,B",
                    help="compare the batched path on these links instead (envelope, modal), alternating")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    if args.links is not None:
        links = args.links.split(",")
        bad = [k for k in links if k not in ("envelope", "modal")]
        if bad or len(links) < 2 or len(set(links)) != len(links):
            print(f"bench_train: --links {args.links!r} is invalid; valid: two or more distinct of envelope, modal",
                  file=sys.stderr)
            return 2
        return _links_main(args, links)
    with tempfile.TemporaryDirectory(prefix="bench_train_") as tmp:
        tree = None
        if not args.no_as_filed:
            if _unpack_rev(args.as_filed, Path(tmp)):
                tree = Path(tmp) / "tree"
            else:
                print(f"note: as-filed path skipped (no git history with {args.as_filed} at {ROOT})")
        res = _measure(args, tree)
    if args.json:
        print(json.dumps(res, indent=1))
        return 0
    _print("PPO model.learn (rollouts + updates):", res["ppo_learn"], args.rounds)
    _print("VecEnv.step alone (random actions, same wrappers):", res["vecenv_step_only"], args.rounds)
    print(f"load average before {res['loadavg_before'][0]:.2f}, after {res['loadavg_after'][0]:.2f} (2 cores)")
    return 0


def _links_main(args, links: list) -> int:
    """The batched path (train's) on each link, alternating per round after a warm-up of each."""
    import numba

    numba.set_num_threads(1)   # as policies.train.train (numba's spinning OpenMP worker starves torch)
    for link in links:         # warm-up (compile the link's step), not measured
        _rate("batched", args.n_envs, 2 * args.n_envs * 128, link)
        _step_rate("batched", args.n_envs, 2 * args.n_envs * 128, link)
    load0 = os.getloadavg()
    learn = {k: [] for k in links}
    step = {k: [] for k in links}
    cpu = {k: [] for k in links}
    for _ in range(args.rounds):
        for link in links:
            c0 = time.process_time()
            learn[link].append(_rate("batched", args.n_envs, args.steps, link))
            cpu[link].append(args.steps / (time.process_time() - c0))
            step[link].append(_step_rate("batched", args.n_envs, args.steps, link))
    res = {"steps_per_round": args.steps, "n_envs": args.n_envs, "rounds": args.rounds, "links": links,
           "ppo_learn_env_steps_per_wall_s": {k: _med_range(v) for k, v in learn.items()},
           "ppo_learn_env_steps_per_cpu_s": {k: _med_range(v) for k, v in cpu.items()},
           "vecenv_step_only_env_steps_per_s": {k: _med_range(v) for k, v in step.items()},
           "loadavg_before": load0, "loadavg_after": os.getloadavg()}
    if args.json:
        print(json.dumps(res, indent=1))
        return 0
    for title, key in (("PPO model.learn, env-steps per wall second", "ppo_learn_env_steps_per_wall_s"),
                       ("PPO model.learn, env-steps per CPU second", "ppo_learn_env_steps_per_cpu_s"),
                       ("VecEnv.step alone (random actions)", "vecenv_step_only_env_steps_per_s")):
        print(title)
        for k, (med, lo, hi) in res[key].items():
            print(f"  {k:>9}: median {med:,.0f} (range {lo:,.0f} .. {hi:,.0f}) over {args.rounds} rounds")
        a, b = links[0], links[1]
        print(f"  ratio {a} / {b}: {res[key][a][0] / res[key][b][0]:.1f}x")
    print(f"load average before {res['loadavg_before'][0]:.2f}, after {res['loadavg_after'][0]:.2f} (2 cores)")
    return 0


def _med_range(v: list) -> list:
    return [statistics.median(v), min(v), max(v)]


def _measure(args, tree) -> dict:
    """All rounds, the paths alternating; ``tree``: the as-filed code (or None)."""
    for path in ("batched", "make_vec_env"):   # warm-up, not measured
        _rate(path, args.n_envs, 4 * args.n_envs * 128)
    load0 = os.getloadavg()
    rates = {"batched": [], "make_vec_env": [], "as_filed": [], "as_filed_train_defaults": []}
    steps_only = {"batched": [], "make_vec_env": []}
    for _ in range(args.rounds):
        for path in steps_only:
            rates[path].append(_rate(path, args.n_envs, args.steps))
            steps_only[path].append(_step_rate(path, args.n_envs, args.steps))
        if tree is not None:
            rates["as_filed"].append(_as_filed_rate(tree, args.n_envs, args.steps))
            rates["as_filed_train_defaults"].append(_as_filed_rate(tree, 1, args.steps // 4, own=True))
    return {"steps_per_round": args.steps, "n_envs": args.n_envs, "rounds": args.rounds,
            "as_filed_rev": None if tree is None else args.as_filed,
            "ppo_learn": _summary(rates), "vecenv_step_only": _summary(steps_only),
            "loadavg_before": load0, "loadavg_after": os.getloadavg()}


if __name__ == "__main__":
    raise SystemExit(main())
