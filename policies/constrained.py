"""Constrained RL on stable-baselines3: a Lagrangian cost penalty and a residual action space.

**Lagrangian PPO** (Ray, Achiam & Amodei 2019, "Benchmarking safe exploration"; the dual ascent of
Altman's constrained MDPs): maximise the return ``J_r`` subject to the mean episode cost
``J_c <= d`` (budget ``d``) by training on the Lagrangian ``r_k - lambda c_k`` with the multiplier
updated from the rollouts, ``lambda <- clip(lambda + eta clip((J_c - d) / d, -1, 2), 0, lambda_max)``
after every rollout (``J_c`` = mean cost of the episodes that ended in it). The per-step cost
``c_k`` is the environment's (:mod:`envs.objective`: the rise of the running overshoot, so it sums
to the episode overshoot). The penalty is a ``VecEnvWrapper`` (:class:`CostPenaltyVecEnv`) between
the Monitor (which logs the unpenalised return and the episode cost) and ``VecNormalize``; the
update is a callback (:class:`LagrangeCallback`). PPO itself is SB3's, untouched.

**Residual policy** (Johannink et al. 2019, "Residual reinforcement learning for robot control"):
the agent's action ``a in [-1, 1]`` corrects the paper's model-based controller (optionally its
budgeted variant, :mod:`policies.budgeted`, ``base_budget``),
``d_short = clip(d_base + scale a, 0, 1)`` (:class:`ResidualVecEnv`); the agent also sees the base
duty (observation field 8, as an action in [-1, 1]). With ``a = 0`` it *is* the model-based
controller, so training starts from the paper's zero-overshoot point and learns where stopping
faster is worth some overshoot. :class:`ResidualPolicy` runs a trained one behind the ``Policy``
protocol.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnvWrapper
from gymnasium import spaces

from mission_sim.contract import OBS_DIM, PolicyContext, duty_to_action

from .budgeted import BudgetedModelBasedPolicy
from .residual import residual_duty, residual_obs  # noqa: F401  (defined with the inference side: no SB3 import)

__all__ = ["CostPenaltyVecEnv", "LagrangeCallback", "ResidualVecEnv", "residual_obs", "residual_duty", "RESIDUAL_SCALE",
           "ramp_budget", "BUDGET_EPISODES", "BUDGET_SEED"]

BUDGET_EPISODES, BUDGET_SEED = 256, 700_000   # windows and seeds the default budget is measured on

RESIDUAL_SCALE = 0.25   # largest duty correction the residual agent may add [-]


class CostPenaltyVecEnv(VecEnvWrapper):
    """Reward ``r - lambda * cost`` with ``cost`` the wrapped adapter's ``step_cost`` (per step)."""

    def __init__(self, venv, lam: float = 0.0):
        super().__init__(venv)
        self.lam = float(lam)
        self.episode_costs: list[float] = []

    def reset(self):
        return self.venv.reset()

    def step_wait(self):
        obs, reward, done, infos = self.venv.step_wait()
        reward = reward - np.float32(self.lam) * np.asarray(self.venv.get_attr("step_cost")[0], dtype=np.float32)
        if done.any():
            self.episode_costs.extend(infos[i]["episode_cost"] for i in np.flatnonzero(done))
        return obs, reward, done, infos

    def pop_episode_costs(self) -> list[float]:
        out, self.episode_costs = self.episode_costs, []
        return out


class LagrangeCallback(BaseCallback):
    """Dual ascent on the multiplier after every rollout; history in ``history`` and ``path`` (JSON).

    ``J_c`` is the mean episode cost of the windows that ended in the rollout (``probe=None``), or
    of a batch of windows run with the *deterministic* policy on ``probe`` (a VecEnv with the
    training stack below VecNormalize; fresh windows every time). The probe is the default of
    ``train``: at 10 kHz the Gaussian exploration dithers the duty next to the link's 4 kHz resonance
    and the stochastic rollouts overshoot by 10-30 % whatever the mean action, so a budget of a few
    % on them is infeasible and the multiplier only grows; the constraint is meant for the policy
    that is deployed (its mean action)."""

    def __init__(self, penalty: CostPenaltyVecEnv, budget: float, lr: float = 50.0, lam_max: float = 5000.0,
                 path=None, probe=None):
        super().__init__()
        if not (np.isfinite(budget) and budget > 0):
            raise ValueError(f"budget={budget!r} is invalid; valid range: (0, inf) (an overshoot fraction)")
        self.penalty, self.budget, self.lr, self.lam_max = penalty, float(budget), float(lr), float(lam_max)
        self.path = None if path is None else Path(path)
        self.probe = probe
        self.history: list[tuple[int, float, float]] = []

    def _on_step(self) -> bool:
        return True

    def _probe_costs(self) -> list[float]:
        """Episode costs of one batch of deterministic windows on the probe env."""
        norm = self.model.get_vec_normalize_env()
        obs = self.probe.reset()
        while True:
            o = norm.normalize_obs(obs) if norm is not None else obs
            obs, _, done, infos = self.probe.step(self.model.predict(o, deterministic=True)[0])
            if done.all():
                return [inf["episode_cost"] for inf in infos]

    def _on_rollout_end(self) -> None:
        costs = self.penalty.pop_episode_costs()
        if self.probe is not None:
            costs = self._probe_costs()
        if not costs:
            return
        jc = float(np.mean(costs))
        g = float(np.clip((jc - self.budget) / self.budget, -1.0, 2.0))
        self.penalty.lam = float(np.clip(self.penalty.lam + self.lr * g, 0.0, self.lam_max))
        self.history.append((int(self.num_timesteps), jc, self.penalty.lam))
        self.logger.record("lagrange/lambda", self.penalty.lam)
        self.logger.record("lagrange/episode_cost", jc)
        if self.path is not None:
            self.path.write_text(json.dumps({"budget": self.budget, "lr": self.lr, "lambda": self.penalty.lam,
                                             "probe": self.probe is not None, "history": self.history}))


class _BaseDuty:
    """The model-based controller for a batch, with per-row restarts (new windows)."""

    def __init__(self, ctx: PolicyContext, n: int, budget: float = 0.0):
        self.pol = BudgetedModelBasedPolicy(ctx, budget=budget)   # budget 0: the paper's controller
        self.pol.reset(n)
        self.fresh = None

    def act(self, obs):
        return self.pol.act(obs, restart=self.fresh)


class ResidualVecEnv(VecEnvWrapper):
    """Action ``a`` -> duty ``clip(d_base + scale a, 0, 1)`` on the wrapped adapter; obs + base duty."""

    def __init__(self, venv, scale: float = RESIDUAL_SCALE, base_budget: float = 0.0):
        if not (np.isfinite(scale) and 0 < scale <= 1):
            raise ValueError(f"residual scale={scale!r} is invalid; valid range: (0, 1]")
        obs_space = spaces.Box(-1.0, 1.0, (OBS_DIM + 1,), np.float32)
        super().__init__(venv, observation_space=obs_space, action_space=spaces.Box(-1.0, 1.0, (1,), np.float32))
        self.scale = float(scale)
        self.base_budget = float(base_budget)
        self.base = _BaseDuty(venv.get_attr("policy_context")[0], venv.num_envs, self.base_budget)
        self._d_base = None

    def _augment(self, obs, restart):
        self.base.fresh = restart
        self._d_base = self.base.act(obs)
        return residual_obs(obs, self._d_base)

    def reset(self):
        obs = self.venv.reset()
        self.base.pol.reset(self.num_envs)
        return self._augment(obs, None)

    def step_async(self, actions):
        d = residual_duty(self._d_base, actions, self.scale)
        self.venv.step_async(duty_to_action(d)[:, None].astype(np.float32))

    def step_wait(self):
        obs, reward, done, infos = self.venv.step_wait()
        idx = np.flatnonzero(done)
        for i in idx:   # terminal observation: base duty of the last step (the controller is not stepped again)
            infos[i]["terminal_observation"] = residual_obs(infos[i]["terminal_observation"][None],
                                                            self._d_base[i:i + 1])[0]
        return self._augment(obs, idx if len(idx) else None), reward, done, infos



def ramp_budget(scenario="random", config=None, cost: str = "overshoot") -> float:
    """Default cost budget: the ramp policy's mean episode cost on ``scenario`` (BUDGET_EPISODES
    windows, seeds BUDGET_SEED + i): "no more overshoot than the ramp" (the paper's ramp slope)."""
    from envs.sb3_vec import SbarSB3VecEnv

    from .classical import RampPolicy

    venv = SbarSB3VecEnv(BUDGET_EPISODES, scenario, config, cost=cost, reset_seed=BUDGET_SEED)
    pol = RampPolicy(venv.policy_context)
    pol.reset(BUDGET_EPISODES)
    obs, costs = venv.reset(), np.zeros(BUDGET_EPISODES)
    for _ in range(venv.config.n_steps):
        obs, _, done, infos = venv.step(duty_to_action(pol.act(obs))[:, None].astype(np.float32))
    costs = np.array([inf["episode_cost"] for inf in infos])
    if not done.all():
        raise RuntimeError("ramp_budget: windows did not end together")
    return float(costs.mean())
