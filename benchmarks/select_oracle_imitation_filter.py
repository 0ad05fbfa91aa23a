"""Select ``oracle_imitation_filtered``'s setting on validation windows, against the MPC, by the rule written in
docs/rl.md ("A safety filter on the learned after-stop sequence"; the rule of "Re-selecting the playback").

    python benchmarks/select_oracle_imitation_filter.py --scenarios sense_delay,battery_low --seed 300 --episodes 100 \\
        --json out/goal2/select.json

Every setting of :data:`GRID` (the unfiltered maps re-timed, the frontier to beat, and the filter's corrections) runs
with each of the five shipped maps (``--models``) on the same windows as the reference ``mpc`` (its own run, the same
windows: runs are per window); per setting and scenario the mean over the maps of the paired overshoot difference
(points) and return difference, the pooled window bootstrap, the fraction in short mode (min over the maps); then the
rule (:func:`select_oracle_imitation_playback.choose`) at ``--margin`` and, if nothing is admissible, at 0.
Validation windows only: ``--seed`` must keep off the training (0-79) and evaluation (1000-1099, 2000-2099) windows.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

_FINE = (1.0, 0.97, 0.94, 0.91, 0.88, 0.85, 0.82, 0.79, 0.76)
#: label -> None (the unfiltered map) or the filter's options; ``slow`` re-times the map in both
GRID = {
    "clone slow=1.0": {"slow": 1.0},
    "clone slow=1.1": {"slow": 1.1},
    "clone slow=1.2": {"slow": 1.2},
    "rate limit=0.004": {"filter": dict(correction="rate", limit=0.004, lam=None, slow=1.0, rates=_FINE)},
    **{f"rate lam={lam:g}": {"filter": dict(correction="rate", lam=lam, slow=1.0, rates=_FINE)} for lam in (0.4, 0.6)},
    "qp stop limit=0 slow=1": {"filter": dict(correction="qp", limit=0.0, slow=1.0, smooth=300.0, every_period=False)},
    "qp every limit=0.006 slow=1.1": {"filter": dict(correction="qp", limit=0.006, slow=1.1, smooth=300.0,
                                                     every_period=True)},
}


def factory(path, spec):
    """A :func:`policies.register` factory of ``spec`` (a :data:`GRID` value) with the map ``path``."""
    def make(ctx, **kwargs):
        if "filter" in spec:
            from policies.oracle_imitation_filter import OracleImitationFilteredPolicy
            return OracleImitationFilteredPolicy(ctx, path=path, **spec["filter"])
        from policies.oracle_imitation import OracleImitationPolicy
        pol = OracleImitationPolicy(ctx, path=path)
        pol.model["slow"] = np.array(float(spec["slow"]))
        return pol
    return make


def main(argv=None):
    from select_oracle_imitation_playback import choose, row_stats, validation_windows

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--models", default="policies/pretrained/oracle_imitation_s*.npz")
    ap.add_argument("--scenarios", default="sense_delay,battery_low")
    ap.add_argument("--settings", default="", help="comma-separated labels of GRID (default: all)")
    ap.add_argument("--ref", default="mpc")
    ap.add_argument("--seed", type=int, default=300)
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--margin", type=float, default=0.10)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    lo, hi = validation_windows(ap, a.seed, a.episodes)
    models = sorted(glob.glob(a.models))
    labels = [s for s in a.settings.split(",") if s] or list(GRID)
    bad = [s for s in labels if s not in GRID]
    if not models or bad:
        ap.error(f"--models {a.models!r} matches nothing, or --settings {bad!r} not in: {', '.join(GRID)}")
    from envs import EnvConfig
    from policies import register
    from policies.compare import run_policies
    config = EnvConfig(link_model="modal")
    t0, c0, l0 = time.time(), time.process_time(), os.getloadavg()
    names = {}
    for i, lab in enumerate(labels):
        names[lab] = []
        for k, p in enumerate(models):
            register(f"goal2_{i}_s{k}", factory(p, GRID[lab]))
            names[lab].append(f"goal2_{i}_s{k}")
    table = {lab: {} for lab in labels}
    for s in a.scenarios.split(","):
        ref = run_policies([a.ref], s, a.episodes, a.seed, config)[a.ref].metrics
        print(f"\n== {s}, windows {lo}-{hi - 1}; {a.ref}: overshoot {ref['overshoot_pct'].mean():.2f} %, "
              f"E after {ref['energy_after_stop_j'].mean():.3f} J, return {ref['return'].mean():.1f}", flush=True)
        for lab in labels:
            c1 = time.process_time()
            runs = run_policies(names[lab], s, a.episodes, a.seed, config)
            v = table[lab][s] = row_stats([runs[n].metrics for n in names[lab]], ref)
            v["cpu_s"] = time.process_time() - c1
            print(f"  {lab:<32} {v['overshoot_pct']:6.2f} % {v['energy_after_stop_j']:.3f} J {v['return']:5.1f} | d return "
                  f"{v['dret']:+5.2f} [{v['dret_pooled'][1]:+5.2f}, {v['dret_pooled'][2]:+5.2f}] | d overshoot "
                  f"{v['dov']:+5.2f} [{v['dov_pooled'][1]:+5.2f}, {v['dov_pooled'][2]:+5.2f}] | SM {v['min_in_sm']:.2f} "
                  f"| {v['cpu_s']:.0f} s CPU", flush=True)
    chosen, ok = choose(table, a.margin)
    print(f"\nadmissible at {a.margin} points: {ok}\nchosen: {chosen}")
    chosen0, ok0 = (None, []) if chosen else choose(table, 0.0)
    if not chosen:
        print(f"admissible at 0: {ok0}\nchosen at 0: {chosen0}")
    info = {"seed": a.seed, "episodes": a.episodes, "ref": a.ref, "margin": a.margin, "models": models,
            "wall_s": time.time() - t0, "cpu_s": time.process_time() - c0, "load_before": l0,
            "load_after": os.getloadavg()}
    print(info)
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        with open(a.json, "w") as f:
            json.dump({"info": info, "chosen": chosen, "admissible": ok, "chosen_at_0": chosen0, "admissible_at_0": ok0,
                       "grid": {k: GRID[k] for k in labels}, "table": table}, f, indent=1)


if __name__ == "__main__":
    main()
