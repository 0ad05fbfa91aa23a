"""Diagnostic: the budgeted modal MPC's after-stop plan against the oracle at the same measured overshoot
(docs/rl.md, "Why the budgeted modal MPC's plan was far from the oracle").

Per window of nominal 1000-1019 on the exact-mode link: the MPC's measured overshoot, energy after the stop, the
oracle's energy at that overshoot (the solve of ``compare``'s gap: cached), the gap, and where the two sequences
differ: the step of the peak ratio, the duty / I2 along the first steps after the stop, the step at which each
reaches d = 1, the energy delivered in the first 2 / 5 / 10 ms after the stop.

    python benchmarks/diag_mpc_modal_plan.py [--policies mpc:0.05,mpc:0.1] [--windows 20] [--save out/x.npz]
"""

from __future__ import annotations

import argparse

import numpy as np


def per_window(name, cfg, windows=20, seed=1000):
    from envs.rollout import DutyRollout
    from policies.compare import run_policy
    from policies.oracle import oracle_window
    tr = run_policy(name, "nominal", windows, seed, cfg)
    m = tr.metrics
    rows, seqs = [], []
    for i in range(windows):
        o = oracle_window("nominal", seed + i, max(m["overshoot_pct"][i], 0.0) / 100.0,
                          starts=("model_based_budget:0.01",), config=cfg, extra_starts=(tr.d_short[:, i],))
        roll = DutyRollout("nominal", seed + i, cfg)
        r = roll.run(np.stack([tr.d_short[:, i], o.duties]))
        k0 = roll.stop_k
        e = r.energy_j[:, k0:]
        ce = np.cumsum(e, axis=1)
        rat = r.ratios
        dd = np.stack([tr.d_short[k0:, i], o.duties[k0:]])
        full = [int(np.argmax(x >= 0.999)) if np.any(x >= 0.999) else -1 for x in dd]
        rows.append(dict(seed=seed + i, over=m["overshoot_pct"][i], e=m["energy_after_stop_j"][i],
                         e_or=o.energy_after_stop_j, over_or=100 * o.overshoot,
                         gap=100 * (m["energy_after_stop_j"][i] - o.energy_after_stop_j) / m["energy_after_stop_j"][i],
                         kpk=np.argmax(rat, axis=1), full=full, e2=ce[:, 19], e5=ce[:, 49], e10=ce[:, 99],
                         d_stop=tr.d_short[k0 - 1, i]))
        seqs.append(dict(d=dd, rat=rat, e=e, i2=r.i2_peak_a[:, k0:], sm=roll.i2_sm_a[k0:]))
    return rows, seqs


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--policies", default="mpc:0.05,mpc:0.1")
    ap.add_argument("--windows", type=int, default=20)
    ap.add_argument("--save", default=None)
    a = ap.parse_args(argv)
    from envs import EnvConfig
    cfg = EnvConfig(link_model="modal")
    saved = {}
    for name in a.policies.split(","):
        rows, seqs = per_window(name, cfg, a.windows)
        g = np.array([r["gap"] for r in rows])
        print(f"{name}: overshoot {np.mean([r['over'] for r in rows]):.2f} %, E {np.mean([r['e'] for r in rows]):.4f} J, "
              f"oracle {np.mean([r['e_or'] for r in rows]):.4f} J, gap mean {g.mean():.1f} % (median {np.median(g):.1f})")
        print("  seed   d_stop over%  E J     E_or J  gap%  | pk step mpc/or | d=1 step mpc/or | E@2ms mpc/or  E@5ms mpc/or  E@10ms mpc/or")
        for r in rows:
            print(f"  {r['seed']} {r['d_stop']:.3f} {r['over']:5.2f} {r['e']:.4f} {r['e_or']:.4f} {r['gap']:5.1f} | "
                  f"{r['kpk'][0]:4d} {r['kpk'][1]:4d} | {r['full'][0]:4d} {r['full'][1]:4d} | "
                  f"{r['e2'][0]:.4f} {r['e2'][1]:.4f}  {r['e5'][0]:.4f} {r['e5'][1]:.4f}  {r['e10'][0]:.4f} {r['e10'][1]:.4f}")
        saved[name] = (rows, seqs)
    if a.save:
        import pickle
        with open(a.save, "wb") as f:
            pickle.dump(saved, f)


if __name__ == "__main__":
    main()
