"""Calibration of ``model_based_budget:b`` on both links: measured overshoot, the same above each window's
oracle floor (:func:`policies.oracle.oracle_floor`, the paper's controller's state at the stop, on that link's
env), energy after the stop, short-mode fraction; 95 % bootstrap intervals over the windows
(:func:`policies.stats.mean_ci`). On the modal link both the plan predicted with the exact-mode link (the
policy as it is, :mod:`policies.budget_modal`) and eq. 4's relaxation (``model_based_budget_eq4:b``: the same
class with ``eq4_relaxation=True``, i.e. the policy before 2026-11-26) run side by side in one batched env.

    nice -n 10 python benchmarks/eval_budget_calibration.py --episodes 100 --out out/budget_calibration.json
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

BUDGETS = (0.0, 0.01, 0.02, 0.05, 0.1)


def _eq4_factory(ctx, budget=0.02, **kw):
    from policies.budgeted import BudgetedModelBasedPolicy
    return BudgetedModelBasedPolicy(ctx, budget=budget, eq4_relaxation=True, **kw)


def _names(link):
    names = [f"model_based_budget:{b:g}" for b in BUDGETS]
    return names + ([f"model_based_budget_eq4:{b:g}" for b in BUDGETS] if link == "modal" else [])


def _make_patch():
    """``policies.make`` understands ``model_based_budget_eq4:B`` (registered for this script only)."""
    import policies
    policies.register("model_based_budget_eq4", _eq4_factory)
    make = policies.make

    def patched(name, ctx=None, **kw):
        base, _, arg = name.partition(":")
        if base == "model_based_budget_eq4":
            return _eq4_factory(ctx or policies.PolicyContext(), budget=float(arg), **kw)
        return make(name, ctx, **kw)
    policies.make = patched


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--links", default="envelope,modal")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    from tqdm import tqdm

    from envs import EnvConfig
    from policies.compare import run_policies
    from policies.oracle import oracle_floor
    from policies.stats import mean_ci
    _make_patch()
    rows = []
    for link in args.links.split(","):
        cfg = EnvConfig(link_model=link)
        t0 = time.perf_counter()
        tr = run_policies(_names(link), "nominal", args.episodes, args.seed, cfg)
        t_run = time.perf_counter() - t0
        floors = np.array([100.0 * oracle_floor("nominal", args.seed + i, cfg).overshoot
                           for i in tqdm(range(args.episodes), desc=f"floors {link}")])
        print(f"{link}: policies {t_run:.1f} s wall, load {os.getloadavg()[0]:.2f}; floor mean {floors.mean():.3f} % "
              f"({floors.min():.2f}-{floors.max():.2f})", flush=True)
        for name, t in tr.items():
            m = t.metrics
            o, e = np.asarray(m["overshoot_pct"]), np.asarray(m["energy_after_stop_j"])
            row = {"link": link, "policy": name, "overshoot_pct": mean_ci(o), "above_floor_pts": mean_ci(o - floors),
                   "energy_after_stop_j": mean_ci(e), "short_mode": float(np.mean(m["reached_short_mode"])),
                   "floor_pct": float(floors.mean())}
            rows.append(row)
            print(f"  {name:28s} overshoot {row['overshoot_pct'][0]:6.2f} % [{row['overshoot_pct'][1]:.2f}, "
                  f"{row['overshoot_pct'][2]:.2f}]  above floor {row['above_floor_pts'][0]:5.2f} pts "
                  f"[{row['above_floor_pts'][1]:.2f}, {row['above_floor_pts'][2]:.2f}]  E after stop "
                  f"{row['energy_after_stop_j'][0]:.3f} J [{row['energy_after_stop_j'][1]:.3f}, "
                  f"{row['energy_after_stop_j'][2]:.3f}]  short mode {row['short_mode']:.2f}", flush=True)
    if args.out:
        from pathlib import Path
        p = Path(args.out)
        p.parent.mkdir(parents=True, exist_ok=True)
        tmp = p.with_suffix(".tmp")
        tmp.write_text(json.dumps(rows, indent=1))
        os.replace(tmp, p)


if __name__ == "__main__":
    main()
