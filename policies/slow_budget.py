"""A learned policy that acts in a slow variable: the MPC's overshoot budget, chosen per control period.

Issue 21 asks for "actions in slow variables (a residual on the model-based controller's budget or
reference instead of the raw duty)". Here the agent does not touch the duty at all: its action
``a in [-1, 1]`` is the measured-overshoot budget of the model-predictive controller
(:mod:`policies.mpc`) for this receiver and this control period,

    b = lo + (a + 1) / 2 (hi - lo)        (:func:`budget_of_action`, default ``[lo, hi] = [0, 0.15]``)

and the duty is the MPC's (receding-horizon QP on the nominal model, V2 piecewise linear, the
after-stop bound ``I2 + ripple <= (1 + b) I2_sm``). So whatever the agent does, the duty stays the
output of a smooth plan: the agent's Gaussian exploration moves a constraint level, it cannot dither
the duty next to the link's 4 kHz resonance (what made every learned duty policy ring, docs/rl.md).
Before the stop the budget has no effect (the MPC tracks the command); after it, the agent can
spend overshoot where it buys return and save it where it does not (a per-window, per-step
allocation that a constant budget cannot make), from what it observes (the contract observation).

Parts:

* :class:`BudgetScheduledMPC`: :class:`policies.mpc.MPCPolicy` with one budget per receiver, set
  before each ``act`` (:meth:`~BudgetScheduledMPC.set_budgets`). The MPC reads its budget only
  through ``_budget_of(receivers)`` in its batched after-stop step; the override gives each
  receiver its own. With every
  budget equal to ``b`` it *is* ``mpc:b`` (bit for bit, ``tests/test_slow_budget.py``).
* :class:`SlowBudgetVecEnv`: the SB3 ``VecEnvWrapper`` of ``dronewpt train --slow-budget LO:HI``
  (on the batched adapter; observation unchanged, action the budget).
* :class:`SlowBudgetPolicy`: a trained one behind the ``Policy`` protocol (``slow_budget:PATH``;
  the shipped seeds ``policies/pretrained/slow_budget_s<k>``).
"""

from __future__ import annotations

import numpy as np

from mission_sim.contract import OBS_INDEX, PolicyContext, denormalise_obs_field, duty_to_action

from .mpc import MPCPolicy
from .shipped import default_model

__all__ = ["BudgetScheduledMPC", "BudgetLatch", "SlowBudgetVecEnv", "SlowBudgetPolicy", "budget_of_action",
           "parse_budget_range", "BUDGET_RANGE", "PRETRAINED_SLOW_BUDGET", "EVERY"]

#: how often the agent's budget is taken: every control period, or once per window at the stop and held
EVERY = ("window", "step")

#: default range of the learned budget [measured overshoot fraction]
BUDGET_RANGE = (0.0, 0.15)
PRETRAINED_SLOW_BUDGET = default_model("slow_budget")   # seeds _s0.._s4 shipped


def parse_budget_range(text) -> tuple[float, float]:
    """``"LO:HI"`` (or a pair) -> (lo, hi) with ``0 <= lo < hi <= 1``; ValueError naming the valid form."""
    try:
        lo, hi = (float(x) for x in (text.split(":") if isinstance(text, str) else text))
    except (ValueError, TypeError):
        raise ValueError(f"slow budget range {text!r} is invalid; valid form: LO:HI, 0 <= LO < HI <= 1 "
                         "(measured overshoot fractions, e.g. 0:0.15)") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 <= lo < hi <= 1.0):
        raise ValueError(f"slow budget range {text!r} is invalid; valid range: 0 <= LO < HI <= 1")
    return lo, hi


def budget_of_action(action, lo: float, hi: float) -> np.ndarray:
    """Agent action(s) in [-1, 1] (clipped) -> budget(s) ``lo + (a + 1) / 2 (hi - lo)``, shape (n,)."""
    a = np.clip(np.asarray(action, dtype=float).reshape(-1), -1.0, 1.0)
    return lo + 0.5 * (a + 1.0) * (hi - lo)


class BudgetScheduledMPC(MPCPolicy):
    """The MPC with a budget per receiver (fraction of measured overshoot), settable every control period. Its
    model is the MPC's: eq. 4's, or the exact modes when the context's ``link_model`` is ``"modal"`` (the shipped
    agents were trained with eq. 4's, docs/rl.md)."""

    def __init__(self, ctx: PolicyContext = PolicyContext(), budget: float = 0.0, **kwargs):
        super().__init__(ctx, budget=budget, **kwargs)
        self.default_budget = float(budget)
        self.name = "mpc_scheduled"
        self._budgets = np.full(self.n, self.default_budget)

    def reset(self, n: int = 1) -> None:
        super().reset(n)
        self._budgets = np.full(self.n, getattr(self, "default_budget", self.budget))

    def set_budgets(self, budgets) -> None:
        """The budget of every receiver for the next ``act`` (n,) or a scalar [fraction, >= 0]."""
        b = np.asarray(budgets, dtype=float).reshape(-1)
        if not np.all(np.isfinite(b)) or np.any(b < 0.0) or np.any(b > 1.0):
            raise ValueError(f"budgets {b!r} are invalid; valid range: [0, 1] (measured overshoot fractions)")
        if len(b) == 1:
            b = np.full(len(self._budgets), b[0])
        elif len(b) != len(self._budgets):
            self.reset(len(b))   # a new batch size: as MPCPolicy.act does on its own
        self._budgets = np.array(b, dtype=float)

    def act(self, obs):
        n = len(np.atleast_2d(obs))
        if len(self._budgets) != n:
            self._budgets = np.full(n, self.default_budget)
        return super().act(obs)

    def _budget_of(self, e):
        # the MPC reads its budget only through this, in its after-stop step of receivers e
        return self._budgets[e]


class BudgetLatch:
    """The budget actually applied per receiver: with ``every="step"`` the agent's of this step; with
    ``"window"`` the agent's action at the first control period after the stop (command 0), held for the
    rest of the window (a contextual bandit per window: one exploration sample per window, so a
    stochastic rollout measures the overshoot of one budget, not the peak of a noisy bound). Before
    the stop the budget has no effect on the MPC; a receiver whose command turns positive again is in a
    new window and is released."""

    _CMD = OBS_INDEX["charge_cmd_a"]

    def __init__(self, lo: float, hi: float, every: str = "window"):
        if every not in EVERY:
            raise ValueError(f"every={every!r} is invalid; valid values: {', '.join(EVERY)}")
        self.lo, self.hi, self.every = float(lo), float(hi), every
        self.held = None

    def reset(self, n: int) -> None:
        self.held = np.full(int(n), np.nan)

    def __call__(self, obs, action) -> np.ndarray:
        """Budgets (n,) for the receivers of ``obs`` given the agent's actions (n,) in [-1, 1]."""
        b = budget_of_action(action, self.lo, self.hi)
        if self.every == "step":
            return b
        o = np.atleast_2d(obs)
        if self.held is None or len(self.held) != len(o):
            self.reset(len(o))
        stopped = np.array([denormalise_obs_field(row, self._CMD) <= 0.0 for row in o])
        self.held[~stopped] = np.nan
        take = stopped & np.isnan(self.held)
        self.held[take] = b[take]
        return np.where(stopped, self.held, self.lo)


def _wrapper_base():
    from stable_baselines3.common.vec_env import VecEnvWrapper
    return VecEnvWrapper


class SlowBudgetVecEnv(_wrapper_base()):
    """SB3 wrapper: the agent's action is the MPC's budget (:func:`budget_of_action`), the duty the MPC's.

    Directly on the batched adapter (contract observations in, duty actions out); the observation is
    passed through unchanged. The MPC sees the same observation the agent does, restarts a receiver
    whose command turns positive after its stop (autoreset: a new window) and is reset with the env.
    """

    def __init__(self, venv, lo: float = BUDGET_RANGE[0], hi: float = BUDGET_RANGE[1], every: str = "window"):
        from gymnasium import spaces
        self.lo, self.hi = parse_budget_range((lo, hi))
        self.latch = BudgetLatch(self.lo, self.hi, every)
        super().__init__(venv, action_space=spaces.Box(-1.0, 1.0, (1,), np.float32))
        ctx = venv.get_attr("policy_context")[0]
        self.base = BudgetScheduledMPC(ctx, budget=self.lo)
        self.base.reset(self.num_envs)
        self.latch.reset(self.num_envs)
        self._obs = None
        self.last_budgets = np.full(self.num_envs, self.lo)

    def reset(self):
        self._obs = self.venv.reset()
        self.base.reset(self.num_envs)
        self.latch.reset(self.num_envs)
        return self._obs

    def step_async(self, actions):
        self.last_budgets = self.latch(self._obs, actions)
        self.base.set_budgets(self.last_budgets)
        d = np.asarray(self.base.act(self._obs), dtype=float).reshape(self.num_envs)
        self.venv.step_async(duty_to_action(d)[:, None].astype(np.float32))

    def step_wait(self):
        obs, reward, done, infos = self.venv.step_wait()
        self._obs = obs
        return obs, reward, done, infos


class SlowBudgetPolicy:
    """The MPC with the budget a trained agent chooses (``path``: a ``dronewpt train --slow-budget`` output;
    default the shipped seed 0), latched as the model was trained: at the stop and held for the window
    (``--slow-budget-every window``, the shipped seeds) or every control period (``step``)."""

    name = "slow_budget"
    uses_link_model = True   # the MPC's model of the context's link_model

    def __init__(self, ctx: PolicyContext = PolicyContext(), path=None, fast: bool = True):
        from .rl import RLPolicy
        self.ctx = ctx
        self.rl = RLPolicy(ctx, PRETRAINED_SLOW_BUDGET if path is None else path, fast=fast, residual=True)
        sb = self.rl.meta.get("slow_budget")
        if not sb:
            raise ValueError(f"{self.rl.path.name} is not a slow-budget model (train it with "
                             "`dronewpt train --slow-budget LO:HI`)")
        self.lo, self.hi = parse_budget_range((sb["lo"], sb["hi"]))
        self.latch = BudgetLatch(self.lo, self.hi, sb.get("every", "step"))
        self.base = BudgetScheduledMPC(ctx, budget=self.lo)
        self.last_budgets = None
        self.n = 1

    def reset(self, n: int = 1) -> None:
        self.n = int(n)
        self.base.reset(n)
        self.rl.reset(n)
        self.latch.reset(n)

    def budgets(self, obs) -> np.ndarray:
        """The budget the agent chooses for each receiver of ``obs`` now [fraction] (before the latch)."""
        u = np.asarray(self.rl.act(obs), dtype=float).reshape(-1)   # RLPolicy: (a + 1) / 2, clipped to [0, 1]
        return self.lo + u * (self.hi - self.lo)

    def act(self, obs):
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float32))
        b = self.budgets(obs)
        self.last_budgets = self.latch(obs, 2.0 * (b - self.lo) / (self.hi - self.lo) - 1.0)
        self.base.set_budgets(self.last_budgets)
        return self.base.act(obs)
