"""CPU of ``oracle_imitation_filtered``'s ``act`` against the plain clone and the MPC (budget 0), in process, on one
batched env of 100 windows (modal link): per policy the CPU time spent in ``act`` over the whole windows (the env's
step not counted), per window and per after-stop step; the policies alternate in every round, after a warm-up round
(numba compiles, the MPC's set-up). Medians and ranges over the rounds, with the load.

    python benchmarks/bench_oracle_imitation_filter.py --scenario battery_low --episodes 100 --rounds 3
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

POLICIES = {
    "oracle_imitation": {},
    "mpc": None,
    "filtered qp (stop)": dict(correction="qp", limit=0.0, slow=1.0, smooth=300.0, every_period=False),
    "filtered qp (every period)": dict(correction="qp", limit=0.006, slow=1.1, smooth=300.0, every_period=True),
    "filtered rate (limit)": dict(correction="rate", limit=0.004, lam=None, slow=1.0),
    "filtered rate (lam 0.6)": dict(correction="rate", lam=0.6, slow=1.0),
}


def act_cpu(make_pol, venv, seed, n):
    """CPU seconds in ``act`` over one rollout of the ``n`` windows, and the number of after-stop steps."""
    obs, _ = venv.reset(seed=[seed + i for i in range(n)])
    pol = make_pol(venv.policy_context)
    pol.reset(n)
    cpu, after = 0.0, 0
    for k in range(venv.config.n_steps):
        c = time.process_time()
        d = np.asarray(pol.act(obs), dtype=float).reshape(n)
        cpu += time.process_time() - c
        after += int(np.sum(k >= venv._stop_k))
        obs, *_ = venv.step((2.0 * np.clip(d, 0.0, 1.0) - 1.0)[:, None].astype(np.float32))
    return cpu, after


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default="battery_low")
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=300)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    from envs import EnvConfig, SbarChargingVectorEnv
    from policies import make
    from policies.oracle_imitation_filter import OracleImitationFilteredPolicy

    def maker(name, opts):
        if opts is None:
            return lambda ctx: make(name, ctx)
        if not opts:
            return lambda ctx: make("oracle_imitation", ctx)
        return lambda ctx: OracleImitationFilteredPolicy(ctx, **opts)
    venv = SbarChargingVectorEnv(num_envs=a.episodes, scenario=a.scenario, config=EnvConfig(link_model="modal"))
    res = {k: [] for k in POLICIES}
    loads = [os.getloadavg()[0]]
    for rnd in range(a.rounds + 1):   # round 0: warm-up
        for name, opts in POLICIES.items():
            cpu, after = act_cpu(maker(name if opts is None else "", opts), venv, a.seed, a.episodes)
            if rnd:
                res[name].append((cpu, after))
        loads.append(os.getloadavg()[0])
    print(f"{a.scenario}, windows {a.seed}-{a.seed + a.episodes - 1}, modal link, {a.rounds} rounds after a warm-up, "
          f"load (1-min) {min(loads):.1f}-{max(loads):.1f}")
    for name, r in res.items():
        cpu = np.array([c for c, _ in r])
        after = r[0][1]
        print(f"  {name:<28} act CPU per window {1e3 * np.median(cpu) / a.episodes:7.1f} ms "
              f"({1e3 * cpu.min() / a.episodes:.1f}-{1e3 * cpu.max() / a.episodes:.1f}); per after-stop step and window "
              f"{1e6 * np.median(cpu) / after:6.1f} us")


if __name__ == "__main__":
    main()
