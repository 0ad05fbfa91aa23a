"""``dronewpt train`` and ``dronewpt compare``: RL training and the head-to-head policy comparison."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .common import (
    CliError,
    add_progress_flag,
    lazy_names_help,
    policy_names,
    prepare_out_dir,
    scenario_names,
    seed_int,
    show_progress,
)


def _add_train(sub):
    p = sub.add_parser("train", help="train an RL mode-switching policy (stable-baselines3)",
                       description="Train PPO or SAC on dronewpt/SbarCharging-v0 or DQN on the discrete "
                                   "(ON-OFF) variant; writes the model zip, its metadata JSON with the "
                                   "observation normalisation statistics, Monitor CSVs and a learning curve PNG.")
    p.add_argument("--algo", choices=("ppo", "sac", "dqn"), required=True)
    p.add_argument("--timesteps", type=int, required=True, help="environment steps to train for")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--seed", type=seed_int(), default=0, help="seed, 0 .. 2^32-1 (default 0)")
    p.add_argument("--n-envs", type=int, default=1, help="parallel environments (default 1)")
    lazy_names_help(p.add_argument("--scenario", default="random"),
                    "training scenario (default random: domain randomisation)", scenario_names)
    add_progress_flag(p)
    p.set_defaults(func=_cmd_train)


def _cmd_train(args) -> int:
    if args.timesteps < 1:
        raise CliError(f"--timesteps {args.timesteps} is invalid; valid range: >= 1")
    if not 1 <= args.n_envs <= 256:
        raise CliError(f"--n-envs {args.n_envs} is invalid; valid range: 1..256")
    if args.scenario not in scenario_names():
        raise CliError(f"--scenario {args.scenario!r} is invalid; valid values: {', '.join(scenario_names())}")
    from policies import require_sb3
    require_sb3()
    prepare_out_dir(args.out)
    from policies.train import train
    res = train(args.algo, args.timesteps, args.out, seed=args.seed, n_envs=args.n_envs, scenario=args.scenario,
                progress=show_progress(args))
    for key, path in res.items():
        print(f"{key}: {path}")
    return 0


def _add_compare(sub):
    p = sub.add_parser("compare", help="compare mode-switching policies head to head",
                       description="Run every policy through the same closed loop on the same seeded charging "
                                   "windows (batched env) and print peak I2, overshoot, time above rated, "
                                   "energy, tracking error, cost and return; writes a figure of the "
                                   "RM -> SM transitions.")
    lazy_names_help(p.add_argument("--policies", default=None),
                    "comma-separated policy names (default: step,ramp,hysteresis,model_based,model_based_online,"
                    "rl,random; rl is skipped with a note when stable-baselines3 is not installed)", policy_names)
    lazy_names_help(p.add_argument("--scenarios", default=None),
                    "comma-separated scenarios (default: nominal,lm_mismatch,windy,battery)", scenario_names)
    p.add_argument("--episodes", type=int, default=20, help="episodes per scenario (default 20)")
    p.add_argument("--seed", type=seed_int(), default=1000,
                   help="seed of episode 0 (episode i uses seed + i), 0 .. 2^32-1 (default 1000)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--out", type=Path, default=Path("out/compare"), help="folder for the figure")
    p.add_argument("--no-plot", action="store_true", help="skip the figure")
    add_progress_flag(p)
    p.set_defaults(func=_cmd_compare)


def sb3_installed() -> bool:
    import importlib.util
    return importlib.util.find_spec("stable_baselines3") is not None


def _rl_or_skip(pols: tuple, explicit: bool) -> tuple:
    """Without stable-baselines3 the default ``rl`` row is skipped with a note on stderr; an ``rl``
    the user asked for with ``--policies`` is an error naming the extra to install."""
    if not any(p_.split(":", 1)[0] == "rl" for p_ in pols) or sb3_installed():
        return pols
    if explicit:
        raise CliError("--policies rl needs stable-baselines3 (with torch): pip install 'dronewpt[rl]'")
    print("dronewpt compare: note: skipping the rl row: stable-baselines3 is not installed "
          "(pip install 'dronewpt[rl]')", file=sys.stderr)
    return tuple(p_ for p_ in pols if p_.split(":", 1)[0] != "rl")


def _cmd_compare(args) -> int:
    from envs import SCENARIOS
    from policies import available
    from policies.compare import (
        DEFAULT_POLICIES,
        DEFAULT_SCENARIOS,
        compare,
        plot_transitions,
    )

    pols = tuple(x.strip() for x in args.policies.split(",") if x.strip()) if args.policies else DEFAULT_POLICIES
    scns = tuple(x.strip() for x in args.scenarios.split(",") if x.strip()) if args.scenarios else DEFAULT_SCENARIOS
    for p_ in pols:
        if p_.split(":", 1)[0] not in available():
            raise CliError(f"--policies {p_!r} is invalid; valid values: {', '.join(available())} (or rl:PATH)")
    pols = _rl_or_skip(pols, explicit=bool(args.policies))
    for s_ in scns:
        if s_ not in SCENARIOS:
            raise CliError(f"--scenarios {s_!r} is invalid; valid values: {', '.join(SCENARIOS)}")
    if not 1 <= args.episodes <= 100_000:
        raise CliError(f"--episodes {args.episodes} is invalid; valid range: 1..100000")
    if args.seed + args.episodes - 1 > 2**32 - 1:
        raise CliError(f"--seed {args.seed} is invalid with --episodes {args.episodes}; valid range: "
                       f"0 .. {2**32 - args.episodes} (episode seeds go up to seed + episodes - 1)")
    if not args.no_plot:
        prepare_out_dir(args.out)
    rows, traces = compare(pols, scns, args.episodes, args.seed, progress=show_progress(args))
    figs = []
    if not args.no_plot:
        figs.append(str(plot_transitions(traces, scns[0], args.out / f"transitions_{scns[0]}.png")))
    if args.format == "json":
        print(json.dumps({"episodes": args.episodes, "seed": args.seed, "rows": rows, "figures": figs}))
        return 0
    print(f"{args.episodes} episodes per scenario, seeds {args.seed}..{args.seed + args.episodes - 1}, "
          "means over episodes (peak max = worst episode)")
    hdr = (f"{'scenario':<12} {'policy':<20} {'peak I2':>8} {'peak max':>8} {'overshoot':>9} {'>rated':>8} "
           f"{'energy':>7} {'after':>7} {'track':>6} {'cost':>7} {'return':>8}")
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        print(f"{r['scenario']:<12} {r['policy'][:20]:<20} {r['peak_i2_a']:>6.2f} A {r['peak_i2_max_a']:>6.2f} A "
              f"{r['overshoot_pct']:>7.1f} % {r['time_above_rated_s'] * 1e3:>5.2f} ms {r['energy_j']:>5.2f} J "
              f"{r['energy_after_stop_j']:>5.2f} J "
              f"{r['tracking_rmse_a']:>4.2f} A {r['cost']:>7.2f} {r['return']:>8.1f}")
    print("overshoot = (max I2 after the stop - final I2) / final I2; >rated = time with I2 above the rated 15 A; "
          "energy into the battery node (after = of it, after the stop command); track = RMS(I_L - command); "
          "cost = sum of the env's overcurrent cost")
    for f in figs:
        print(f"figure: {f}")
    return 0
