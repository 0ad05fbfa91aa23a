"""Policies behind one protocol (:class:`mission_sim.contract.Policy`), made by name.

Modules: ``classical`` (step, ramp, model_based), ``kernels`` (their compiled per-step functions for
the mission's fast path; numba, imported on demand), ``onoff``, ``online``, ``budgeted``, ``budget_modal``,
``budget_scan``, ``random_policy``, ``mpc``, ``oracle``, ``rl`` / ``residual`` / ``constrained`` / ``imitation`` / ``obs_mask`` / ``smoothing`` /
``train`` / ``callbacks`` / ``hyperparams`` / ``slow_budget`` (RL, needs stable-baselines3), ``oracle_imitation`` / ``oracle_imitation_train`` / ``oracle_imitation_filter``, ``inference``,
``compare``, ``batched``, ``forked``, ``stats``, ``threads``.

>>> from policies import make
>>> pol = make("model_based")

Modules, from the classical controllers to learning and comparing:

=================  ==========================================================================
``classical``      step, ramp and the paper's model-based inverse controller (Fig. 5)
``mpc``            model-predictive control: receding-horizon QP in V2 on the nominal model (daqp)
``mpc_modal``      the MPC's prediction model on the exact-mode link (the context's ``link_model="modal"``)
``mpc_lock``       the modal MPC's after-stop prediction with the rectifier's phase lock (V2 turned onto I2's phase;
                   numba), its rows and derivatives for the sequential convex iterations, the estimator's locked step
``oracle``         the per-window limit: best open-loop duty sequence after the stop (SLSQP)
``budgeted``       the model-based controller with an overshoot budget (the classical frontier)
``budget_modal``   its after-stop plan predicted on the exact-mode link (the context's ``link_model="modal"``)
``budget_scan``    that plan's relaxation search compiled (numba): the coarse pass and the fine scan over blocks of plans
``online``         the model-based controller with an online Lm estimate
``onoff``          hysteresis ON-OFF (the classic unsynchronised mode switching)
``random_policy``  uniformly random duties (the floor)
``rl``             a stable-baselines3 model file behind the protocol (``rl`` extra)
``inference``      the SB3 actor exported to numpy for fast deterministic inference
``residual``       model-based duty plus a bounded learned correction
``constrained``    Lagrangian cost penalty and residual action space on SB3
``imitation``      behaviour cloning / DAgger of a (privileged) teacher into an SB3 PPO actor
``obs_mask``       observation fields held at exactly 0 at the network input (imitation's mask, kept by PPO)
``smoothing``      low-pass filtered duty and duty-change penalty (SAC / TD3 / PPO train options)
``slow_budget``    a learned policy acting in a slow variable: the MPC's overshoot budget per step
``oracle_imitation``  the oracle's after-stop sequence learned from the stop observation (amortised imitation)
``oracle_imitation_train``  its training side: stop observations, the oracle's sequences, open-loop scoring
``oracle_imitation_filter``  that sequence as the reference of a safety filter on the MPC's model after the stop
``callbacks``      SB3 callbacks of ``train``: progress bar with return and cost, evaluation
``hyperparams``    rl-baselines3-zoo style hyperparameter files (YAML / JSON)
``train``          ``dronewpt train``: PPO / SAC / TD3 / DQN on the batched env, imitation, outputs and metadata
``stats``          bootstrap and Student's t intervals, paired differences
``compare``        ``dronewpt compare``: every policy on the same seeded windows, with statistics
``batched``        compare's policies side by side in one batched env; training seeds as one stacked network
``forked``         one piece of work (compare's MPC runs) in a forked child process beside the parent's
``threads``        one BLAS thread for the rollouts' batched small matrices (threadpoolctl)
``shipped``        the shipped models' table: each learned kind's default file and seed prefix (no heavy imports)
``pretrained/``    shipped models (``.zip`` + metadata ``.json``); ``hyperparams/`` their settings
=================  ==========================================================================
"""

from __future__ import annotations

from typing import Callable

from mission_sim.contract import Policy, PolicyContext

from .classical import ModelBasedPolicy, RampPolicy, StepPolicy
from .onoff import HysteresisPolicy
from .online import OnlineLmModelBasedPolicy
from .random_policy import RandomPolicy


def require_sb3() -> None:
    """Raise a one-line ``ValueError`` when stable-baselines3 (the ``rl`` extra) is not installed."""
    import importlib.util

    if importlib.util.find_spec("stable_baselines3") is None:
        raise ValueError("RL policies and training need stable-baselines3 (with torch): "
                         "pip install 'dronewpt[rl]'")


def _rl(ctx, **kwargs):
    require_sb3()
    from .rl import RLPolicy   # imports stable-baselines3 (torch): only when asked for
    return RLPolicy(ctx, **kwargs)


def _ppo_lagrangian(ctx, **kwargs):
    """The shipped Lagrangian PPO (a plain SB3 PPO file; constrained only in how it was trained)."""
    require_sb3()
    from .rl import PRETRAINED_LAGRANGIAN, RLPolicy
    pol = RLPolicy(ctx, **{"path": PRETRAINED_LAGRANGIAN, **kwargs})
    pol.name = "ppo_lagrangian"
    return pol


def _imitation(ctx, **kwargs):
    """The shipped imitation student (a PPO actor trained by ``train --imitate``, :mod:`policies.imitation`)."""
    require_sb3()
    from .rl import RLPolicy, load_meta
    from .shipped import default_model
    kwargs = {"path": default_model("imitation"), **kwargs}
    if load_meta(kwargs["path"]).get("residual"):   # a residual student corrects the budgeted model-based duty
        from .residual import ResidualPolicy
        pol = ResidualPolicy(ctx, **kwargs)
    else:
        pol = RLPolicy(ctx, **kwargs)
    pol.name = "imitation"
    return pol


def _residual(ctx, **kwargs):
    require_sb3()
    from .residual import ResidualPolicy
    return ResidualPolicy(ctx, **kwargs)


def _slow_budget(ctx, **kwargs):
    """The MPC with a learned budget per control period (:mod:`policies.slow_budget`; ``slow_budget:PATH``)."""
    require_sb3()
    from .slow_budget import SlowBudgetPolicy
    return SlowBudgetPolicy(ctx, **kwargs)


def _oracle_imitation(ctx, **kwargs):
    """The learned oracle sequence after the stop (:mod:`policies.oracle_imitation`; ``oracle_imitation:PATH``)."""
    from .oracle_imitation import OracleImitationPolicy
    return OracleImitationPolicy(ctx, **kwargs)


def _oracle_imitation_filtered(ctx, **kwargs):
    """The learned oracle sequence with the MPC's model as a safety filter after the stop
    (:mod:`policies.oracle_imitation_filter`; ``oracle_imitation_filtered:PATH``)."""
    from .oracle_imitation_filter import OracleImitationFilteredPolicy
    return OracleImitationFilteredPolicy(ctx, **kwargs)


def _mpc(ctx, **kwargs):
    from .mpc import MPCPolicy
    return MPCPolicy(ctx, **kwargs)


def _budgeted(ctx, **kwargs):
    from .budgeted import BudgetedModelBasedPolicy
    return BudgetedModelBasedPolicy(ctx, **kwargs)


__all__ = ["make", "available", "register", "require_sb3", "Policy", "PolicyContext"]

_REGISTRY: dict[str, Callable[..., Policy]] = {
    "step": StepPolicy,
    "ramp": RampPolicy,
    "model_based": ModelBasedPolicy,
    "model_based_online": OnlineLmModelBasedPolicy,
    "hysteresis": HysteresisPolicy,
    "random": RandomPolicy,
    "rl": _rl,
    "ppo_lagrangian": _ppo_lagrangian,
    "residual": _residual,
    "model_based_budget": _budgeted,
    "mpc": _mpc,
    "imitation": _imitation,
    "slow_budget": _slow_budget,
    "oracle_imitation": _oracle_imitation,
    "oracle_imitation_filtered": _oracle_imitation_filtered,
}
#: names that take a model file as ``name:PATH``
_WITH_PATH = ("rl", "ppo_lagrangian", "residual", "imitation", "slow_budget", "oracle_imitation",
              "oracle_imitation_filtered")


def register(name: str, factory: Callable[..., Policy]) -> None:
    """Add a policy factory ``factory(ctx, **kwargs) -> Policy`` under ``name``."""
    _REGISTRY[name] = factory


def available() -> list[str]:
    return sorted(_REGISTRY)


def make(name: str, ctx: PolicyContext | None = None, **kwargs) -> Policy:
    """A fresh policy by name; ``ValueError`` naming the valid names.

    ``name``: one of :func:`available` (``step``, ``ramp``, ``model_based`` (the paper's controller), ``mpc``, ``rl``
    (the shipped model), ...), ``NAME:PATH`` for a model file (``rl:PATH``, ``residual:PATH``: a model
    ``dronewpt train`` wrote, its metadata ``.json`` beside it) or ``model_based_budget:B`` / ``mpc:B`` (an overshoot
    budget B in [0, 1]). ``ctx``: what the policy is made for (the link it assumes, the control period [s], the
    rated I2 [A], the plant's link model): ``mission_sim.config.policy_context(cfg)`` for a mission, an env's
    ``env.policy_context`` for that env, None for :class:`~mission_sim.contract.PolicyContext`'s defaults (Table I's
    link, a 100 us control period, 15 A). The policy acts on the observation contract of :mod:`mission_sim.contract`
    (``reset()``, then ``act(obs)``: the short duty d_short in [0, 1]).

    ``"mpc:B"``: B (a fraction) is the measured (instantaneous-peak) overshoot allowed, or the window's floor if
    that is higher. ``"model_based_budget:B"``: on the exact-mode link (``ctx.link_model == "modal"``, the envs'
    default) B is the measured overshoot allowed above F, the overshoot the controller predicts at the stop for its
    B = 0 plan (the paper's controller; the policy's ``predicted_floor``; within 0.2 point of ``model_based``'s
    measured overshoot on nominal windows, and above the window's oracle floor). Measured on nominal windows
    1000-1019: 0.23 B to B + 0.31 points above F (B in points, 100 B; B = 0.02: 0.46-1.85 points), at most B + 0.6
    points (``tests/test_budget_modal.py``). On eq. 4's link B is the relaxation of the reference after the stop,
    the measured overshoot about 100 B + 3.3 % (:class:`policies.budgeted.BudgetedModelBasedPolicy`)."""
    if not isinstance(name, str):   # (None, a policy object: an AttributeError on .partition)
        raise ValueError(f"policy={name!r:.80} is invalid; valid: a name, one of {', '.join(available())} (or rl:PATH)")
    if ctx is not None and not isinstance(ctx, PolicyContext):
        raise ValueError(f"ctx={ctx!r:.80} is invalid; valid: a PolicyContext (mission_sim.config.policy_context(cfg)) "
                         "or None (Table I's)")
    base, colon, arg = name.partition(":")
    if colon and not arg.strip() and (base in _WITH_PATH or base in ("model_based_budget", "mpc")):
        # `--policy rl:$MODEL` with MODEL unset ran the shipped model
        raise ValueError(f"policy={name!r} is invalid: nothing after ':'; valid: {base} alone, or "
                         f"{base}:{'B (a number)' if base in ('model_based_budget', 'mpc') else 'PATH'}")
    if arg and base in ("model_based_budget", "mpc"):   # model_based_budget:0.02 = overshoot budget 2 %
        try:
            budget = float(arg)
        except ValueError:
            raise ValueError(f"policy={name!r} is invalid; valid: {base}:B with B a number, the overshoot budget "
                             "(e.g. 0.02)") from None
        try:
            return _REGISTRY[base](ctx or PolicyContext(), **{**kwargs, "budget": budget})
        except ValueError as exc:
            raise ValueError(f"policy={name!r} is invalid: {exc}") from None
    if base not in _REGISTRY or (colon and base not in _WITH_PATH):
        raise ValueError(f"policy={name!r} is invalid; valid values: {', '.join(available())} "
                         f"(or {':PATH, '.join(_WITH_PATH)}:PATH)")
    if arg:   # (an oracle imitation .npz was named "RL model file"; a FIFO is refused without opening it)
        from mission_sim.validation import check_regular_file
        if base.startswith("oracle_imitation"):
            check_regular_file(arg, "oracle imitation model file", "a model .npz (as "
                               "benchmarks/train_oracle_imitation.py writes)")
        else:
            check_regular_file(arg, "RL model file", "a model file (as `dronewpt train` writes)")
        kwargs = {**kwargs, "path": arg}
    return _REGISTRY[base](ctx or PolicyContext(), **kwargs)
