"""A retrained seed set against the shipped one, on the same windows in the same run (paired).

Runs (:func:`policies.compare.run_policies`, the closed loop of ``dronewpt compare``: one batched env, the
same seeded windows ``seed + i`` for every policy) the references, every seed of the shipped set and every
seed of the new set on one scenario, and prints per policy (sets: mean over the seed means with a Student t
95 % interval over seeds; references: bootstrap over windows) the measured overshoot %, the fraction in
short mode (sets: the lowest seed's), the energy after the stop and the return; then the new set minus the
shipped set, two ways:

* ``welch``: difference of the two sets' means of seed means, Welch t interval over the two sets of seed means
  (the training-seed uncertainty: new and shipped seeds are independent trainings, not pairs);
* ``paired``: per window the mean over the new seeds minus the mean over the shipped seeds, bootstrap over
  windows (the window-to-window uncertainty, on the same windows).

    python benchmarks/eval_retrained.py --kind slow_budget --new 'out/modal/slow_budget_s*/ppo_sbar.zip' \
        --old 'policies/pretrained/slow_budget_s*.zip' --refs model_based,mpc --link modal --json out/x.json
"""

from __future__ import annotations

import argparse
import glob
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

KEYS = ("overshoot_pct", "reached_short_mode", "energy_after_stop_j", "return")


def welch(a, b) -> tuple:
    """``(mean(a) - mean(b), lo, hi)``: Welch t 95 % interval of the difference of two means."""
    from scipy.stats import t as student_t
    a, b = np.asarray(a, float), np.asarray(b, float)
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)
    d = float(a.mean() - b.mean())
    se = math.sqrt(va + vb)
    if se == 0.0:
        return d, d, d
    df = (va + vb) ** 2 / (va ** 2 / (len(a) - 1) + vb ** 2 / (len(b) - 1))
    h = float(student_t.ppf(0.975, df)) * se
    return d, d - h, d + h


def evaluate(kind, new, old, refs, scenario, episodes, seed, config) -> dict:
    from policies.compare import run_policies
    from policies.stats import mean_ci, seed_ci
    new_specs = [f"{kind}:{p}" for p in new]
    old_specs = [f"{kind}:{p}" for p in old]
    runs = run_policies([*refs, *old_specs, *new_specs], scenario, episodes, seed, config)
    rows = {}
    for r in refs:
        m = runs[r].metrics
        rows[r] = {k: mean_ci(m[k]) for k in KEYS}
        rows[r]["reached_short_mode"] = float(np.mean(m["reached_short_mode"]))
    per_window = {}
    for label, specs in (("shipped", old_specs), ("new", new_specs)):
        ms = [runs[s].metrics for s in specs]
        rows[label] = {k: seed_ci([np.mean(m[k]) for m in ms]) for k in KEYS}
        rows[label]["reached_short_mode"] = min(float(np.mean(m["reached_short_mode"])) for m in ms)
        rows[label]["per_seed"] = {k: [round(float(np.mean(m[k])), 4) for m in ms] for k in KEYS}
        per_window[label] = {k: np.mean([m[k] for m in ms], axis=0) for k in KEYS}
    diff = {}
    for k in ("overshoot_pct", "energy_after_stop_j", "return"):
        diff[k] = {"welch": welch(rows["new"]["per_seed"][k], rows["shipped"]["per_seed"][k]),
                   "paired": mean_ci(per_window["new"][k] - per_window["shipped"][k])}
    return {"rows": rows, "new_minus_shipped": diff}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kind", required=True)
    ap.add_argument("--new", required=True, help="glob of the retrained seeds' models")
    ap.add_argument("--old", required=True, help="glob of the shipped seeds' models")
    ap.add_argument("--refs", default="model_based")
    ap.add_argument("--scenario", default="nominal")
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--link", choices=("envelope", "modal"), default="modal")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    new, old = sorted(glob.glob(a.new)), sorted(glob.glob(a.old))
    if len(new) < 2 or len(old) < 2:
        print(f"eval_retrained: --new {a.new!r} / --old {a.old!r} match {len(new)} / {len(old)} files; valid: "
              f"two or more each", file=sys.stderr)
        return 2
    from envs import EnvConfig
    refs = [r for r in a.refs.split(",") if r]
    t0, c0, load0 = time.time(), time.process_time(), os.getloadavg()[0]
    res = evaluate(a.kind, new, old, refs, a.scenario, a.episodes, a.seed, EnvConfig(link_model=a.link))
    res.update(kind=a.kind, new=new, old=old, scenario=a.scenario, episodes=a.episodes, seed=a.seed, link=a.link,
               wall_s=round(time.time() - t0, 1), cpu_s=round(time.process_time() - c0, 1),
               load_avg_1min=[load0, os.getloadavg()[0]])
    for label, row in res["rows"].items():
        cells = []
        for k in KEYS:
            v = row[k]
            cells.append(f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v[0]:.3f} [{v[1]:.3f}, {v[2]:.3f}]")
        print(f"{label:>28}: " + " | ".join(cells))
        if "per_seed" in row:
            print(" " * 30 + "per seed: " + json.dumps(row["per_seed"]))
    for k, d in res["new_minus_shipped"].items():
        w, p = d["welch"], d["paired"]
        print(f"new - shipped {k}: {w[0]:+.3f} welch [{w[1]:+.3f}, {w[2]:+.3f}] paired-windows [{p[1]:+.3f}, {p[2]:+.3f}]")
    print(f"wall {res['wall_s']} s, CPU {res['cpu_s']} s, load {res['load_avg_1min']}")
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps(res, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
