"""Environment throughput against gymnasium's CartPole-v1, measured in the same run.

* single env: steps/s of the raw env (``env.unwrapped``-style object, no wrappers) and through
  ``gymnasium.make`` (default wrappers: OrderEnforcing, PassiveEnvChecker), each as a ratio to
  CartPole-v1 measured the same way (goal: ratio >= 1.0). CartPole alternates its two actions
  (long episodes), ours holds a duty; both are reset when an episode ends (reset cost included).
* single env with a fresh uniform random action every step (both envs), the issue-14 measure
  (goal: ratio >= 1.5).
* vector env: ns per env-step of ``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``
  at N = 64, 256, 1024, 4096, 16384 (``--n``), beside gymnasium's own batched CartPoleVectorEnv at the
  same N in the same run: all numba threads (parallel over sub-envs from
  ``SbarChargingVectorEnv.PARALLEL_MIN_ENVS`` on), one thread (``num_threads=1``) and the default
  (``num_threads=None``: one or all threads chosen by measured step times);
  with a held duty and with uniform random actions each step for both envs, autoresets included
  (the worst case for ours: the I2 envelope changes sign in many windows every step, and those
  steps are re-stepped in 17 rectifier-period sub-steps; issue 22's goal: ratio >= 1.0 at N >= 4096).
  ``--vector-only`` skips the single-env rows; the N table is printed last.
* ``--links``: instead, the vector env on the exact-mode link (``EnvConfig(link_model="modal")``, the envs'
  default since 2026-11-26) against eq. 4's envelope (``EnvConfig(link_model="envelope")``, the default before),
  both named explicitly, alternating in the same run, one thread, at the ``--n`` widths (held duty and random
  actions): ns per env-step of each and the ratio modal / envelope.
* ``--link {envelope,modal}``: the link of our env in the CartPole comparisons (default: the envs' default, modal;
  the goals above were set, and met, on eq. 4's envelope link: ``--link envelope`` reproduces those runs).
  Printed with every table.

Every measurement is warmed up once (discarded), then alternates between the two envs in
rounds and reports the median round (and the
range of the per-round ratios), which damps the noise of a shared machine; ``os.getloadavg()``
is printed.

    python benchmarks/bench_env.py [--seconds 1.0] [--rounds 5] [--n 64 1024 4096 16384] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import gymnasium as gym  # noqa: E402

import envs  # noqa: E402


def _single_rate(env, actions, seconds):
    env.reset(seed=0)
    n, t0 = 0, time.perf_counter()
    step = env.step
    while True:
        for a in actions:
            _, _, term, trunc, _ = step(a)
            if term or trunc:
                env.reset()
        n += len(actions)
        dt = time.perf_counter() - t0
        if dt >= seconds:
            return n / dt


def _vector_rate(venv, actions, seconds):
    venv.reset(seed=0)
    seq = actions if isinstance(actions, list) else [actions] * 20
    n, t0 = 0, time.perf_counter()
    while True:
        for a in seq:
            venv.step(a)
        n += 20 * venv.num_envs
        dt = time.perf_counter() - t0
        if dt >= seconds:
            return n / dt


def _pair(rate_a, rate_b, rounds):
    """Alternate two measurements ``rounds`` times after one warm-up round of each (numba's
    compile or cache load, first-touch allocations; discarded): medians and the per-round ratios
    b / a."""
    rate_a(), rate_b()
    ra, rb = [], []
    for _ in range(rounds):
        ra.append(rate_a())
        rb.append(rate_b())
    ratios = [b / a for a, b in zip(ra, rb)]
    return {"cartpole_steps_s": statistics.median(ra), "sbar_steps_s": statistics.median(rb),
            "ratio": statistics.median(ratios), "ratio_min": min(ratios), "ratio_max": max(ratios)}


def _vector(n_vec, rng, seconds, rounds, config=None):
    """Ours (``make_vec``, vector entry point; default threads and one thread; env config ``config``) against
    CartPoleVectorEnv at the same N."""
    from gymnasium.envs.classic_control.cartpole import CartPoleVectorEnv

    out = {"n_envs": n_vec}
    cpv = CartPoleVectorEnv(num_envs=n_vec)
    acts = np.zeros((n_vec, 1), np.float32)
    acts_cp = np.ones(n_vec, dtype=np.int64)
    acts_rand = [rng.uniform(-1, 1, (n_vec, 1)).astype(np.float32) for _ in range(20)]
    acts_cp_rand = [rng.integers(0, 2, n_vec) for _ in range(20)]
    import numba
    top = numba.config.NUMBA_NUM_THREADS
    for mode, kw in (("", {"num_threads": top}), ("_1thread", {"num_threads": 1}), ("_auto", {})):
        venv = gym.make_vec(envs.ENV_ID, num_envs=n_vec, vectorization_mode="vector_entry_point", config=config, **kw)
        out["threads" + mode] = venv.unwrapped.num_threads if venv.unwrapped._n_chunks > 1 else 1
        out["held" + mode] = _pair(lambda: _vector_rate(cpv, acts_cp, seconds), lambda: _vector_rate(venv, acts, seconds),
                                   rounds)
        out["random" + mode] = _pair(lambda: _vector_rate(cpv, acts_cp_rand, seconds),
                                     lambda: _vector_rate(venv, acts_rand, seconds), rounds)
    return out


def _links(n_vec, rng, seconds, rounds):
    """ns per env-step of the modal link (the default) against eq. 4's envelope at width ``n_vec``, one thread
    (both links named: the result does not depend on which is the default)."""
    from envs import EnvConfig, SbarChargingVectorEnv
    env_a = SbarChargingVectorEnv(num_envs=n_vec, scenario="random", num_threads=1,
                                  config=EnvConfig(link_model="envelope"))
    env_b = SbarChargingVectorEnv(num_envs=n_vec, scenario="random", num_threads=1,
                                  config=EnvConfig(link_model="modal"))
    acts = np.zeros((n_vec, 1), np.float32)
    acts_rand = [rng.uniform(-1, 1, (n_vec, 1)).astype(np.float32) for _ in range(20)]
    out = {"n_envs": n_vec}
    for label, a in (("held", acts), ("random", acts_rand)):
        r = _pair(lambda: _vector_rate(env_a, a, seconds), lambda: _vector_rate(env_b, a, seconds), rounds)
        out[label] = {"envelope_ns": 1e9 / r["cartpole_steps_s"], "modal_ns": 1e9 / r["sbar_steps_s"],
                      "ratio": 1.0 / r["ratio"], "ratio_min": 1.0 / r["ratio_max"], "ratio_max": 1.0 / r["ratio_min"]}
    return out


def _print_links(res):
    print("\nvector env, one thread, ns per env-step (medians); ratio = modal / envelope (range over rounds)")
    print("| N | actions | envelope (eq. 4) ns | modal (exact modes, the envs' default) ns | ratio |")
    print("|---|---|---|---|---|")
    for v in res["links"]:
        for label in ("held", "random"):
            r = v[label]
            print(f"| {v['n_envs']} | {label} | {r['envelope_ns']:.1f} | {r['modal_ns']:.1f} | {r['ratio']:.2f}x "
                  f"({r['ratio_min']:.2f}-{r['ratio_max']:.2f}) |")
    print(f"load average (1 min) before {res['load_before'][0]:.2f}, after {res['load_after'][0]:.2f}")


def run(seconds=1.0, rounds=5, n_vec=(64, 256, 1024, 4096, 16384), vector_only=False, link=None):
    from envs import EnvConfig
    config = EnvConfig() if link is None else EnvConfig(link_model=link)
    out = {"load_before": os.getloadavg(), "link": config.link_model}
    if not vector_only:
        out.update(_singles(seconds, rounds, config))
    rng = np.random.default_rng(1)
    out["vector"] = [_vector(n, rng, seconds, rounds, config) for n in n_vec]
    out["load_after"] = os.getloadavg()
    return out


def _singles(seconds, rounds, config=None):
    from gymnasium.envs.classic_control.cartpole import CartPoleEnv

    out = {}
    pairs = {
        "raw": (CartPoleEnv(), envs.SbarChargingEnv(config=config)),
        "make": (gym.make("CartPole-v1"), gym.make(envs.ENV_ID, config=config)),
    }
    # CartPole alternates left/right (long episodes, few resets: its best case); ours holds a duty
    a_cp, a_ours = [0, 1] * 250, [np.array([0.0], np.float32)] * 500
    for label, (cp, ours) in pairs.items():
        out[f"single_{label}"] = _pair(lambda: _single_rate(cp, a_cp, seconds),
                                       lambda: _single_rate(ours, a_ours, seconds), rounds)
    rng = np.random.default_rng(0)
    r_cp = [int(a) for a in rng.integers(0, 2, 500)]
    r_ours = [np.array([a], np.float32) for a in rng.uniform(-1, 1, 500)]
    cp, ours = pairs["make"]
    out["single_make_random"] = _pair(lambda: _single_rate(cp, r_cp, seconds),
                                      lambda: _single_rate(ours, r_ours, seconds), rounds)
    return out


def _print_table(res):
    """The N table: ns per env-step (medians), ratio CartPoleVectorEnv / ours with the per-round range."""
    print(f"\nvector env ({res['link']} link), random actions (autoresets), ns per env-step, medians; ratio = "
          "CartPole ns / ours ns")
    print("| N | CartPoleVectorEnv ns | ours, all threads: ns, ratio (range) | 1 thread | default (auto) |")
    print("|---|---|---|---|---|")
    for v in res["vector"]:
        cells = []
        for mode in ("", "_1thread", "_auto"):
            r = v["random" + mode]
            cells.append(f"{1e9 / r['sbar_steps_s']:.1f} ns, {r['ratio']:.2f}x ({r['ratio_min']:.2f}-{r['ratio_max']:.2f})")
        print(f"| {v['n_envs']} ({v['threads']} threads) | {1e9 / v['random']['cartpole_steps_s']:.1f} | " + " | ".join(cells)
              + " |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=1.0, help="time per measurement (default 1 s)")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--n", type=int, nargs="+", default=[64, 256, 1024, 4096, 16384],
                    help="vector env widths (default 64 256 1024 4096 16384)")
    ap.add_argument("--vector-only", action="store_true", help="skip the single-env measurements")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--links", action="store_true", help="the modal link against the envelope (module docstring)")
    ap.add_argument("--link", choices=("envelope", "modal"), default=None,
                    help="our env's link in the CartPole comparisons (default: the envs' default, modal)")
    args = ap.parse_args(argv)
    if args.links:
        res = {"load_before": os.getloadavg()}
        rng = np.random.default_rng(1)
        res["links"] = [_links(n, rng, args.seconds, args.rounds) for n in args.n]
        res["load_after"] = os.getloadavg()
        print(json.dumps(res, indent=2)) if args.json else _print_links(res)
        return 0
    res = run(args.seconds, args.rounds, args.n, args.vector_only, args.link)
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    print(f"our env on the {res['link']} link; load average before {res['load_before'][0]:.2f}, after "
          f"{res['load_after'][0]:.2f} (1 min)")
    for label, goal in (("single_raw", 1.0), ("single_make", 1.0), ("single_make_random", 1.5)):
        if label not in res:
            continue
        r = res[label]
        print(f"{label:<19} CartPole-v1 {r['cartpole_steps_s']:>10,.0f} steps/s   SbarCharging-v0 "
              f"{r['sbar_steps_s']:>10,.0f} steps/s   ratio {r['ratio']:.2f} (range {r['ratio_min']:.2f}-"
              f"{r['ratio_max']:.2f}; goal >= {goal})")
    for v in res["vector"]:
        for label, goal in (("held", "-"), ("random", ">= 1.0"), ("held_1thread", "-"), ("random_1thread", "-"),
                            ("held_auto", "-"), ("random_auto", ">= 1.0")):
            r = v[label]
            print(f"vector N={v['n_envs']:<6} {label:<6} CartPoleVectorEnv {r['cartpole_steps_s']:>13,.0f}   SbarCharging-v0 "
                  f"{r['sbar_steps_s']:>13,.0f} env-steps/s   ratio {r['ratio']:.2f} (range {r['ratio_min']:.2f}-"
                  f"{r['ratio_max']:.2f}; goal {goal})")
    _print_table(res)
    print(f"load average (1 min) before {res['load_before'][0]:.2f}, after {res['load_after'][0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
