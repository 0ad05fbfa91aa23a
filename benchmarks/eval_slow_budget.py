"""Evaluate a learned policy trained with several seeds against several classical references, paired.

Runs (through :func:`policies.compare.run_policy`, the closed loop of ``dronewpt compare``: same
batched env, same seeded windows ``seed + i``) every reference policy and every seed's model on
every scenario, and prints / writes per scenario:

* per policy: mean over windows (seed models: mean over the seed means, t interval over seeds) of
  measured overshoot %, fraction in short mode, energy after the stop, return;
* for the learned kind against each reference: the paired difference of return and of overshoot
  (points) on the same windows, per seed the mean over windows, then the mean over seeds with a
  Student t 95 % interval over the 5 seed means (:func:`policies.stats.seed_ci`), and the pooled
  bootstrap interval over windows of each seed (:func:`policies.stats.mean_ci`), reported as the
  worst (lowest) lower bound over seeds;
* the fraction of windows in short mode of every seed (min over seeds).

    python benchmarks/eval_slow_budget.py --models 'policies/pretrained/slow_budget_s*.zip' \
        --refs model_based,model_based_online,mpc --scenarios nominal,lm_drift --episodes 100 --json out/x.json

``--link modal`` (the default since 2026-11-26, as the envs') evaluates on the exact-mode link
(``envs.EnvConfig(link_model="modal")``, as ``compare --link``), ``--link envelope`` on eq. 4's, the oracle gaps
included (the oracle on the same env config; its cache key holds the config).

The same numbers as ``dronewpt compare --train-seeds slow_budget=slow_budget:PATH,...`` for the
reference ``model_based`` (compare's default); the other references are what this adds.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import time

import numpy as np


def _per_seed(metrics_list, ref, key):
    return [float(np.nanmean(m[key] - ref[key])) for m in metrics_list]


def oracle_gap(tr, scenario, windows, seed, config=None):
    """Per window (in short mode) of a policy's traces: 100 (E - E_oracle) / E at the policy's own measured
    overshoot (as :func:`policies.compare.oracle_gaps`; the oracle on the env config ``config``, its link
    included); returns the list of gaps [%]."""
    from policies.oracle import oracle_window
    m, gaps = tr.metrics, []
    for i in range(min(int(windows), tr.d_short.shape[1])):
        if not m["reached_short_mode"][i]:
            continue
        o = oracle_window(scenario, seed + i, max(m["overshoot_pct"][i], 0.0) / 100.0,
                          starts=("model_based_budget:0.01",), config=config, extra_starts=(tr.d_short[:, i],))
        e = m["energy_after_stop_j"][i]
        gaps.append(100.0 * (e - o.energy_after_stop_j) / e)
    return gaps


def evaluate(models, refs, scenarios, episodes, seed, kind="slow_budget", extra=(), oracle_windows=0, no_gap=(),
             config=None):
    from tqdm import tqdm

    from policies.compare import run_policy
    from policies.stats import mean_ci, seed_ci

    out = {}
    jobs = [(s, p) for s in scenarios for p in list(refs) + list(extra) + [f"{kind}:{m}" for m in models]]
    bar = tqdm(total=len(jobs), desc="eval", unit="run")
    for s in scenarios:
        met, gaps = {}, {}
        for p in list(refs) + list(extra) + [f"{kind}:{m}" for m in models]:
            tr = run_policy(p, s, episodes, seed, config)
            met[p] = tr.metrics
            if oracle_windows and s == scenarios[0] and p not in no_gap:
                gaps[p] = oracle_gap(tr, s, oracle_windows, seed, config)
            bar.update(1)
        learned = [met[f"{kind}:{m}"] for m in models]
        row = {"policies": {}, "paired": {}}
        for p in list(refs) + list(extra):
            m = met[p]
            row["policies"][p] = {k: mean_ci(m[k]) for k in ("overshoot_pct", "reached_short_mode",
                                                             "energy_after_stop_j", "return")}
        row["policies"][kind] = {k: seed_ci([float(np.mean(m[k])) for m in learned])
                                 for k in ("overshoot_pct", "reached_short_mode", "energy_after_stop_j", "return")}
        row["policies"][kind]["per_seed"] = [{k: float(np.mean(m[k])) for k in ("overshoot_pct", "reached_short_mode",
                                                                                "energy_after_stop_j", "return")}
                                             for m in learned]
        for p in refs:
            ref = met[p]
            row["paired"][p] = {
                "d_return_seed_t": seed_ci(_per_seed(learned, ref, "return")),
                "d_overshoot_pts_seed_t": seed_ci(_per_seed(learned, ref, "overshoot_pct")),
                "d_return_boot_worst_lo": min(mean_ci(m["return"] - ref["return"])[1] for m in learned),
                "d_overshoot_boot_worst_hi": max(mean_ci(m["overshoot_pct"] - ref["overshoot_pct"])[2] for m in learned),
                # per window the mean over the seeds of the paired difference, bootstrap over the windows
                "d_return_pooled_boot": mean_ci(np.mean([m["return"] - ref["return"] for m in learned], axis=0)),
                "d_overshoot_pooled_boot": mean_ci(np.mean([m["overshoot_pct"] - ref["overshoot_pct"] for m in learned],
                                                           axis=0)),
            }
        if gaps:
            row["oracle_gap_pct"] = {p: mean_ci(g) for p, g in gaps.items() if not p.startswith(kind + ":")}
            per = [float(np.mean(gaps[f"{kind}:{m}"])) for m in models]
            row["oracle_gap_pct"][kind] = seed_ci(per)
            row["oracle_gap_pct"][kind + "_per_seed"] = per
            row["oracle_gap_pct"][kind + "_worst_window"] = max(max(gaps[f"{kind}:{m}"]) for m in models)
            row["oracle_windows"] = int(oracle_windows)
        row["min_in_sm"] = min(float(np.mean(m["reached_short_mode"])) for m in learned)
        out[s] = row
    bar.close()
    return out


def _fmt(t, f="{:.2f}"):
    return f"{f.format(t[0])} [{f.format(t[1])}, {f.format(t[2])}]"


def report(res, kind="slow_budget"):
    for s, row in res.items():
        print(f"\n== {s}  (min fraction in short mode over seeds: {row['min_in_sm']:.2f})")
        for p, v in row["policies"].items():
            print(f"  {p:<26} overshoot {_fmt(v['overshoot_pct'])} %  in SM {v['reached_short_mode'][0]:.2f}  "
                  f"E after {_fmt(v['energy_after_stop_j'], '{:.3f}')} J  return {_fmt(v['return'], '{:.1f}')}")
        for p, g in row.get("oracle_gap_pct", {}).items():
            txt = f"{g:.1f}" if isinstance(g, float) else _fmt(g, "{:.1f}") if len(g) == 3 else str([round(x, 1) for x in g])
            print(f"  gap to the oracle ({row['oracle_windows']} windows) {p:<26} {txt} %")
        for p, d in row["paired"].items():
            print(f"  {kind} - {p:<20} d return {_fmt(d['d_return_seed_t'], '{:.1f}')} (t over seeds; worst seed's "
                  f"bootstrap lo {d['d_return_boot_worst_lo']:.1f})  d overshoot {_fmt(d['d_overshoot_pts_seed_t'])} pts "
                  f"(worst seed's bootstrap hi {d['d_overshoot_boot_worst_hi']:.2f})")
            print(f"  {'':<{len(kind) + 23}} pooled over seeds, bootstrap over windows: d return "
                  f"{_fmt(d['d_return_pooled_boot'], '{:.1f}')}  d overshoot {_fmt(d['d_overshoot_pooled_boot'])} pts")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--models", required=True, help="glob of the seed models (zip)")
    ap.add_argument("--kind", default="slow_budget")
    ap.add_argument("--refs", default="model_based,model_based_online,mpc")
    ap.add_argument("--extra", default="", help="more policies to show (not paired)")
    ap.add_argument("--scenarios", default="nominal")
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--json", default=None)
    ap.add_argument("--oracle-windows", type=int, default=0, help="gap to the oracle on the first scenario's first N")
    ap.add_argument("--no-gap", default="model_based_online", help="policies without an oracle gap")
    ap.add_argument("--link", choices=("envelope", "modal"), default="modal",
                    help="the env's link model (envs.EnvConfig.link_model, as compare --link; default modal, the envs' "
                    "default since 2026-11-26); the oracle on the same")
    a = ap.parse_args(argv)
    models = sorted(glob.glob(a.models))
    if not models:
        raise SystemExit(f"--models {a.models!r}: no file matches")
    from envs import EnvConfig
    config = EnvConfig(link_model=a.link)   # always named: the result must not depend on the envs' default
    t0, c0, l0 = time.time(), time.process_time(), os.getloadavg()
    res = evaluate(models, [r for r in a.refs.split(",") if r], a.scenarios.split(","), a.episodes, a.seed, a.kind,
                   [e for e in a.extra.split(",") if e], a.oracle_windows, tuple(a.no_gap.split(",")), config)
    report(res, a.kind)
    info = {"models": models, "episodes": a.episodes, "seed": a.seed, "link": a.link, "wall_s": time.time() - t0,
            "cpu_s": time.process_time() - c0, "load_before": l0, "load_after": os.getloadavg()}
    print(f"\n{info}")
    if a.json:
        tmp = a.json + ".tmp"
        with open(tmp, "w") as f:
            json.dump({"info": info, "results": res}, f, indent=1)
        os.replace(tmp, a.json)


if __name__ == "__main__":
    main()
