"""Issue 21: the same after-stop variants of a policy under PPO-like Gaussian action noise (std sigma in
action units on every step, clipped to [-1, 1]): does the stochastic return still prefer short mode?
100 windows seeded 1000..1099.

    python benchmarks/diag_rl_after_stop_noise.py rl:policies/pretrained/rl_s0.zip nominal
"""

from __future__ import annotations

import sys

import numpy as np


def main(argv):
    from envs import SbarChargingVectorEnv
    from envs import EnvConfig   # these diagnostics measured eq. 4's env (the default until 2026-11-26)
    from envs.objective import stop_step
    from policies import make

    base = argv[0]; scen = argv[1]
    sigmas = [0.0, 0.022, 0.05, 0.1, 0.223]
    mods = [("lift", 0.0), ("lift", 0.1), ("lift", 0.25), ("ramp1", None)]
    combos = [(s, m) for s in sigmas for m in mods]
    n = 100; B = len(combos)
    venv = SbarChargingVectorEnv(num_envs=n * B, scenario=scen, config=EnvConfig(link_model="envelope")); c = venv.config
    pol = make(base, venv.policy_context); pol.reset(venv.num_envs)
    obs, info = venv.reset(seed=[1000 + i for i in range(n)] * B)
    T = c.n_steps; ks = stop_step(info["t_stop_s"], c.dt_s, T)
    rng = np.random.default_rng(0)
    rew = np.zeros((T, n * B)); d0 = np.zeros(n * B)
    sig = np.repeat([s for s, m in combos], n)
    for k in range(T):
        db = np.clip(np.asarray(pol.act(obs), float).reshape(-1), 0, 1)
        j = k - ks; aft = j >= 0; d = db.copy()
        for b, (s, (m, x)) in enumerate(combos):
            r = slice(b * n, (b + 1) * n)
            v = db[r] + x * (1 - db[r]) if m == "lift" else d0[r] + (1 - d0[r]) * np.minimum(1, (j[r] + 1) / 10)
            d[r] = np.where(aft[r], v, db[r])
        d0 = np.where(aft, d0, db)
        a = np.clip(2 * d - 1 + sig * rng.standard_normal(n * B), -1, 1)   # noise on every step, as PPO's rollouts
        obs, rr, te, tr, last = venv.step(a[:, None].astype(np.float32)); rew[k] = rr
    print(f"{scen}, windows 1000..1099, policy {base}, Gaussian action noise sigma on every step; return [overshoot %, SM]")
    print("sigma  " + " ".join(f"{(m + (f' {x}' if x is not None else ' 1ms->1')):>22s}" for m, x in mods))
    for s in sigmas:
        cells = []
        for mm in mods:
            b = combos.index((s, mm)); r = slice(b * n, (b + 1) * n)
            cells.append(f"{rew[:, r].sum(0).mean():7.1f} [{100*last['overshoot'][r].mean():5.0f}, {last['reached_short_mode'][r].mean():4.2f}]")
        print(f"{s:5.3f}  " + " ".join(f"{x:>22s}" for x in cells))


if __name__ == "__main__":
    main(sys.argv[1:])
