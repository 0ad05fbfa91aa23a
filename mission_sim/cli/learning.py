"""``dronewpt train`` and ``dronewpt compare``: RL training and the head-to-head policy comparison."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..validation import check_regular_file
from .common import (
    CliError,
    add_progress_flag,
    figures_out,
    float_arg,
    TRAIN_TIMESTEPS_RANGE,
    int_in,
    lazy_names_help,
    name_list,
    path_arg,
    policy_names,
    prepare_out_dir,
    range_arg,
    scenario_names,
    seed_int,
    show_progress,
    startup_gc_paused,
)


#: the command line's own defaults of train's options that have an effect only with another one, where they differ
#: from ``train()``'s (the others stay None and ``train()`` fills them from ``policies.train.ONLY_WITH_DEFAULTS``;
#: which option each needs: :data:`mission_sim.train_options.ONLY_WITH`)
_CLI_ONLY_WITH_DEFAULTS = {"imitation_epochs": 60}


_TRAIN_DESCRIPTION = ("Train PPO, SAC or TD3 on dronewpt/SbarCharging-v0 or DQN on the discrete (ON-OFF) "
                      "variant on the batched env adapter; optionally Lagrangian (episode cost against a "
                      "budget) and / or residual on the model-based controller, from a behaviour clone "
                      "(--imitate) or with a slow-variable action (--slow-budget). Writes the model zip, "
                      "its metadata JSON, vecnormalize.pkl, the Monitor CSV (return and cost), evaluation "
                      "on held-out seeds (best model, curve), checkpoints, TensorBoard logs when "
                      "installed and a learning curve PNG.")


def _add_train(sub):
    from ..train_options import RANGES   # (numpy-free: train()'s ranges, read by its parser too)
    p = sub.add_parser("train", help="train an RL mode-switching policy (stable-baselines3)",
                       description=_TRAIN_DESCRIPTION)
    p.add_argument("--algo", choices=("ppo", "sac", "td3", "dqn"), required=True)
    p.add_argument("--timesteps", type=int_in("timesteps", 0, valid=TRAIN_TIMESTEPS_RANGE), required=True,
                   help="environment steps to train for, an integer (1e5: write 100000 or 100_000)")
    p.add_argument("--out", type=path_arg("--out"), required=True, help="output folder")
    p.add_argument("--seed", type=range_arg("seed", RANGES["seed"]), default=0, help=f"seed, {RANGES['seed'].text()} (default 0)")
    p.add_argument("--n-envs", type=range_arg("n-envs", RANGES["n_envs"]), default=64,
                   help=f"parallel windows of the batched env, {RANGES['n_envs'].text()} (default 64)")
    lazy_names_help(p.add_argument("--scenario", default="random"),
                    "training scenario (default random: domain randomisation)", scenario_names)
    p.add_argument("--hyperparams", type=path_arg("--hyperparams"), default=None, metavar="FILE",
                   help="YAML or JSON model arguments, rl-baselines3-zoo style (policy_kwargs as a dict or "
                        "'dict(...)'); override the defaults")
    p.add_argument("--env", action="append", default=[], metavar="KEY=VALUE",
                   help="env config / reward weight override, repeatable: n_steps, slow_every, rated_i2_a, "
                        "bus_c_f, dt_s, tracking, overcurrent, i_ref_a, device_tj_c, hold_tol_a, v2_updates, "
                        "v2_refine_levels, v2_refine_tol; devices=PRESET (ideal, schottky, sic; "
                        "default schottky); link_model=envelope|modal (or --link, not both with different values)")
    _add_link_flag(p)
    p.add_argument("--cost", choices=("overshoot", "overcurrent"), default="overshoot",
                   help="episode cost: overshoot = max(0, peak |I2| after the stop / true short-mode I2 - 1) "
                        "(default); overcurrent = sum of max(0, |I2|/rated - 1) per step")
    p.add_argument("--lagrangian", action="store_true", help="learn a multiplier of the episode cost against --budget")
    p.add_argument("--budget", type=float_arg("--budget", positive=True), default=None,
                   help="mean episode cost allowed (default: the ramp policy's on the training scenario)")
    p.add_argument("--lambda-lr", type=range_arg("--lambda-lr", RANGES["lambda_lr"]),
                   help="multiplier step per rollout at a cost 100 %% over budget (default 50)")
    p.add_argument("--probe-episodes", type=int,
                   help="deterministic windows the multiplier's cost is measured on after every rollout "
                        "(default 32; 0 = the stochastic rollouts themselves)")
    p.add_argument("--residual", action="store_true", help="learn a bounded correction of the model-based duty")
    p.add_argument("--residual-scale", type=float_arg("--residual-scale", positive=True, hi=1.0),
                   help="largest duty correction (default 0.25)")
    p.add_argument("--residual-base-budget", type=float_arg("--residual-base-budget"),
                   help="overshoot budget of the model-based controller the residual corrects (default 0: the "
                        "paper's controller)")
    p.add_argument("--slow-budget", default=None, metavar="LO:HI",
                   help="the action is the MPC's measured-overshoot budget in [LO, HI] per control period, the duty "
                        "the MPC's (a slow variable: no dither of the duty; policies.slow_budget), e.g. 0:0.15")
    p.add_argument("--slow-budget-every", choices=("window", "step"),
                   help="with --slow-budget: take the agent's budget once per window at the stop and hold it "
                        "(default) or every control period")
    p.add_argument("--history", type=int, default=1, metavar="K",
                   help="frame stack: the policy sees the last K observations (default 1; envs.history)")
    p.add_argument("--action-filter", type=float_arg("--action-filter"), default=0.0, metavar="ALPHA",
                   help="low-pass the duty: d = ALPHA d_prev + (1 - ALPHA) d_new, in training and at inference "
                        "(default 0: off; policies.smoothing)")
    p.add_argument("--smooth-penalty", type=float_arg("--smooth-penalty"), default=0.0, metavar="W",
                   help="reward minus W (d - d_prev)^2 per step (default 0: off)")
    p.add_argument("--imitate", default=None, metavar="TEACHER",
                   help="behaviour-clone the policy TEACHER first (a policy name: mpc, mpc:0.05, "
                        "model_based_budget:0.02, ...; privileged:NAME = the teacher sees the present, noise-free "
                        "currents); --timesteps then counts PPO fine-tuning steps (0: imitation only, the clone is "
                        "OUT/ppo_sbar.zip; otherwise the clone is kept as OUT/clone.zip + clone.json, the "
                        "fine-tuned model is OUT/ppo_sbar.zip and starts from the clone's log_std, not "
                        "log_std_init; policies.imitation)")
    p.add_argument("--dagger", type=int, metavar="N",
                   help="DAgger iterations after behaviour cloning (default 0)")
    p.add_argument("--imitation-episodes", type=int, help="windows per imitation iteration (default 64)")
    p.add_argument("--imitation-epochs", type=int, help="passes over the data per fit (default 60)")
    p.add_argument("--imitation-mask", metavar="FIELD,...",
                   help="observation fields hidden from the student (default last_d_short; add i2_amp_a,"
                        "battery_current_a,rect_current_a for a feed-forward student; '' for none)")
    p.add_argument("--eval-every", type=range_arg("eval-every", RANGES["eval_every"]), default=50_000,
                   help="env steps between evaluations (default 50000)")
    p.add_argument("--eval-episodes", type=range_arg("eval-episodes", RANGES["eval_episodes"]), default=32,
                   help="held-out evaluation windows (default 32)")
    p.add_argument("--checkpoint-every", type=range_arg("checkpoint-every", RANGES["checkpoint_every"]), default=100_000,
                   help="env steps between checkpoints (default 100000)")
    p.add_argument("--resume", type=path_arg("--resume"), default=None, metavar="CHECKPOINT.zip",
                   help="continue from a checkpoint of checkpoints/ (its VecNormalize statistics next to it)")
    add_progress_flag(p)
    p.set_defaults(func=_cmd_train)   # ONLY_WITH's options default to None (not given): train() fills them


#: :data:`mission_sim.contract.LINK_MODELS` (not imported: the parser stays free of wpt_receiver's import;
#: tests/test_mpc_modal.py checks they agree)
LINK_CHOICES = ("envelope", "modal")


def _add_link_flag(p):
    """``--link {envelope,modal}``: the envs' plant (``envs.EnvConfig.link_model``)."""
    p.add_argument("--link", choices=LINK_CHOICES, default=None,
                   help="the env's link model: modal = the mission's exact-mode link (default since 2026-11-26; "
                        "peaks within 0.23 %% of the switching model; an env-step costs ~15x (duty held) to "
                        "~100x (random actions) the envelope's CPU; compare's default rows 5-6x its wall time on "
                        "two free cores, 6-9x its CPU: docs/performance.md), envelope = eq. 4 with the ripple table "
                        "(what the shipped RL models were trained on); docs/envs.md")


def _link_config(args):
    """The :class:`envs.EnvConfig` of ``--link`` (None without it: the envs' own default, the modal link)."""
    if args.link is None:
        return None
    from envs import EnvConfig
    return EnvConfig(link_model=args.link)


def _link_name(args) -> str:
    """The link the envs of this command run on: ``--link``, else the envs' default (``EnvConfig.link_model``)."""
    if args.link is not None:
        return args.link
    from envs import EnvConfig
    return EnvConfig.link_model


def _env_overrides(items) -> dict:
    from .common import parse_set
    out = {}
    for k, v in parse_set(items, "--env").items():
        if k in ("devices", "link_model") and isinstance(v, str):
            out[k] = v
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise CliError(f"--env {k}={v!r} is invalid; valid: KEY=NUMBER")
        out[k] = v
    return out


def _only_with(args):
    """An option of :data:`mission_sim.train_options.ONLY_WITH` given without the option that uses it is refused
    (given, even at its default value: it had no effect; the error names its value); then the ones not given whose
    option is on get :data:`_CLI_ONLY_WITH_DEFAULTS`; the others stay None (not given: ``train()`` fills them)."""
    from ..train_options import ONLY_WITH, unused_option
    unused = unused_option(vars(args))
    if unused is not None:   # before: trained without it, exit 0
        value = getattr(args, unused[0])
        flag, needs = ("--" + o.replace("_", "-") for o in unused)
        raise CliError(f"{flag} {value!r} is only used with {needs}; valid: add {needs}, or drop {flag}")
    for dest, default in _CLI_ONLY_WITH_DEFAULTS.items():
        if getattr(args, dest) is None and getattr(args, ONLY_WITH[dest]):
            setattr(args, dest, default)


def _check_train(args):
    """One-line errors (``CliError``); those that need no import of numpy, envs or policies first (a misuse was
    refused after ``policies.train`` was imported)."""
    _only_with(args)
    lo = 0 if args.imitate else 1
    if args.timesteps < lo:
        raise CliError(f"--timesteps {args.timesteps} is invalid; valid range: {TRAIN_TIMESTEPS_RANGE}")
    for flag, v, lo in (("--dagger", args.dagger, 0), ("--imitation-episodes", args.imitation_episodes, 1),
                        ("--imitation-epochs", args.imitation_epochs, 1)):
        if v is not None and v < lo:
            raise CliError(f"{flag} {v} is invalid; valid range: >= {lo}")
    if not 0.0 <= args.action_filter < 1.0:
        raise CliError(f"--action-filter {args.action_filter} is invalid; valid range: [0, 1)")
    from ..train_options import algo_conflict
    bad = algo_conflict(vars(args))   # (before: refused by train() only, after --out was made, in Python's words)
    if bad:
        opt, algos, why = bad
        flag = "--" + opt.replace("_", "-")
        given = "" if opt == "residual" else f" {getattr(args, opt):g}" if opt == "action_filter" else f" {getattr(args, opt)}"
        raise CliError(f"--algo {args.algo} is invalid with {flag}{given}; valid: --algo {', '.join(algos[:-1])}"
                       f"{' or ' if len(algos) > 1 else ''}{algos[-1]} ({why}), or drop {flag}")
    if args.smooth_penalty < 0.0:
        raise CliError(f"--smooth-penalty {args.smooth_penalty} is invalid; valid range: >= 0")
    if args.probe_episodes is not None and not 0 <= args.probe_episodes <= 1024:
        raise CliError(f"--probe-episodes {args.probe_episodes} is invalid; valid range: 0..1024")
    from mission_sim.contract import OBS_INDEX, check_history
    try:   # (the library's rule and words, train()'s and the envs'; its own copy here until 2026-11-27 night)
        check_history(args.history)
    except ValueError as exc:
        from .notices import flag_words
        raise CliError(flag_words("train", str(exc))) from None
    for f in _imitation_mask(args) or ():
        if f not in OBS_INDEX:
            raise CliError(f"--imitation-mask {f!r} is invalid; valid values: {', '.join(OBS_INDEX)}")
    if args.imitate is not None:
        from policies import available
        teacher = args.imitate[len("privileged:"):] if args.imitate.startswith("privileged:") else args.imitate
        if teacher.split(":", 1)[0] not in available():
            raise CliError(f"--imitate {args.imitate!r} is invalid; valid values: a policy name ({', '.join(available())}"
                           "), optionally privileged:NAME")
    if args.scenario not in scenario_names():
        raise CliError(f"--scenario {args.scenario!r} is invalid; valid values: {', '.join(scenario_names())}")
    for flag, path in (("--hyperparams", args.hyperparams), ("--resume", args.resume)):
        if path is not None:
            check_regular_file(path, flag)  # a FIFO is refused without opening it
    if args.slow_budget is not None:
        from policies.slow_budget import parse_budget_range
        try:
            parse_budget_range(args.slow_budget)
        except ValueError as exc:
            raise CliError(f"--slow-budget: {exc}") from None
        if args.algo == "dqn" or args.residual or args.imitate or args.action_filter or args.smooth_penalty:
            raise CliError("--slow-budget is invalid with --algo dqn, --residual, --imitate, --action-filter or "
                           "--smooth-penalty; valid: --algo ppo / sac / td3 without them (the duty is the MPC's)")


def _imitation_mask(args) -> tuple | None:
    """``--imitation-mask``'s fields (None: not given)."""
    if args.imitation_mask is None:
        return None
    return tuple(f.strip() for f in args.imitation_mask.split(",") if f.strip())


def _cmd_train(args) -> int:
    _check_train(args)
    env = _env_overrides(args.env)
    if args.link is not None:
        if env.get("link_model", args.link) != args.link:
            raise CliError(f"--link {args.link} conflicts with --env link_model={env['link_model']}; valid: one of "
                           "them, or both with the same value")
        env["link_model"] = args.link
    from policies.train import env_config
    try:   # a bad --env key or value is refused before anything is written
        env_config(env)
    except ValueError as exc:
        raise CliError(f"--env: {exc}") from None
    from policies import require_sb3
    require_sb3()
    if args.hyperparams is not None:  # malformed, unknown keys, wrong types: refused before --out is created
        import stable_baselines3 as sb3

        from policies.hyperparams import load_hyperparams
        load_hyperparams(args.hyperparams, getattr(sb3, args.algo.upper()))
    from policies.train import earlier_run, train
    held = None if args.resume is not None else earlier_run(args.out, f"{args.algo}_sbar")
    if held:   # (it replaced an earlier run's model and logs without a word)
        raise CliError(f"--out {str(args.out)!r} holds an earlier training run ({held}), which this run would "
                       "replace; valid: a new --out folder, --resume <one of its models> to go on training it, "
                       "or remove the folder")
    prepare_out_dir(args.out)
    try:
        res = train(args.algo, args.timesteps, args.out, seed=args.seed, n_envs=args.n_envs, scenario=args.scenario,
                    progress=show_progress(args), hyperparams_file=args.hyperparams, env=env, cost=args.cost,
                    lagrangian=args.lagrangian, budget=args.budget, lambda_lr=args.lambda_lr, residual=args.residual,
                    residual_scale=args.residual_scale, eval_every=args.eval_every,
                    eval_episodes=args.eval_episodes, checkpoint_every=args.checkpoint_every, resume=args.resume,
                    probe_episodes=args.probe_episodes, residual_base_budget=args.residual_base_budget,
                    history=args.history, action_filter=args.action_filter, smooth_penalty=args.smooth_penalty,
                    imitate=args.imitate, dagger=args.dagger, imitation_episodes=args.imitation_episodes,
                    imitation_epochs=args.imitation_epochs, slow_budget=args.slow_budget,
                    slow_budget_every=args.slow_budget_every,
                    imitation_mask=_imitation_mask(args))
    except ValueError as exc:
        raise CliError(str(exc)) from None
    for key, path in res.items():
        print(f"{key}: {path}")
    from policies.train import final_summary
    summary = final_summary(json.loads(Path(res["meta"]).read_text()), str(res.get("model", "MODEL.zip"))) \
        if "meta" in res else None
    if summary is not None:
        print(summary)
    return 0


def _add_compare(sub):
    p = sub.add_parser("compare", help="compare mode-switching policies head to head, with statistics",
                       description="Run every policy through the same closed loop on the same seeded charging "
                                   "windows (batched env); print per policy and scenario the mean with a 95 % "
                                   "bootstrap interval of overshoot, fraction reaching short mode, peak I2, "
                                   "energy before / after the stop, tracking, cost and return, and the paired "
                                   "difference against model_based; write the RM -> SM transitions and the "
                                   "return / energy-after-stop versus overshoot figure with the Pareto front and "
                                   "the budgeted model-based curve.")
    lazy_names_help(p.add_argument("--policies", default=None),
                    "comma-separated policy names (default: step,ramp,hysteresis,model_based,model_based_online,"
                    "model_based_budget:0.01,model_based_budget:0.02,mpc,rl,ppo_lagrangian,residual,random; the learned "
                    "rows rl, ppo_lagrangian, residual and imitation are each one row over their shipped training "
                    "seeds; the SB3 ones are skipped with a note when stable-baselines3 is not installed)",
                    policy_names)
    lazy_names_help(p.add_argument("--scenarios", default=None),
                    "comma-separated scenarios (default: nominal,lm_mismatch,windy,battery,lm_high,lm_drift,lm_drift_fast,"
                    "sense_delay,sense_delay_long,battery_low,battery_empty,detuned,detuned_wide; lm_high is outside "
                    "the training range, each model-is-wrong scenario has a held-out variant; on the default "
                    "exact-mode link the whole default set takes ~5-10 min)", scenario_names)
    p.add_argument("--episodes", type=int, default=100, help="episodes per scenario (default 100)")
    p.add_argument("--seed", type=seed_int(), default=1000,
                   help="seed of episode 0 (episode i uses seed + i), 0 .. 2^32-1 (default 1000)")
    p.add_argument("--train-seeds", action="append", default=[], metavar="LABEL=SPEC,SPEC,...",
                   help="one row aggregated over models of one kind trained with different seeds, e.g. "
                        "ppo_lag=rl:a/ppo_sbar.zip,rl:b/ppo_sbar.zip (a glob in a path is expanded); repeatable "
                        "(default with the default --policies: the shipped rl, ppo_lagrangian, residual and imitation seeds); "
                        "without --policies a LABEL that names a default row replaces that row")
    p.add_argument("--no-frontier", action="store_true", help="skip the budgeted model-based sweep")
    p.add_argument("--oracle-windows", type=int, default=0, metavar="N",
                   help="on the first scenario's first N windows: the oracle (best open-loop duty sequence after "
                        "the stop, policies.oracle; cached on disk) curve in the frontier figure and every policy's "
                        "gap to it at its own overshoot (default 0: off; ~2-5 s CPU per window and policy the "
                        "first time)")
    _add_link_flag(p)
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--out", type=path_arg("--out"), default=None,
                   help="folder for the figures (default out/compare; not with --no-plot)")
    p.add_argument("--no-plot", action="store_true", help="skip the figures")
    add_progress_flag(p)
    p.set_defaults(func=_cmd_compare)


def _train_seed_groups(items) -> dict:
    """``LABEL=SPEC,SPEC`` -> {label: [spec, ...]} (globs in paths expanded, sorted)."""
    import glob
    out = {}
    for item in items:
        label, sep, rest = item.partition("=")
        if not sep or not label.strip() or not rest.strip():
            raise CliError(f"--train-seeds {item!r} is invalid; valid form: LABEL=SPEC,SPEC,... (SPEC e.g. rl:PATH)")
        specs = []
        for sp in (x.strip() for x in rest.split(",") if x.strip()):
            base, colon, path = sp.partition(":")
            hits = sorted(glob.glob(path)) if colon and any(c in path for c in "*?[") else [path] if colon else []
            if colon and not hits:
                raise CliError(f"--train-seeds {sp!r} is invalid: no file matches {path!r}")
            specs += [f"{base}:{h}" for h in hits] if colon else [sp]
        if label.strip() in out:   # a second group of the same label replaced the first without a word
            raise CliError(f"--train-seeds {item!r}: label {label.strip()!r} is given twice; valid: one "
                           "--train-seeds per label (its specs comma-separated)")
        out[label.strip()] = specs
    return out


def sb3_installed() -> bool:
    import importlib.util
    return importlib.util.find_spec("stable_baselines3") is not None


_SB3_POLICIES = ("rl", "ppo_lagrangian", "residual", "imitation", "slow_budget")


def _rl_or_skip(pols: tuple, explicit: bool) -> tuple:
    """Without stable-baselines3 the default SB3 rows (rl, ppo_lagrangian, residual) are skipped with
    a note on stderr; one the user asked for with ``--policies`` is an error naming the extra to install."""
    sb3_rows = [p_ for p_ in pols if p_.split(":", 1)[0] in _SB3_POLICIES]
    if not sb3_rows or sb3_installed():
        return pols
    if explicit:
        raise CliError(f"--policies {sb3_rows[0]} needs stable-baselines3 (with torch): pip install 'dronewpt[rl]'")
    print(f"dronewpt compare: note: skipping the {', '.join(sb3_rows)} rows: stable-baselines3 is not installed "
          "(pip install 'dronewpt[rl]')", file=sys.stderr)
    return tuple(p_ for p_ in pols if p_ not in sb3_rows)


def _mpc_or_skip(pols: tuple, explicit: bool) -> tuple:
    """Without daqp the default ``mpc`` row is skipped with a note; asked for with ``--policies`` it is an error."""
    import importlib.util
    rows = [p_ for p_ in pols if p_.split(":", 1)[0] == "mpc"]
    if not rows or importlib.util.find_spec("daqp") is not None:
        return pols
    if explicit:
        raise CliError(f"--policies {rows[0]} needs the QP solver daqp: pip install 'dronewpt[mpc]'")
    print("dronewpt compare: note: skipping the mpc row: daqp is not installed (pip install 'dronewpt[mpc]')",
          file=sys.stderr)
    return tuple(p_ for p_ in pols if p_ not in rows)


def _shipped_seed_rows(pols: tuple):
    """At the defaults the shipped learned kinds with several training seeds are one row each,
    aggregated over their seeds (instead of the seed-0 row)."""
    from policies.compare import OPT_IN_SEEDS, shipped_seed_groups
    groups = {k: v for k, v in shipped_seed_groups().items() if k not in OPT_IN_SEEDS}
    return tuple(p_ for p_ in pols if p_ not in groups), groups


def _check_compare(args, pols, scns, groups):
    from envs import SCENARIOS
    from policies import available
    from policies.compare import EPISODES, check_row_labels

    from ..validation import seed_range
    try:
        check_row_labels(pols, groups)
    except ValueError as exc:   # (policies lists the model 'rl:...' twice (also as 'rl'): the --policies' own)
        text = str(exc)
        raise CliError("--" + text if text.startswith("policies ") else f"--train-seeds: {text}" if groups
                       else text) from None
    for p_ in pols + tuple(sp for specs in groups.values() for sp in specs):
        if p_.split(":", 1)[0] not in available():
            raise CliError(f"--policies {p_!r} is invalid; valid values: {', '.join(available())} (or rl:PATH)")
    for s_ in scns:
        if s_ not in SCENARIOS:
            raise CliError(f"--scenarios {s_!r} is invalid; valid values: {', '.join(SCENARIOS)}")
    if not EPISODES.contains(args.episodes):   # (policies.compare's ranges: one table, read at the call)
        raise CliError(f"--episodes {args.episodes} is invalid; valid range: {EPISODES.text()}")
    args.out = figures_out(args, "out/compare")
    if not 0 <= args.oracle_windows <= args.episodes:
        raise CliError(f"--oracle-windows {args.oracle_windows} is invalid; valid range: 0..{args.episodes} (--episodes)")
    seeds = seed_range(args.episodes)
    if not seeds.contains(args.seed):
        raise CliError(f"--seed {args.seed} is invalid with --episodes {args.episodes}; valid range: "
                       f"{seeds.text()} (episode seeds go up to seed + episodes - 1)")


def _listed(text: str, flag: str) -> tuple:
    """The names of ``--policies`` / ``--scenarios`` (an empty list, ``''`` or ``','``, is refused)."""
    from envs import SCENARIOS
    from policies import available
    valid = [*available()] if flag == "--policies" else list(SCENARIOS)
    return tuple(name_list(text, flag, valid))


def _cmd_compare(args) -> int:
    return startup_gc_paused(_compare_command, args)   # (cli/common.py: the collector off through the start-up)


def _compare_command(args, started) -> int:
    from wpt_receiver.numba_start import cache_loads_without_registries, prepare
    prepare()   # numba's start-up without importing the scipy.linalg package (~0.3 s of CPU)
    from policies.compare import DEFAULT_POLICIES, DEFAULT_SCENARIOS, compare, frontier, frontier_specs

    pols = DEFAULT_POLICIES if args.policies is None else _listed(args.policies, "--policies")
    scns = DEFAULT_SCENARIOS if args.scenarios is None else _listed(args.scenarios, "--scenarios")
    groups = _train_seed_groups(args.train_seeds)
    if not args.policies and not args.train_seeds and sb3_installed():
        pols, groups = _shipped_seed_rows(pols)
    elif args.policies is None:   # a group labelled as a default row replaces it (docs/rl.md, "Comparison")
        pols = tuple(p_ for p_ in pols if p_ not in groups)
    _check_compare(args, pols, scns, groups)
    cache_loads_without_registries()   # cached kernels loaded without numba's registries (~0.3 s of CPU)
    pols = _rl_or_skip(pols, explicit=bool(args.policies))
    pols = _mpc_or_skip(pols, explicit=bool(args.policies))
    if not args.no_plot:
        prepare_out_dir(args.out)
    cfg = _link_config(args)
    started()   # the start-up's objects frozen, the collector back on for the runs (startup_gc_paused)
    try:
        more, early = {}, []   # the frontier's budgets run in compare's batched env (one rollout, not two)

        def _frontier_rows(extra_traces):   # its rows while the MPC's child still runs (no bar: ~50 ms)
            early.append(frontier(scns[0], episodes=args.episodes, seed=args.seed, config=cfg, traces=extra_traces))
        rows, traces = compare(pols, scns, args.episodes, args.seed, progress=show_progress(args), train_seeds=groups,
                               extra=() if args.no_frontier else frontier_specs(), extra_traces=more, config=cfg,
                               on_extra=_frontier_rows)
        sweep = [] if args.no_frontier else early[0] if early else frontier(
            scns[0], episodes=args.episodes, seed=args.seed, config=cfg, progress=show_progress(args),
            traces={**more, **traces})
        curve = _oracle(args, rows, traces, scns[0], cfg)
    except (ValueError, FileNotFoundError) as exc:
        raise CliError(str(exc)) from None
    figs = [] if args.no_plot else _compare_figures(traces, rows, sweep, scns[0], args.out, curve)
    if args.format == "json":
        print(json.dumps({"episodes": args.episodes, "seed": args.seed, "link": _link_name(args), "rows": rows,
                          "frontier": sweep,
                          "oracle": [{k: v for k, v in r.items() if k != "per_window"} for r in curve],
                          "figures": figs}))
        return 0
    _print_compare(rows, sweep, args)
    for f in figs:
        print(f"figure: {f}")
    return 0


def _oracle(args, rows, traces, scenario, cfg=None) -> list:
    """The oracle curve and gaps of ``--oracle-windows`` (rows updated in place); [] when off."""
    if not args.oracle_windows:
        return []
    from policies.compare import oracle_curve, oracle_gaps
    oracle_gaps(rows, traces, scenario, args.oracle_windows, args.seed, config=cfg, progress=show_progress(args))
    return oracle_curve(scenario, args.oracle_windows, args.seed, config=cfg, progress=show_progress(args))


def _compare_figures(traces, rows, sweep, scenario, out, curve=()) -> list[str]:
    from policies.compare import plot_frontier, plot_transitions
    return [str(plot_transitions(traces, scenario, out / f"transitions_{scenario}.png")),
            str(plot_frontier(rows, sweep, scenario, out / f"frontier_{scenario}.png", oracle=list(curve)))]


def _ci(r, k, scale=1.0, fmt="{:.2f}"):
    return f"{fmt.format(r[k] * scale)} [{fmt.format(r[k + '_lo'] * scale)}, {fmt.format(r[k + '_hi'] * scale)}]"


def _print_compare(rows, sweep, args):
    print(f"{args.episodes} episodes per scenario, seeds {args.seed}..{args.seed + args.episodes - 1}; mean "
          "[95 % interval]: bootstrap over episodes, or t over training seeds when seeds > 1")
    if _link_name(args) == "modal":
        print("plant: the exact-mode link (the default; --link envelope for eq. 4's); mpc predicts with its modes "
              "(policies.mpc_modal), model_based_budget plans its after-stop duties with them (policies.budget_modal)")
    # column widths from the cells (2026-11-28: lm_drift_fast, sense_delay_long and intervals such as
    # 197.98 [150.16, 244.68] overran the fixed widths and shifted the rest of their rows)
    cells = [(r["scenario"], r["policy"][:24], _ci(r, "overshoot_pct"), _ci(r, "energy_after_stop_j", fmt="{:.3f}"),
              _ci(r, "return", fmt="{:.1f}"), _ci(r, "d_return", fmt="{:.1f}") if "d_return" in r else "(reference)")
             for r in rows]
    w = [max([n, *(len(c[i]) for c in cells)]) for i, n in enumerate((12, 24, 20, 20, 22, 24))]
    hdr = (f"{'scenario':<{w[0]}} {'policy':<{w[1]}} {'seeds':>5} {'overshoot %':>{w[2]}} {'in SM':>5} "
           f"{'peak I2 A':>9} {'E before J':>10} {'E after J':>{w[3]}} {'track A':>7} {'return':>{w[4]}} "
           f"{'d return vs model_based':>{w[5]}}")
    print(hdr)
    print("-" * len(hdr))
    for r, (scn, pol, over, after, ret, d) in zip(rows, cells):
        print(f"{scn:<{w[0]}} {pol:<{w[1]}} {r['train_seeds']:>5} {over:>{w[2]}} "
              f"{r['reached_short_mode']:>5.2f} {r['peak_i2_a']:>9.2f} {r['energy_before_stop_j']:>10.3f} "
              f"{after:>{w[3]}} {r['tracking_rmse_a']:>7.2f} {ret:>{w[4]}} {d:>{w[5]}}")
    print("overshoot = peak |I2| after the stop over the true link's short-mode I2, minus 1; in SM = fraction of "
          "episodes with I_L < 0.5 A from 14 ms after the stop on; E after = energy delivered after the stop")
    if any(r["policy"].startswith("model_based_budget") for r in rows) or sweep:
        if _link_name(args) == "modal":
            print("model_based_budget:b: b = the measured overshoot allowed above F, the overshoot the controller "
                  "predicts at the stop for its plan at b = 0, the paper's controller (within 0.2 point of "
                  "model_based's measured overshoot; not the window's oracle floor, which is lower); b = 0.02: "
                  "measured 0.5-1.9 points above F, bound 2.6; mpc:b: b = the measured overshoot allowed, or the "
                  "window's floor if higher")
        else:
            print("model_based_budget:b: b = the relaxation of the controller's reference after the stop, (1 + b) "
                  "I2_sm: eq. 4's envelope promise, not the measured overshoot (about 100 b + 3.3 % on nominal, "
                  "5.45 % at b = 0.02); mpc:b: b = the measured overshoot allowed, or the window's floor if higher")
    gaps = [r for r in rows if "oracle_gap_pct" in r]
    if gaps:
        print(f"gap to the oracle ({gaps[0]['scenario']}, first {args.oracle_windows} windows; energy after the stop "
              "above the best open-loop sequence at the policy's own overshoot, windows in short mode): " + "; ".join(
                  f"{r['policy']} {_ci(r, 'oracle_gap_pct', fmt='{:.1f}')} % ({r['oracle_windows']} w)" for r in gaps))
    if sweep:
        print(f"budgeted model-based curve ({sweep[0]['scenario']}): " + "; ".join(
            f"b={r['budget']:g}: {r['overshoot_pct']:.2f} %, {r['energy_after_stop_j']:.3f} J, return {r['return']:.1f}"
            for r in sweep))
