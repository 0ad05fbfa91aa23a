"""Train the amortised imitation of the oracle (:mod:`policies.oracle_imitation`): solve the oracle on
training windows, choose each window's budget by one Lagrangian multiplier, fit one model per seed.

    python benchmarks/train_oracle_imitation.py --link modal --scenarios nominal --windows 0:80 \
        --deltas 0.003,0.006,0.01,0.016 --lam 0.4 --slow 1.1 --out out/oracle_imitation_modal/oracle_imitation

(the shipped models' command since 2026-11-26, in their ``meta``, the files then copied to
``policies/pretrained/``; the defaults are these options but ``--out``, which is
``out/oracle_imitation/oracle_imitation`` so a run never overwrites the shipped models; with the oracle's cache
warm it reproduces them bit for bit, ~20 s) writes ``OUT_s<k>.npz`` per training seed ``k`` (a few kB each; the
command, the scenarios, windows, budgets, the control period, the link and the teacher's mean overshoot / energy in
its ``meta``). ``--link`` (default ``modal``, the envs' default since 2026-11-26) is the plant of the teacher's
solves and of the stop observations, always passed as an explicit ``EnvConfig(link_model=...)`` and recorded as
``meta["link"]``; the models shipped before 2026-11-26 were fitted on ``--link envelope`` (eq. 4; no ``link`` in
their meta then). ``--base mpc`` runs the MPC before the stop and solves
the teacher from its state there, stored as ``meta["base"]``. The oracle is solved on each
scenario's *plant* (a scenario that differs from another only in its sensing delay shares its
windows' oracle: the delay changes what the policy sees, not the link), cached on disk
(``$DRONEWPT_CACHE_DIR``), ~1-5 s of CPU per (window, budget) the first time. Training windows must
be disjoint from the evaluation's (``compare``'s seeds 1000-1099). Bad options (values, names, an
``--out`` that cannot be written): one line naming the option, value and valid range, exit 2, before
any oracle solve.
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


def _conv(flag: str, valid: str, convert):
    """argparse type: ``convert(text)`` or one error line naming ``flag``, the value and ``valid``."""
    def conv(text):
        try:
            v = convert(text)
        except (ValueError, TypeError, IndexError):
            v = None
        if v is None:
            raise argparse.ArgumentTypeError(f"{flag}={text!r} is invalid; valid: {valid}")
        return v
    return conv


def _in(lo, hi, lo_open=False):
    """``float(text)`` if it is in ``[lo, hi]`` (``(lo, hi]`` if ``lo_open``), else None."""
    def conv(text):
        v = float(text)
        return v if np.isfinite(v) and (v > lo if lo_open else v >= lo) and v <= hi else None
    return conv


def _windows(text):
    lo, hi = (int(x) for x in text.split(":"))
    return (lo, hi) if 0 <= lo < hi and (hi <= 1000 or lo >= 1100) else None


def _list(item):
    def conv(text):
        vals = [item(x) for x in text.split(",") if x.strip()]
        return vals if vals and all(v is not None for v in vals) else None
    return conv


def _features(text):
    from policies.oracle_imitation import FEATURE_NAMES
    names = [x.strip() for x in text.split(",") if x.strip()]
    bad = [x for x in names if x not in FEATURE_NAMES]
    if not names or bad:
        raise argparse.ArgumentTypeError(f"--features {', '.join(map(repr, bad)) or repr(text)} is invalid; valid: "
                                         f"comma-separated names out of {', '.join(FEATURE_NAMES)}")
    return [FEATURE_NAMES.index(x) for x in names]


def _base(text):
    from policies.oracle_imitation import BASES
    return text if text in BASES else None


def _seed(text):
    from mission_sim.validation import SEED_RANGE
    v = int(text)
    return v if SEED_RANGE.contains(v) else None


def parse(argv):
    """The options, every bad one refused with one line (exit 2) before any oracle solve: values and
    their ranges, the scenarios, and the output files (their folder created and writable now)."""
    from mission_sim.cli.common import CliError, OneLineParser, check_out_file
    ap = OneLineParser(prog="train_oracle_imitation.py", description=__doc__.split("\n")[0])
    ap.add_argument("--scenarios", default="nominal", help="comma-separated scenarios (envs.SCENARIOS)")
    ap.add_argument("--windows", default=(0, 80), help="training window seeds LO:HI (disjoint from 1000-1099)",
                    type=_conv("--windows", "LO:HI, 0 <= LO < HI, disjoint from 1000-1099", _windows))
    ap.add_argument("--deltas", default=[0.003, 0.006, 0.01, 0.016], help="budgets above each window's floor "
                    "(fractions)", type=_conv("--deltas", "comma-separated numbers in (0, 0.2]", _list(_in(0.0, 0.2, True))))
    ap.add_argument("--lam", default=0.4, help="multiplier, J per point of overshoot (> 0)",
                    type=_conv("--lam", "a number > 0 (J per point)", _in(0.0, np.inf, True)))
    ap.add_argument("--train-seeds", default=[0, 1, 2, 3, 4], help="bootstrap seeds, one model each",
                    type=_conv("--train-seeds", "comma-separated integers 0..2^32-1", _list(_seed)))
    ap.add_argument("--slow", default=1.1, help="play the learned sequence this many times slower "
                    "(>= 1; less overshoot for more energy, chosen on validation windows)",
                    type=_conv("--slow", "a number in [1, 3]", _in(1.0, 3.0)))
    ap.add_argument("--features", default="d_pre,cmd_before_a", help="stop features the clone reads "
                    "(policies.oracle_imitation.FEATURE_NAMES)")
    ap.add_argument("--base", default="model_based", help="controller before the stop (the teacher is solved "
                    "from its state at the stop; stored in the model's meta)",
                    type=_conv("--base", "one of model_based, mpc", _base))
    ap.add_argument("--link", choices=("envelope", "modal"), default="modal",
                    help="the env's link model (envs.EnvConfig.link_model, as compare --link; default modal, the envs' "
                    "default since 2026-11-26): the plant of the oracle solves and of the stop observations, recorded "
                    "in meta['link']")
    ap.add_argument("--out", default="out/oracle_imitation/oracle_imitation",
                    help="output prefix: writes OUT_s<k>.npz (default under out/, not the shipped models)")
    a = ap.parse_args(argv)
    try:
        a.cols = _features(a.features)
    except argparse.ArgumentTypeError as exc:
        ap.error(str(exc))
    from envs import SCENARIOS
    a.scenarios = [s.strip() for s in a.scenarios.split(",") if s.strip()]
    bad = [s for s in a.scenarios if s not in SCENARIOS]
    if not a.scenarios or bad:
        ap.error(f"--scenarios {', '.join(map(repr, bad)) or repr('')} is invalid; valid: comma-separated names out of "
                 f"{', '.join(SCENARIOS)}")
    try:
        for k in a.train_seeds:
            check_out_file(f"{a.out}_s{k}.npz", "--out", ".npz")
    except CliError as exc:
        ap.error(str(exc))
    a.seeds = list(range(*a.windows))
    return a


def dataset(scenarios, seeds, deltas, lam, base="model_based", config=None):
    """``(features, targets, info)`` of every (scenario, window): the stop features of ``base``'s run
    (the paper's controller by default) and the chosen oracle sequence, solved from its state at the stop, on
    the env config ``config`` (None: the envs' default, the modal link; the oracle's disk cache keys hold it)."""
    from policies.oracle_imitation import choose_targets, stop_features, target_sequences
    from policies.oracle_imitation_train import collect_stop_observations, oracle_targets
    X, Y, ov, en, fl = [], [], [], [], []
    for s in scenarios:
        frames, k0 = collect_stop_observations(s, seeds[0], len(seeds), config=config, base=base)
        tg = oracle_targets(plant_scenario(s), seeds, deltas, config=config, progress=True, base=base)
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
    config = EnvConfig(link_model=a.link)   # always named: the teacher must not depend on the envs' default
    X, Y, info = dataset(a.scenarios, a.seeds, a.deltas, a.lam, a.base, config)
    print(f"teacher: {len(X)} windows, overshoot {100 * info['overshoot'].mean():.3f} % (floor "
          f"{100 * info['floor'].mean():.3f} %), energy after the stop {info['energy_j'].mean():.4f} J")
    os.makedirs(os.path.dirname(a.out) or ".", exist_ok=True)
    for k in a.train_seeds:
        model = fit(X, Y, cols=a.cols, seed=k)
        rms = float(np.sqrt(((predict(model, X) - Y) ** 2).mean()))   # the clone's error (before the slow-down)
        model["slow"] = np.array(a.slow)
        meta = {"command": " ".join(["python", "benchmarks/train_oracle_imitation.py"] + list(sys.argv[1:] if argv is None else argv)),
                "scenarios": a.scenarios, "windows": [a.seeds[0], a.seeds[-1] + 1], "deltas": a.deltas, "lam": a.lam, "slow": a.slow,
                "seed": k, "base": a.base, "features": a.features.split(","), "teacher_overshoot_pct": 100 * float(info["overshoot"].mean()),
                "teacher_energy_j": float(info["energy_j"].mean()), "fit_rms_duty": rms,
                "control_period_s": config.dt_s, "link": a.link}   # the windows' env: the period, the plant
        save_model(model, f"{a.out}_s{k}.npz", meta)
        print(f"seed {k}: fit RMS {rms:.4f} (duty) -> {a.out}_s{k}.npz")
    print(f"{time.time() - t0:.0f} s wall, {time.process_time() - c0:.0f} s CPU, load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
