"""CPU per stop of ``model_based_budget:b``'s search on the exact-mode link (:func:`policies.budget_modal.relaxation`),
in-process, on the real stops of nominal windows, beside an older ``policies/budget_modal.py`` in the same run.

The stops are captured in the closed loop (``model_based_budget:0.01`` on the modal env, ``--episodes`` nominal
windows from ``--seed``: the stop state, the controller's state, its last duty and the battery voltage, does not
depend on the budget). For each budget every stop's ``r*`` is computed by the current search (its plan cache
cleared before each stop, so no stop shares another's plans) and, with ``--baseline FILE`` (e.g. ``git show
aa14d7e:policies/budget_modal.py > /tmp/old.py``), by the old module loaded beside it, alternating stop by stop;
the two ``r*`` must be equal (a difference is printed and the exit status is 1). Process CPU time per stop:
median with the range; the load average before and after.

    python benchmarks/bench_budget_modal.py [--episodes 100] [--budgets 0.01,0.02,0.05,0.1] [--baseline OLD.py]
        [--save-rstar FILE.npy]

A change in :mod:`wpt_receiver.modal_kernel` (which both modules share) is timed by running this script on two
trees in turn (``PYTHONPATH``), alternating, each with ``--save-rstar``, and comparing the saved ``r*``.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def capture_stops(episodes: int, seed: int) -> list:
    """The arguments of :func:`policies.budget_modal.relaxation` after the budget, one tuple per real stop."""
    from envs import EnvConfig
    from policies import budget_modal as bm
    from policies.compare import run_policies
    caps, orig = [], bm.relaxation

    def spy(*a):
        caps.append(a[1:])
        return orig(*a)
    bm.relaxation = spy
    try:
        run_policies(["model_based_budget:0.01"], "nominal", episodes, seed, EnvConfig(link_model="modal"))
    finally:
        bm.relaxation = orig
    return caps


def _load(path: Path):
    spec = importlib.util.spec_from_file_location("policies._budget_modal_baseline", path)
    mod = importlib.util.module_from_spec(spec)
    mod.__package__ = "policies"
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def _cpu(f, *args):
    t = time.process_time()
    r = f(*args)
    return r, time.process_time() - t


def _summary(t) -> str:
    t = 1e3 * np.asarray(t)
    return f"median {np.median(t):.1f} ms [{t.min():.1f}, {t.max():.1f}]"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--budgets", default="0.01,0.02,0.05,0.1")
    ap.add_argument("--baseline", type=Path, default=None, help="an older policies/budget_modal.py to time beside")
    ap.add_argument("--save-rstar", type=Path, default=None,
                    help="write every (budget, stop) r* of the current search to this .npy (to compare two trees)")
    args = ap.parse_args(argv)
    from policies import budget_modal as bm
    old = _load(args.baseline) if args.baseline else None
    stops = capture_stops(args.episodes, args.seed)
    bm.relaxation(0.01, *stops[0])                      # compiled / loaded before timing
    if old is not None:
        old.relaxation(0.01, *stops[0])
    print(f"{len(stops)} stops of nominal windows {args.seed}..{args.seed + args.episodes - 1}; load {os.getloadavg()}")
    differ, rstars = 0, []
    for budget in (float(b) for b in args.budgets.split(",")):
        t_new, t_old, n_diff = [], [], 0
        for i, stop in enumerate(stops):
            if old is not None:
                r_old, t = _cpu(old.relaxation, budget, *stop)
                t_old.append(t)
            bm._STOPS.clear()
            r_new, t = _cpu(bm.relaxation, budget, *stop)
            t_new.append(t)
            rstars.append(r_new)
            if old is not None and r_old != r_new:
                n_diff += 1
                print(f"  b={budget} stop {i}: r* {r_old} (baseline) != {r_new}")
        line = f"b={budget:g}: current {_summary(t_new)}"
        if old is not None:
            line += f"; baseline {_summary(t_old)} ({np.median(t_old) / np.median(t_new):.1f}x); r* differing: {n_diff}"
        print(line + f"; load {os.getloadavg()[0]:.2f}", flush=True)
        differ += n_diff
    if args.save_rstar is not None:
        np.save(args.save_rstar, np.asarray(rstars, dtype=float))
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
