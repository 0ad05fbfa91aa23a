"""Measure the budgeted modal MPC with and without the locked-phase prediction of its after-stop plan (docs/rl.md,
"The rectifier's phase lock in the modal MPC's prediction"): per window of a scenario on the exact-mode link, the
measured overshoot, the energy after the stop, the gap to the oracle from the policy's own state at the stop and
``compare``'s gap (either state), the CPU of the closed loop; written to a JSON file for paired comparisons.

    python benchmarks/eval_mpc_lock.py --lock 1 --out /tmp/lock.json [--policies mpc:0.05,mpc:0.1] [--windows 20]
        [--scenario nominal] [--no-oracle]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import time

import numpy as np


def run(names, scenario, windows, seed, cfg, oracle=True):
    from policies.compare import run_policy
    from policies.oracle import oracle_window
    out = {}
    for name in names:
        t0, c0 = time.perf_counter(), time.process_time()
        tr = run_policy(name, scenario, windows, seed, cfg)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        m = tr.metrics
        r = {"overshoot_pct": [float(x) for x in m["overshoot_pct"]],
             "energy_after_stop_j": [float(x) for x in m["energy_after_stop_j"]],
             "reached_short_mode": [bool(x) for x in m["reached_short_mode"]],
             "return": [float(x) for x in m["return"]] if "return" in m else None,
             "cpu_s": cpu, "wall_s": wall, "load": os.getloadavg()[0],
             "sha1": hashlib.sha1(np.ascontiguousarray(tr.d_short).tobytes()
                                  + b"".join(np.asarray(m[k], dtype=float).tobytes() for k in sorted(m))).hexdigest()[:12]}
        if oracle:
            own, both = [], []
            for i in range(windows):
                b = max(m["overshoot_pct"][i], 0.0) / 100.0
                both.append(oracle_window(scenario, seed + i, b, starts=("model_based_budget:0.01",), config=cfg,
                                          extra_starts=(tr.d_short[:, i],)).energy_after_stop_j)
                own.append(oracle_window(scenario, seed + i, b, starts=(), config=cfg,
                                         extra_starts=(tr.d_short[:, i],)).energy_after_stop_j)
            e = np.array(r["energy_after_stop_j"])
            r["gap_own_pct"] = list(100 * (e - np.array(own)) / e)
            r["gap_compare_pct"] = list(100 * (e - np.array(both)) / e)
        out[name] = r
        print(name, f"overshoot {np.mean(r['overshoot_pct']):.3f} %, E {np.mean(r['energy_after_stop_j']):.4f} J,",
              f"own gap {np.mean(r.get('gap_own_pct', [np.nan])):.2f} %, compare gap "
              f"{np.mean(r.get('gap_compare_pct', [np.nan])):.2f} %, cpu {cpu:.1f} s, sha1 {r['sha1']}", flush=True)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--policies", default="mpc:0.05,mpc:0.1")
    ap.add_argument("--scenario", default="nominal")
    ap.add_argument("--windows", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--lock", type=int, default=None, help="1/0: force the locked prediction on/off (default: the code's)")
    ap.add_argument("--link", default="modal", choices=("envelope", "modal"))
    ap.add_argument("--no-oracle", action="store_true")
    ap.add_argument("--set", default="", help="NAME=VALUE,... module constants of policies.mpc (an experiment)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    from envs import EnvConfig
    import policies.mpc as mpc
    if a.lock is not None and hasattr(mpc, "_LOCK"):
        mpc._LOCK = bool(a.lock)
    for kv in filter(None, a.set.split(",")):
        k, v = kv.split("=")
        setattr(mpc, k, type(getattr(mpc, k))(float(v)))
    res = run(a.policies.split(","), a.scenario, a.windows, a.seed, EnvConfig(link_model=a.link), not a.no_oracle)
    with open(a.out, "w") as f:
        json.dump({"args": vars(a), "results": res}, f)


if __name__ == "__main__":
    main()
