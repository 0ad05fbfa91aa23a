"""Issue 21: the sign of dQ/da along a policy's own after-stop trajectory (no learning).

A policy (default rl_s0) runs closed loop on nominal windows 1000..1099; in each block the duty of ONE
after-stop step j (offset from the stop step) is raised by DELTA (the policy then reacts as it would),
and the change of the return from the stop step (discounts 0.98 / 0.995 / 1) against the unperturbed
run is split into the tracking (-I_L / i_ref) and the overcurrent terms: what PPO's per-step advantage
of "a bit more duty here" sees.

    python benchmarks/diag_rl_after_stop_q.py rl:policies/pretrained/rl_s0.zip 0.05
"""

from __future__ import annotations

import sys

import numpy as np

OFFSETS = (0, 1, 2, 5, 10, 20, 40, 80)


def main(argv):
    from envs import SbarChargingVectorEnv
    from envs import EnvConfig   # these diagnostics measured eq. 4's env (the default until 2026-11-26)
    from envs.objective import stop_step
    from policies import make

    base = argv[0] if argv else "rl:policies/pretrained/rl_s0.zip"
    delta = float(argv[1]) if len(argv) > 1 else 0.05
    n, B = 100, len(OFFSETS) + 1
    venv = SbarChargingVectorEnv(num_envs=n * B, scenario="nominal", config=EnvConfig(link_model="envelope"))
    c = venv.config
    pol = make(base, venv.policy_context)
    pol.reset(venv.num_envs)
    obs, info = venv.reset(seed=[1000 + i for i in range(n)] * B)
    T = c.n_steps
    ks = stop_step(info["t_stop_s"], c.dt_s, T)
    off = np.repeat([-10**6, *OFFSETS], n)     # block 0: unperturbed
    rew, il, pk = (np.zeros((T, n * B)) for _ in range(3))
    for k in range(T):
        d = np.clip(np.asarray(pol.act(obs), float).reshape(-1), 0, 1)
        d = np.where(k - ks == off, np.minimum(1.0, d + delta), d)
        obs, r, te, tr, last = venv.step((2 * d - 1)[:, None].astype(np.float32))
        rew[k], il[k], pk[k] = r, last["rect_current_a"], np.abs(last["i2_peak_a"])
    w = c.reward
    over = -w.overcurrent * np.maximum(0.0, pk / c.rated_i2_a - 1.0)
    track = -il / w.i_ref_a
    kk = np.arange(T)[:, None]
    print(f"{base}, nominal 1000..1099, +{delta} duty at one after-stop step j; change of the return from the "
          f"stop step against the unperturbed run, mean over windows (tracking / overcurrent)")
    print(f"{'j':>4s} " + " ".join(f"{'G ' + str(g):>24s}" for g in (0.98, 0.995, 1.0)))
    for b, j in enumerate(OFFSETS, start=1):
        rows, ref = slice(b * n, (b + 1) * n), slice(0, n)
        cells = []
        for g in (0.98, 0.995, 1.0):
            wgt = np.where(kk >= ks[None, rows], g ** np.clip(kk - ks[None, rows], 0, None), 0.0)
            dt_ = ((track[:, rows] - track[:, ref]) * wgt).sum(0).mean()
            do_ = ((over[:, rows] - over[:, ref]) * wgt).sum(0).mean()
            cells.append(f"{dt_ + do_:+7.3f} ({dt_:+.3f}/{do_:+.3f})")
        print(f"{j:4d} " + " ".join(f"{x:>24s}" for x in cells))


if __name__ == "__main__":
    main(sys.argv[1:])
