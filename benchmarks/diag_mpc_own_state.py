"""Diagnostic: split the modal MPC's gap to the oracle (docs/rl.md, "Why the budgeted modal MPC's plan was far from
the oracle") into the after-stop plan's part and the state at the stop's part.

Per window of nominal 1000-1019 on the exact-mode link, at the MPC's measured overshoot: the oracle of ``compare``'s gap
(started from the MPC's own sequence *and* from ``model_based_budget:0.01``'s, i.e. from either state at the stop),
and the oracle started from the MPC's own sequence only (the MPC's state at the stop: what its after-stop plan could
reach). Both cached (:func:`policies.oracle.oracle_window`).

    python benchmarks/diag_mpc_own_state.py [--policies mpc:0.05,mpc:0.1] [--windows 20]
"""

from __future__ import annotations

import argparse

import numpy as np


def split(name, cfg, windows=20, seed=1000):
    from policies.compare import run_policy
    from policies.oracle import oracle_window
    tr = run_policy(name, "nominal", windows, seed, cfg)
    m, rows = tr.metrics, []
    for i in range(windows):
        b = max(m["overshoot_pct"][i], 0.0) / 100.0
        both = oracle_window("nominal", seed + i, b, starts=("model_based_budget:0.01",), config=cfg,
                             extra_starts=(tr.d_short[:, i],))
        own = oracle_window("nominal", seed + i, b, starts=(), config=cfg, extra_starts=(tr.d_short[:, i],))
        e = m["energy_after_stop_j"][i]
        rows.append((seed + i, m["overshoot_pct"][i], e, own.energy_after_stop_j, both.energy_after_stop_j))
    r = np.array(rows)
    g_own, g_both = 100 * (r[:, 2] - r[:, 3]) / r[:, 2], 100 * (r[:, 2] - r[:, 4]) / r[:, 2]
    print(f"{name}: overshoot {r[:, 1].mean():.2f} %, E {r[:, 2].mean():.4f} J; gap to the oracle from its own state "
          f"{g_own.mean():.1f} % (max {g_own.max():.1f}), from either state (compare's) {g_both.mean():.1f} % (max {g_both.max():.1f})")
    for x, a, b in zip(rows, g_own, g_both):
        print("   %d  %.2f %%  E %.4f  E_own %.4f  E_either %.4f   gap own %.1f %%  either %.1f %%" % (*x, a, b))
    return r


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--policies", default="mpc:0.05,mpc:0.1")
    ap.add_argument("--windows", type=int, default=20)
    ap.add_argument("--link", default="modal", choices=("envelope", "modal"))
    a = ap.parse_args(argv)
    from envs import EnvConfig
    for name in a.policies.split(","):
        split(name, EnvConfig(link_model=a.link), a.windows)


if __name__ == "__main__":
    main()
