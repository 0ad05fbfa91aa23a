"""A stable-baselines3 ``VecEnv`` over the batched numpy vector env (needs the ``rl`` extra).

:class:`SbarSB3VecEnv` steps all ``num_envs`` charging windows in one numpy call
(:class:`envs.vector.SbarChargingVectorEnv`) instead of SB3's ``DummyVecEnv`` loop over single
envs and wrappers. SB3 semantics:

* **autoreset in the same step**: when a window ends (truncation after ``n_steps``), the returned
  observation is the first one of the next window, and ``infos[i]["terminal_observation"]`` holds
  the last one; ``infos[i]["TimeLimit.truncated"]`` is True (PPO then bootstraps the value of the
  terminal observation, as with ``make_vec_env``);
* **seeding**: ``seed(s)`` seeds sub-env ``i`` with ``s + i`` at the next ``reset()`` (as
  ``DummyVecEnv``), later windows continue each sub-env's generator: sub-env ``i`` reproduces a
  single :class:`envs.charging.SbarChargingEnv` reset with seed ``s + i`` and then without seed;
* **slim info**: an empty dict per sub-env while its window runs; at the end of a window the
  episode summary: ``episode_cost`` (= the sum of the per-step ``cost``, :mod:`envs.objective`),
  ``overshoot``, ``reached_short_mode``, ``overcurrent_cost`` (sum of the per-step overcurrent
  term), ``energy_after_stop_j``, for ``VecMonitor(..., info_keywords=EPISODE_KEYS)``;
* the per-step cost of the last step is the array attribute ``step_cost`` (the constraint
  wrappers read it without going through ``infos``);
* **cost definition** ``cost=``: ``"overshoot"`` (default; the env's ``info["cost"]``, the rise of
  the running overshoot after the stop, summing to ``max(0, overshoot)`` per window,
  :mod:`envs.objective`) or ``"overcurrent"`` (``max(0, |I2|_pk / I2_rated - 1)`` per step);
  ``episode_cost`` is the window's sum of the chosen per-step cost;
* **fixed seeds** ``reset_seed=s``: every ``reset()`` re-seeds sub-env ``i`` with ``s + i`` (an
  evaluation set that is the same windows at every evaluation, for ``EvalCallback``).
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from mission_sim.validation import SEED_RANGE, check_number

from .core import EnvConfig
from .vector import SbarChargingDiscreteVectorEnv, SbarChargingVectorEnv

__all__ = ["SbarSB3VecEnv", "EPISODE_KEYS"]

EPISODE_KEYS = ("episode_cost", "overshoot", "reached_short_mode", "overcurrent_cost", "energy_after_stop_j")
COSTS = ("overshoot", "overcurrent")


class SbarSB3VecEnv(VecEnv):
    """``num_envs`` charging windows as one SB3 ``VecEnv`` (continuous, or ``discrete=True`` ON-OFF)."""

    def __init__(self, num_envs: int = 64, scenario="random", config: EnvConfig | dict | None = None,
                 discrete: bool = False, cost: str = "overshoot", reset_seed: int | None = None):
        if cost not in COSTS:
            raise ValueError(f"cost={cost!r} is invalid; valid values: {', '.join(COSTS)}")
        self.cost = cost
        self.reset_seed = None if reset_seed is None else \
            check_number("reset_seed", reset_seed, SEED_RANGE)   # (1.5 was seed 1, silently)
        cls = SbarChargingDiscreteVectorEnv if discrete else SbarChargingVectorEnv
        self.venv = cls(num_envs=num_envs, scenario=scenario, config=config)
        self.render_mode = None
        super().__init__(self.venv.num_envs, self.venv.single_observation_space, self.venv.single_action_space)
        n = self.num_envs
        self._actions = None
        self.step_cost = np.zeros(n)
        self._acc = np.zeros((3, n))   # overcurrent cost, energy after the stop, chosen cost, of the running windows

    @property
    def config(self) -> EnvConfig:
        return self.venv.config

    @property
    def policy_context(self):
        return self.venv.policy_context

    def reset(self):
        if self.reset_seed is not None:
            self.seed(self.reset_seed)
        # one per sub-env, None: its generator goes on (DummyVecEnv's env.reset(seed=None); was seed 0)
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        opts = self._options[0] or None
        obs, _ = self.venv.reset(seed=seeds, options=opts)
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._acc[:] = 0.0
        self.step_cost = np.zeros(self.num_envs)
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, reward, term, trunc, info = self.venv.step(self._actions)
        self.step_cost = info["cost"] if self.cost == "overshoot" else info["overcurrent"]
        after = info["charge_cmd_a"] == 0.0
        self._acc[0] += info["overcurrent"]
        self._acc[1] += np.where(after, info["energy_j"], 0.0)
        self._acc[2] += self.step_cost
        done = term | trunc
        infos = [{} for _ in range(self.num_envs)]
        if done.any():
            idx = np.flatnonzero(done)
            summary = {"episode_cost": self._acc[2], "overshoot": info["overshoot"],
                       "reached_short_mode": info["reached_short_mode"], "overcurrent_cost": self._acc[0],
                       "energy_after_stop_j": self._acc[1]}
            for i in idx.tolist():
                infos[i] = {"terminal_observation": obs[i].copy(), "TimeLimit.truncated": bool(trunc[i] and not term[i]),
                            **{k: v[i].item() for k, v in summary.items()}}
            obs[idx] = self.venv.restart(idx)
            self._acc[:, idx] = 0.0
        return obs, reward.astype(np.float32), done, infos

    def close(self) -> None:
        self.venv.close()

    def _indices(self, indices):
        if indices is None:
            return range(self.num_envs)
        return [indices] if isinstance(indices, int) else list(indices)

    def get_attr(self, attr_name: str, indices=None):
        if attr_name == "render_mode":
            return [None for _ in self._indices(indices)]
        owner = self if attr_name in ("step_cost", "policy_context", "config") else self.venv
        value = getattr(owner, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value, indices=None) -> None:
        """The batched env's attribute, shared by every window: ``indices`` must be None or all of them (a part of them
        switched every window, silently)."""
        if indices is not None and sorted(set(self._indices(indices))) != list(range(self.num_envs)):
            raise ValueError(f"set_attr({attr_name!r}, indices={indices!r}) is invalid; valid: indices=None or every "
                             f"window 0..{self.num_envs - 1} (the batched env's attributes are shared by its windows)")
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs):
        raise NotImplementedError(f"env_method({method_name!r}): the batched env has no per-sub-env objects")

    def env_is_wrapped(self, wrapper_class, indices=None):
        return [False for _ in self._indices(indices)]
