"""What the modal plan of ``model_based_budget`` (:mod:`policies.budget_modal`) changes for the policies built on
it, on the modal env: ``residual`` and ``imitation`` (their shipped seeds correct ``model_based_budget:0.01``),
before (the base with eq. 4's relaxation r = b, as before 2026-11-26) and after (the base's modal plan), on the
same windows; measured overshoot, energy after the stop, short mode, return, with 95 % bootstrap intervals and
the paired difference after - before. Nothing is retrained.

    nice -n 10 python benchmarks/eval_wrapped_budget_modal.py --episodes 100
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def _run(names, episodes, seed, eq4: bool):
    from envs import EnvConfig
    from policies import budgeted
    from policies.compare import run_policies
    init = budgeted.BudgetedModelBasedPolicy.__init__

    def patched(self, *a, **kw):   # the bases built inside residual / imitation take the option too
        init(self, *a, **{"eq4_relaxation": eq4, **kw})
    budgeted.BudgetedModelBasedPolicy.__init__ = patched
    try:
        return run_policies(names, "nominal", episodes, seed, EnvConfig(link_model="modal"))
    finally:
        budgeted.BudgetedModelBasedPolicy.__init__ = init


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--policies", default="residual,imitation,model_based_budget:0.01")
    args = ap.parse_args(argv)
    from policies.stats import mean_ci
    names = args.policies.split(",")
    t0 = time.perf_counter()
    before = _run(names, args.episodes, args.seed, eq4=True)
    after = _run(names, args.episodes, args.seed, eq4=False)
    print(f"{time.perf_counter() - t0:.1f} s wall, load {os.getloadavg()[0]:.2f}")
    for n in names:
        for label, tr in (("before", before[n]), ("after", after[n])):
            m = tr.metrics
            o, e = mean_ci(m["overshoot_pct"]), mean_ci(m["energy_after_stop_j"])
            ret = mean_ci(m["return"]) if "return" in m else (float("nan"),) * 3
            print(f"{n:26s} {label:6s} overshoot {o[0]:6.2f} % [{o[1]:.2f}, {o[2]:.2f}]  E after stop {e[0]:.3f} J "
                  f"[{e[1]:.3f}, {e[2]:.3f}]  short mode {np.mean(m['reached_short_mode']):.2f}  return {ret[0]:.1f} "
                  f"[{ret[1]:.1f}, {ret[2]:.1f}]")
        d = mean_ci(after[n].metrics["overshoot_pct"] - before[n].metrics["overshoot_pct"])
        de = mean_ci(after[n].metrics["energy_after_stop_j"] - before[n].metrics["energy_after_stop_j"])
        print(f"{n:26s} paired after - before: overshoot {d[0]:+.2f} pts [{d[1]:+.2f}, {d[2]:+.2f}], "
              f"E after stop {de[0]:+.3f} J [{de[1]:+.3f}, {de[2]:+.3f}]")


if __name__ == "__main__":
    main()
