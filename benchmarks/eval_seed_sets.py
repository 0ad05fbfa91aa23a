"""Two sets of training seeds of one kind (e.g. a retrained ``rl`` against the shipped one) on the same windows.

For every scenario, every model of both sets and the references run side by side on windows ``seed + i``
(:func:`policies.compare.run_policies`); printed and written (``--json``) per scenario:

* per set: the mean over the seed means [Student t 95 % over the seeds] of overshoot %, energy after the
  stop, return; the fraction of windows in short mode of the worst seed;
* new - old: the difference of the set means with a Welch t interval over the two sets of seed means, and
  paired on the windows: per window the new set's mean over seeds minus the old set's, bootstrap over windows;
* each reference (one policy): mean [bootstrap over windows].

    python benchmarks/eval_seed_sets.py --new 'out/retrain_mask/rl_bc_s*/ppo_sbar.zip' \
        --old 'out/retrain_mask/old/rl_s*.zip' --refs model_based_budget:0.05 --scenarios nominal,sense_delay
    python benchmarks/eval_seed_sets.py --kind imitation --new 'out/modal/imitation_s*/ppo_sbar.zip' \
        --old 'policies/pretrained/imitation_s*.zip' --refs model_based_budget:0.02 --link envelope

``--kind`` names the models' policy kind (``KIND:PATH``, default ``rl``); ``--link`` the env's link (default
``modal``, the envs' default since 2026-11-26; ``envelope``: eq. 4's).
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import time

import numpy as np

KEYS = ("overshoot_pct", "reached_short_mode", "energy_after_stop_j", "return")


def welch_ci(a, b, level: float = 0.95) -> tuple[float, float, float]:
    """Mean(a) - mean(b) with a Welch t interval (Welch-Satterthwaite degrees of freedom)."""
    from scipy import stats

    a, b = np.asarray(a, float), np.asarray(b, float)
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)
    d, se = a.mean() - b.mean(), np.sqrt(va + vb)
    df = (va + vb) ** 2 / (va ** 2 / (len(a) - 1) + vb ** 2 / (len(b) - 1)) if se > 0 else 1.0
    h = stats.t.ppf(0.5 + level / 2, df) * se
    return float(d), float(d - h), float(d + h)


def _set_row(mets) -> dict:
    from policies.stats import seed_ci

    row = {k: seed_ci([float(np.mean(m[k])) for m in mets]) for k in KEYS}
    row["min_in_sm"] = min(float(np.mean(m["reached_short_mode"])) for m in mets)
    row["per_seed_return"] = [float(np.mean(m["return"])) for m in mets]
    row["per_seed_in_sm"] = [float(np.mean(m["reached_short_mode"])) for m in mets]
    return row


def scenario_row(met: dict, new: list, old: list, refs: list, kind: str = "rl") -> dict:
    from policies.stats import mean_ci

    mn, mo = [met[f"{kind}:{p}"] for p in new], [met[f"{kind}:{p}"] for p in old]
    row = {"new": _set_row(mn), "old": _set_row(mo), "refs": {r: {k: mean_ci(met[r][k]) for k in KEYS} for r in refs}}
    for k in ("return", "overshoot_pct", "energy_after_stop_j"):
        row[f"d_{k}_welch"] = welch_ci([np.mean(m[k]) for m in mn], [np.mean(m[k]) for m in mo])
        row[f"d_{k}_paired_boot"] = mean_ci(np.mean([m[k] for m in mn], axis=0) - np.mean([m[k] for m in mo], axis=0))
    return row


def _fmt(t, f="{:.1f}"):
    return f"{f.format(t[0])} [{f.format(t[1])}, {f.format(t[2])}]"


def report(res: dict) -> None:
    for s, row in res.items():
        print(f"\n== {s}")
        for name in ("new", "old"):
            r = row[name]
            print(f"  {name:<4} overshoot {_fmt(r['overshoot_pct'])} %  in SM (worst seed) {r['min_in_sm']:.2f}  "
                  f"E after {_fmt(r['energy_after_stop_j'], '{:.3f}')} J  return {_fmt(r['return'])}  "
                  f"per seed {[round(x, 1) for x in r['per_seed_return']]}")
        print(f"  new - old: d return {_fmt(row['d_return_welch'])} (Welch over seeds), "
              f"{_fmt(row['d_return_paired_boot'])} (paired on windows, bootstrap); d overshoot "
              f"{_fmt(row['d_overshoot_pct_welch'], '{:.2f}')} pts (Welch), "
              f"{_fmt(row['d_overshoot_pct_paired_boot'], '{:.2f}')} (paired); d E after "
              f"{_fmt(row['d_energy_after_stop_j_welch'], '{:.4f}')} J (Welch), "
              f"{_fmt(row['d_energy_after_stop_j_paired_boot'], '{:.4f}')} (paired)")
        for p, v in row["refs"].items():
            print(f"  {p:<26} overshoot {_fmt(v['overshoot_pct'])} %  E after "
                  f"{_fmt(v['energy_after_stop_j'], '{:.3f}')} J  return {_fmt(v['return'])}")


def main(argv=None):
    from policies.compare import run_policies

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--new", required=True, help="glob of the new set's models (rl: zip files)")
    ap.add_argument("--old", required=True, help="glob of the old set's models")
    ap.add_argument("--refs", default="model_based_budget:0.05")
    ap.add_argument("--scenarios", default="nominal")
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--json", default=None)
    ap.add_argument("--kind", default="rl", help="the models' policy kind (KIND:PATH; default rl)")
    ap.add_argument("--link", choices=("envelope", "modal"), default="modal", help="the env's link (default modal)")
    a = ap.parse_args(argv)
    new, old = sorted(glob.glob(a.new)), sorted(glob.glob(a.old))
    if not new or not old:
        raise SystemExit(f"--new {a.new!r} / --old {a.old!r}: no file matches")
    from envs import EnvConfig

    refs = [r for r in a.refs.split(",") if r]
    config = EnvConfig(link_model=a.link)
    t0, c0, l0 = time.time(), time.process_time(), os.getloadavg()
    res = {}
    for s in a.scenarios.split(","):
        specs = refs + [f"{a.kind}:{p}" for p in new + old]
        met = {k: v.metrics for k, v in run_policies(specs, s, a.episodes, a.seed, config).items()}
        res[s] = scenario_row(met, new, old, refs, a.kind)
    report(res)
    info = {"kind": a.kind, "link": a.link, "new": new, "old": old, "episodes": a.episodes, "seed": a.seed, "wall_s": time.time() - t0,
            "cpu_s": time.process_time() - c0, "load_before": l0, "load_after": os.getloadavg()}
    print(f"\n{info}")
    if a.json:
        with open(a.json + ".tmp", "w") as f:
            json.dump({"info": info, "results": res}, f, indent=1)
        os.replace(a.json + ".tmp", a.json)


if __name__ == "__main__":
    main()
