"""Diagnostic: the oracle's search near the floor on the exact-mode link (docs/rl.md, "Issue 21's must-shows
on the exact-mode link").

1. Per window of nominal 1000-1019 (cached solves after ``eval_slow_budget.py --link modal --oracle-windows 20``):
   the oracle's floor, a policy's measured overshoot, its energy after the stop and the oracle's at that overshoot.
2. On one window, the same search (``policies.oracle._Problem``) from the same policy's sequence on eq. 4 and on the
   modal link: how far it moves, and the measured overshoot along the first basis directions (its kink).

The stall this showed (floor 2.53 % against eq. 4's 1.63 %) was the forward-difference step: 2e-3 in x against
the modal link's per-step peaks, kinked on that scale; the oracle differences with 1e-4 on that link since
2026-11-26 (``policies.oracle._fd_step``; docs/rl.md, "Why the oracle stalled on the exact-mode link").

    python benchmarks/diag_oracle_modal.py [--policies oracle_imitation:PATH,mpc] [--window 1]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def per_window(name, cfg, windows=20, seed=1000):
    from policies.compare import run_policy
    from policies.oracle import oracle_floor, oracle_window
    tr = run_policy(name, "nominal", windows, seed, cfg)
    m, rows = tr.metrics, []
    for i in range(windows):
        o = oracle_window("nominal", seed + i, max(m["overshoot_pct"][i], 0.0) / 100.0,
                          starts=("model_based_budget:0.01",), config=cfg, extra_starts=(tr.d_short[:, i],))
        f = oracle_floor("nominal", seed + i, cfg)
        e = m["energy_after_stop_j"][i]
        rows.append((100 * f.overshoot, m["overshoot_pct"][i], e, o.energy_after_stop_j, 100 * (e - o.energy_after_stop_j) / e))
    r = np.array(rows)
    print(f"{name}: floor {r[:, 0].mean():.2f} %, policy {r[:, 1].mean():.2f} %, policy below the floor in "
          f"{int((r[:, 1] < r[:, 0]).sum())} of {windows} windows, gap <= 0.2 % in {int((r[:, 4] <= 0.2).sum())}, "
          f"gap mean {r[:, 4].mean():.1f} % (max {r[:, 4].max():.1f})")
    for x in rows:
        print("   floor %.2f %%  policy %.2f %%  E %.3f J  E_oracle %.3f J  gap %.1f %%" % x)


def one_window(name, link, i, seed=1000):
    from envs import EnvConfig
    from envs.rollout import DutyRollout
    from policies import oracle as O
    from policies.compare import run_policy
    cfg = EnvConfig(link_model="modal" if link == "modal" else "envelope")
    tr = run_policy(name, "nominal", i + 1, seed, cfg)
    P = O._Problem(DutyRollout("nominal", seed + i, cfg), tr.d_short[:, i], tr.metrics["overshoot_pct"][i] / 100)
    r0 = P.roll.run(P.duties(np.zeros((1, O.N_BASIS))))
    t = time.process_time()
    best = P.solve()
    print(f"{link}: window {seed + i}, from {name}'s sequence: E {r0.energy_after_stop_j[0]:.4f} J at "
          f"{100 * r0.overshoot[0]:.2f} % -> {best.energy_after_stop_j:.4f} J at {100 * best.overshoot:.2f} % "
          f"({100 * (1 - best.energy_after_stop_j / r0.energy_after_stop_j[0]):.2f} % less; {time.process_time() - t:.1f} s CPU)")
    for k in range(3):
        xs = np.zeros((5, O.N_BASIS))
        xs[:, k] = [-2e-3, -1e-3, 0.0, 1e-3, 2e-3]
        rr = P.roll.run(P.duties(xs))
        print(f"   basis {k}, x = -2e-3..2e-3: overshoot % {np.round(100 * rr.overshoot, 3)}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--policies", default="oracle_imitation:policies/pretrained/oracle_imitation_s1.npz,mpc")
    ap.add_argument("--window", type=int, default=1)
    a = ap.parse_args(argv)
    from envs import EnvConfig
    for name in a.policies.split(","):
        per_window(name, EnvConfig(link_model="modal"))
    name = a.policies.split(",")[0]
    for link in ("envelope", "modal"):
        one_window(name, link, a.window)


if __name__ == "__main__":
    main()
