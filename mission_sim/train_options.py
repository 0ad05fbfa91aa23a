"""``policies.train.train``'s options that have an effect only with another one (:data:`ONLY_WITH`) and the rule
refusing one given without it (:func:`unused_option`), numpy-free: ``dronewpt train`` refuses a misuse before it
imports ``policies`` (numpy, the policies, ``policies.train``: ~0.3 s at a free machine's start, more when loaded);
``policies.train`` reads the same table (their values when not given: ``policies.train.ONLY_WITH_DEFAULTS``). Also
the ranges of train's number options (:data:`RANGES`), one table for ``train()`` and ``dronewpt train``'s parser."""

from __future__ import annotations

import math
from collections.abc import Mapping

from .validation import SEED_RANGE, Range

__all__ = ["ONLY_WITH", "unused_option", "ALGO_ONLY", "algo_conflict", "RANGES"]

#: train()'s number options and their ranges: ``train()`` checks its keyword arguments against them
#: (``mission_sim.validation.check_number``) and ``dronewpt train``'s --seed, --n-envs, --eval-every, --eval-episodes,
#: --checkpoint-every and --lambda-lr are parsed with them (``cli.common.range_arg``): one table, the same range text
#: (two tables until 2026-11-27 evening, ``policies.train._COUNTS`` and the parser's)
RANGES = {"seed": SEED_RANGE, "n_envs": Range(1, 1024, integer=True), "eval_every": Range(1, math.inf, integer=True),
          "eval_episodes": Range(1, math.inf, integer=True), "checkpoint_every": Range(1, math.inf, integer=True),
          "lambda_lr": Range(0, math.inf, lo_open=True, hi_open=True)}

#: train's options that have an effect only with another one: {option: the option it needs}. One given (not None)
#: without it is refused, by ``train()`` (``ValueError``) and ``dronewpt train`` (exit 2) alike (:func:`unused_option`)
ONLY_WITH = {"lambda_lr": "lagrangian", "probe_episodes": "lagrangian", "residual_scale": "residual",
             "residual_base_budget": "residual", "dagger": "imitate", "imitation_episodes": "imitate",
             "imitation_epochs": "imitate", "imitation_mask": "imitate", "slow_budget_every": "slow_budget",
             "budget": "lagrangian"}


def unused_option(opts: Mapping) -> tuple[str, str] | None:
    """``(option, the option it needs)`` for the first option of :data:`ONLY_WITH` that ``opts`` gives (a value other
    than None, even the default's) while the option it needs is off (False, None or empty); None when there is none."""
    for opt, needs in ONLY_WITH.items():
        if opts.get(opt) is not None and not opts.get(needs):
            return opt, needs
    return None


#: options that only some algorithms take: {option: (the algorithms that take it, why)}. One given (true) with another
#: ``algo`` is refused by ``train()`` (``ValueError``) and ``dronewpt train`` (exit 2, before ``--out`` is made) alike
#: (:func:`algo_conflict`): before, ``--algo dqn --residual`` and ``--algo sac --imitate mpc`` were refused by
#: ``train()`` only, after ``--out`` was made, and ``--algo dqn --action-filter`` trained, wrote part of its outputs,
#: then stopped at the discrete env's "actions=0.13 is invalid"
ALGO_ONLY = {"imitate": (("ppo",), "the student is a PPO actor"),
             "residual": (("ppo", "sac", "td3"), "a continuous correction"),
             "action_filter": (("ppo", "sac", "td3"), "a low-passed duty is not 0 or 1")}


def algo_conflict(opts: Mapping) -> tuple[str, tuple[str, ...], str] | None:
    """``(option, the algorithms that take it, why)`` for the first option of :data:`ALGO_ONLY` that ``opts`` gives
    (true) with an ``algo`` (default ``ppo``) that does not take it; None when there is none."""
    algo = opts.get("algo") or "ppo"
    for opt, (algos, why) in ALGO_ONLY.items():
        if opts.get(opt) and algo not in algos:
            return opt, algos, why
    return None
