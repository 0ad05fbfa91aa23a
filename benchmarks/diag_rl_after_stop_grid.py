"""Issue 21, `rl` parks at d ~ 0.7: the return landscape of after-stop duty sequences (no learning).

Before the stop the policy BASE (e.g. model_based, rl:policies/pretrained/rl_s0.zip) runs; after it
each block replays "ramp over R ms from the last pre-stop duty to level h, then hold" or lifts BASE's own
after-stop duty towards 1 (d = base + x (1 - base)). 100 windows seeded 1000..1099.

    python benchmarks/diag_rl_after_stop_grid.py model_based nominal
"""

from __future__ import annotations

import sys

import numpy as np


def main(argv):
    from envs import SbarChargingVectorEnv
    from envs import EnvConfig   # these diagnostics measured eq. 4's env (the default until 2026-11-26)
    from envs.objective import stop_step
    from policies import make

    base = argv[0]; scen = argv[1] if len(argv) > 1 else "nominal"
    levels = [0.6, 0.7, 0.8, 0.9, 0.95, 1.0]; ramps = [0.3, 1, 2, 3, 5]
    # mode "lift": after the stop d = base + x (1 - base), x in lifts
    lifts = [0.0, 0.1, 0.25, 0.5, 0.75, 1.0]
    combos = [("ramp", R, h) for R in ramps for h in levels] + [("lift", x, None) for x in lifts]
    n = 100; B = len(combos)
    venv = SbarChargingVectorEnv(num_envs=n * B, scenario=scen, config=EnvConfig(link_model="envelope"))
    c = venv.config
    pol = make(base, venv.policy_context); pol.reset(venv.num_envs)
    obs, info = venv.reset(seed=[1000 + i for i in range(n)] * B)
    T = c.n_steps; ks = stop_step(info["t_stop_s"], c.dt_s, T)
    rew = np.zeros((T, n * B)); d0 = np.zeros(n * B)
    for k in range(T):
        db = np.clip(np.asarray(pol.act(obs), float).reshape(-1), 0, 1)
        j = k - ks; aft = j >= 0; d = db.copy()
        for b, (m, p, h) in enumerate(combos):
            r = slice(b * n, (b + 1) * n)
            if m == "ramp":
                N = max(1, round(p * 10)); x = d0[r] + (h - d0[r]) * np.minimum(1, (j[r] + 1) / N)
            else:
                x = db[r] + p * (1 - db[r])
            d[r] = np.where(aft[r], x, db[r])
        d0 = np.where(aft, d0, db)
        obs, rr, te, tr, last = venv.step((2 * d - 1)[:, None].astype(np.float32)); rew[k] = rr
    print(f"{scen}, windows 1000..1099, before the stop: {base}; return (overshoot %, in SM)")
    print("ramp ms \\ level " + " ".join(f"{h:>17.2f}" for h in levels))
    for R in ramps:
        cells = []
        for h in levels:
            b = combos.index(("ramp", R, h)); r = slice(b * n, (b + 1) * n)
            cells.append(f"{rew[:, r].sum(0).mean():6.1f} ({100*last['overshoot'][r].mean():4.0f},{last['reached_short_mode'][r].mean():4.2f})")
        print(f"{R:>15} " + " ".join(cells))
    print("lift x (d = base + x (1 - base) after the stop):")
    for x in lifts:
        b = combos.index(("lift", x, None)); r = slice(b * n, (b + 1) * n)
        print(f"  x={x:4.2f} return {rew[:, r].sum(0).mean():6.1f} overshoot {100*last['overshoot'][r].mean():5.1f} SM {last['reached_short_mode'][r].mean():.2f}")


if __name__ == "__main__":
    main(sys.argv[1:])
