"""Why the retrained unconstrained PPO (`rl`) parks the duty near 0.7 after the stop (issue 21).

No learning: the env is stepped directly. Before the stop every row runs the paper's
``model_based`` controller (deterministic, the same for every candidate); from the first step
scored against the stop (``envs.objective.stop_step``) each block replays one open-loop after-stop
duty sequence: hold a constant duty (0.7 is where `rl` parks), ramp from the last pre-stop duty to
1 over 1 / 3 / 10 ms, step to 1. Printed per sequence (mean over the windows): the undiscounted
return split before / after the stop, the after-stop return split into its tracking term
(``-I_L / i_ref``: the command is 0) and its overcurrent penalty (``-10 max(0, |I2_pk| / 15 - 1)``),
the discounted return from the stop step for gamma 0.98 / 0.995 / 0.999, overshoot, short mode, E
after the stop. ``--noise SIGMA`` adds PPO-like Gaussian exploration noise (std in action units,
the policy's ``exp(log_std)``; action clipped to [-1, 1]) after the stop, around the sequence's
action (``--mean-offset`` moves the mean beyond the bound, as an unbounded Gaussian mean can), to
see what the stochastic rollouts PPO learns from make of each sequence.

    python benchmarks/diag_rl_after_stop.py --episodes 100 --seed 1000
    python benchmarks/diag_rl_after_stop.py --noise 0.223
"""

from __future__ import annotations

import argparse

import numpy as np


def sequences(dt_s: float) -> dict:
    """name -> f(j, d0): after-stop duty at step j (0 = the first step scored against the stop)."""
    def ramp(ms, to=1.0):
        n = max(1, int(round(ms * 1e-3 / dt_s)))
        return lambda j, d0: d0 + (to - d0) * np.minimum(1.0, (j + 1) / n)
    seq = {f"hold {h:.2f}": (lambda h: lambda j, d0: np.full_like(d0, h))(h) for h in (0.6, 0.7, 0.8, 0.9, 0.95)}
    seq.update({"ramp .7 1ms": ramp(1, 0.7), "ramp .7 3ms": ramp(3, 0.7), "ramp 10 ms": ramp(10), "ramp 3 ms": ramp(3), "ramp 1 ms": ramp(1),
                "step to 1": lambda j, d0: np.ones_like(d0)})
    return seq


def run(episodes: int, seed: int, scenario: str, noise: float, mean_offset: float, noise_seed: int = 0):
    from envs import SbarChargingVectorEnv
    from envs import EnvConfig   # these diagnostics measured eq. 4's env (the default until 2026-11-26)
    from envs.objective import stop_step
    from policies import make

    venv = SbarChargingVectorEnv(num_envs=1, scenario=scenario, config=EnvConfig(link_model="envelope"))
    seqs = sequences(venv.config.dt_s)
    names = list(seqs)
    n, B = episodes, len(names)
    venv = SbarChargingVectorEnv(num_envs=n * B, scenario=scenario, config=EnvConfig(link_model="envelope"))
    c = venv.config
    pol = make("model_based", venv.policy_context)
    pol.reset(venv.num_envs)
    obs, info = venv.reset(seed=[seed + i for i in range(n)] * B)
    T = c.n_steps
    k_stop = stop_step(info["t_stop_s"], c.dt_s, T)
    rng = np.random.default_rng(noise_seed)
    rew, il, pk, e = (np.zeros((T, n * B)) for _ in range(4))
    d0 = np.zeros(n * B)
    for k in range(T):
        d_mb = np.clip(np.asarray(pol.act(obs), float).reshape(-1), 0.0, 1.0)
        j = k - k_stop
        after = j >= 0
        d = d_mb.copy()
        for b, name in enumerate(names):
            rows = slice(b * n, (b + 1) * n)
            d[rows] = np.where(after[rows], seqs[name](np.maximum(j[rows], 0), d0[rows]), d_mb[rows])
        a = 2.0 * d - 1.0
        if noise > 0:
            a = np.where(after, np.clip(a + mean_offset * (d >= 1.0) + noise * rng.standard_normal(a.shape), -1, 1), a)
        d0 = np.where(after, d0, d_mb)   # the last pre-stop duty, frozen at the stop
        obs, r, term, trunc, last = venv.step(a[:, None].astype(np.float32))
        rew[k], il[k], pk[k], e[k] = r, last["rect_current_a"], np.abs(last["i2_peak_a"]), last["energy_j"]
    venv.close()
    w = c.reward
    kk = np.arange(T)[:, None]
    after = kk >= k_stop[None, :]
    over = -w.overcurrent * np.maximum(0.0, pk / c.rated_i2_a - 1.0)
    out = {}
    for b, name in enumerate(names):
        rows = slice(b * n, (b + 1) * n)
        A = after[:, rows]
        disc = {}
        for g in (0.98, 0.995, 0.999):
            gk = g ** np.clip(kk - k_stop[None, rows], 0, None)
            disc[g] = (np.where(A, rew[:, rows] * gk, 0.0)).sum(0).mean()
        out[name] = dict(
            ret=rew[:, rows].sum(0).mean(), before=np.where(A, 0, rew[:, rows]).sum(0).mean(),
            after=np.where(A, rew[:, rows], 0).sum(0).mean(), over_pen=np.where(A, over[:, rows], 0).sum(0).mean(),
            track=np.where(A, -il[:, rows] / w.i_ref_a, 0).sum(0).mean(), disc=disc,
            overshoot=100 * last["overshoot"][rows].mean(), sm=last["reached_short_mode"][rows].mean(),
            e_after=np.where(A, e[:, rows], 0).sum(0).mean(), il_end=il[-1, rows].mean(),
            steps_after=(T - k_stop[rows]).mean())
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--scenario", default="nominal")
    ap.add_argument("--noise", type=float, default=0.0, help="Gaussian action noise std after the stop (action units)")
    ap.add_argument("--mean-offset", type=float, default=0.0, help="action mean beyond +1 where the duty is 1")
    a = ap.parse_args(argv)
    out = run(a.episodes, a.seed, a.scenario, a.noise, a.mean_offset)
    print(f"{a.scenario}, windows {a.seed}..{a.seed + a.episodes - 1}, model_based before the stop, noise {a.noise}"
          f" (mean offset {a.mean_offset}); mean over windows; after-stop steps "
          f"{next(iter(out.values()))['steps_after']:.1f}")
    print(f"{'after stop':12s} {'return':>7s} {'before':>7s} {'after':>7s} {'-I_L/7':>7s} {'overcur':>7s} "
          f"{'G.98':>6s} {'G.995':>6s} {'G.999':>6s} {'ovs %':>6s} {'SM':>5s} {'E_aft J':>7s} {'I_L end':>7s}")
    for name, m in out.items():
        print(f"{name:12s} {m['ret']:7.1f} {m['before']:7.1f} {m['after']:7.1f} {m['track']:7.1f} {m['over_pen']:7.2f} "
              f"{m['disc'][0.98]:6.2f} {m['disc'][0.995]:6.2f} {m['disc'][0.999]:6.2f} {m['overshoot']:6.1f} "
              f"{m['sm']:5.2f} {m['e_after']:7.3f} {m['il_end']:7.3f}")


if __name__ == "__main__":
    main()
