"""Train the amortised imitation of the oracle (:mod:`policies.oracle_imitation`): solve the oracle on
training windows, choose each window's budget by one Lagrangian multiplier, fit one model per seed.

    python benchmarks/train_oracle_imitation.py --scenarios nominal,sense_delay,lm_drift --windows 0:160 \
        --deltas 0.003,0.006,0.01 --lam 0.3 --train-seeds 0,1,2,3,4 --out policies/pretrained/oracle_imitation

writes ``OUT_s<k>.npz`` per training seed ``k`` (a few kB each; the command, the scenarios, windows,
budgets and the teacher's mean overshoot / energy in its ``meta``). The oracle is solved on each
scenario's *plant* (a scenario that differs from another only in its sensing delay shares its
windows' oracle: the delay changes what the policy sees, not the link), cached on disk
(``$DRONEWPT_CACHE_DIR``), ~1-5 s of CPU per (window, budget) the first time. Training windows must
be disjoint from the evaluation's (``compare``'s seeds 1000-1099). Bad options: one line, exit 2.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np


def plant_scenario(name: str) -> str:
    """The scenario whose oracle serves ``name``: ``nominal`` for a scenario that is nominal but for its
    sensing delay (the same windows, the same link), else ``name`` itself."""
    from dataclasses import replace

    from envs import get_scenario
    from envs.scenario import SCENARIOS
    scn = get_scenario(name)
    plain = replace(scn, name="nominal", sense_delay_steps=(0, 0))
    return "nominal" if plain == SCENARIOS["nominal"] else name


def parse(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenarios", default="nominal,sense_delay,lm_drift")
    ap.add_argument("--windows", default="0:160", help="training window seeds LO:HI (disjoint from 1000-1099)")
    ap.add_argument("--deltas", default="0.003,0.006,0.01", help="budgets above each window's floor (fractions)")
    ap.add_argument("--lam", type=float, default=0.3, help="multiplier, J per point of overshoot (> 0)")
    ap.add_argument("--train-seeds", default="0,1,2,3,4")
    ap.add_argument("--slow", type=float, default=1.0, help="play the learned sequence this many times slower "
                    "(>= 1; less overshoot for more energy, chosen on validation windows)")
    ap.add_argument("--features", default="d_pre,cmd_before_a", help="stop features the clone reads "
                    "(policies.oracle_imitation.FEATURE_NAMES)")
    ap.add_argument("--out", default="out/oracle_imitation")
    a = ap.parse_args(argv)
    from envs import get_scenario
    try:
        a.scenarios = [s for s in a.scenarios.split(",") if s]
        for s in a.scenarios:
            get_scenario(s)
        lo, hi = (int(x) for x in a.windows.split(":"))
        a.deltas = [float(x) for x in a.deltas.split(",")]
        a.train_seeds = [int(x) for x in a.train_seeds.split(",")]
        from policies.oracle_imitation import FEATURE_NAMES
        a.cols = [FEATURE_NAMES.index(x) for x in a.features.split(",")]
    except ValueError as exc:
        ap.exit(2, f"train_oracle_imitation: invalid option ({str(exc).splitlines()[0]}); valid: --windows LO:HI, "
                   f"--deltas/--train-seeds comma-separated numbers, --features names from FEATURE_NAMES\n")
    if not (0 <= lo < hi and (hi <= 1000 or lo >= 1100)):
        ap.exit(2, f"--windows {a.windows!r} is invalid; valid: LO:HI with 0 <= LO < HI, disjoint from 1000-1099\n")
    if not a.deltas or not all(0.0 < d <= 0.2 for d in a.deltas) or not (a.lam > 0 and np.isfinite(a.lam)) \
            or not a.scenarios or not (1.0 <= a.slow <= 3.0):
        ap.exit(2, "train_oracle_imitation: --deltas must be in (0, 0.2], --lam > 0, --slow in [1, 3], --scenarios non-empty\n")
    a.seeds = list(range(lo, hi))
    return a


def dataset(scenarios, seeds, deltas, lam):
    """``(features, targets, info)`` of every (scenario, window): the stop features of the paper's
    controller's run and the chosen oracle sequence."""
    from policies.oracle_imitation import choose_targets, stop_features, target_sequences
    from policies.oracle_imitation_train import collect_stop_observations, oracle_targets
    X, Y, ov, en, fl = [], [], [], [], []
    for s in scenarios:
        frames, k0 = collect_stop_observations(s, seeds[0], len(seeds))
        tg = oracle_targets(plant_scenario(s), seeds, deltas, progress=True)
        pick = choose_targets(tg["energy_j"], tg["overshoot"], lam)
        rows = np.arange(len(seeds))
        X.append(stop_features(frames))
        Y.append(target_sequences(tg["duties"][rows, pick], k0))
        ov.append(tg["overshoot"][rows, pick])
        en.append(tg["energy_j"][rows, pick])
        fl.append(tg["floor"])
    return np.vstack(X), np.vstack(Y), {"overshoot": np.concatenate(ov), "energy_j": np.concatenate(en),
                                         "floor": np.concatenate(fl)}


def main(argv=None):
    a = parse(argv)
    from envs.core import EnvConfig
    from policies.oracle_imitation import fit, predict, save_model
    t0, c0 = time.time(), time.process_time()
    X, Y, info = dataset(a.scenarios, a.seeds, a.deltas, a.lam)
    print(f"teacher: {len(X)} windows, overshoot {100 * info['overshoot'].mean():.3f} % (floor "
          f"{100 * info['floor'].mean():.3f} %), energy after the stop {info['energy_j'].mean():.4f} J")
    os.makedirs(os.path.dirname(a.out) or ".", exist_ok=True)
    for k in a.train_seeds:
        model = fit(X, Y, cols=a.cols, seed=k)
        rms = float(np.sqrt(((predict(model, X) - Y) ** 2).mean()))   # the clone's error (before the slow-down)
        model["slow"] = np.array(a.slow)
        meta = {"command": " ".join(["python", "benchmarks/train_oracle_imitation.py"] + list(sys.argv[1:] if argv is None else argv)),
                "scenarios": a.scenarios, "windows": [a.seeds[0], a.seeds[-1] + 1], "deltas": a.deltas, "lam": a.lam, "slow": a.slow,
                "seed": k, "features": a.features.split(","), "teacher_overshoot_pct": 100 * float(info["overshoot"].mean()),
                "teacher_energy_j": float(info["energy_j"].mean()), "fit_rms_duty": rms,
                "control_period_s": EnvConfig().dt_s}   # the windows' env (config None): the period it learned at
        save_model(model, f"{a.out}_s{k}.npz", meta)
        print(f"seed {k}: fit RMS {rms:.4f} (duty) -> {a.out}_s{k}.npz")
    print(f"{time.time() - t0:.0f} s wall, {time.process_time() - c0:.0f} s CPU, load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
