"""Smooth actions for off-policy RL (SAC, TD3) and PPO: a low-pass filter on the duty and / or a
penalty on its change per control period (issue 21).

Gaussian exploration on the duty every 100 us dithers the link next to its 4 kHz resonance
(docs/rl.md). Two standard remedies, as ``dronewpt train`` options, in one ``VecEnvWrapper``
(:class:`SmoothActionVecEnv`, directly on the batched adapter, below the Monitor):

* ``action_filter = alpha`` in [0, 1): the applied duty is the first-order low-pass
  ``d_k = alpha d_{k-1} + (1 - alpha) (a_k + 1) / 2`` (:func:`filtered_duty`). ``d_{k-1}`` is the
  observation's ``last_d_short``, so the filter needs no state of its own and the trained policy
  applies the same filter at inference (:class:`policies.rl.RLPolicy` reads ``action_filter`` from
  the metadata). The pole at ``alpha`` per 100 us (``alpha = 0.5``: a 1.1 kHz corner) keeps the
  exploration below the resonance;
* ``smooth_penalty = w``: reward ``r_k - w (d_k - d_{k-1})^2`` (the duty change squared, per step;
  the Monitor's return includes it).
"""

from __future__ import annotations

import numpy as np

from mission_sim.contract import OBS_INDEX, action_to_duty, duty_to_action

__all__ = ["filtered_duty", "SmoothActionVecEnv"]

_LAST_D = OBS_INDEX["last_d_short"]


def _last_duty(obs) -> np.ndarray:
    o = np.atleast_2d(np.asarray(obs, dtype=float))
    return np.clip((o[:, _LAST_D] + 1.0) * 0.5, 0.0, 1.0)   # denormalise_obs of the field (range 0..1)


def filtered_duty(obs, d_new, alpha: float) -> np.ndarray:
    """``alpha last_d + (1 - alpha) d_new`` with ``last_d`` the observation's previous duty (field 6)."""
    return alpha * _last_duty(obs) + (1.0 - alpha) * np.asarray(d_new, dtype=float).reshape(-1)


def _wrapper_base():
    from stable_baselines3.common.vec_env import VecEnvWrapper
    return VecEnvWrapper


class SmoothActionVecEnv(_wrapper_base()):
    """Low-pass filtered duty and / or a duty-change penalty on an SB3 ``VecEnv`` of contract observations."""

    def __init__(self, venv, alpha: float = 0.0, penalty: float = 0.0):
        if not (np.isfinite(alpha) and 0.0 <= alpha < 1.0):
            raise ValueError(f"action_filter={alpha!r} is invalid; valid range: [0, 1)")
        if not (np.isfinite(penalty) and penalty >= 0.0):
            raise ValueError(f"smooth_penalty={penalty!r} is invalid; valid range: [0, inf)")
        super().__init__(venv)
        self.alpha, self.penalty = float(alpha), float(penalty)
        self._obs = None
        self._dd = None

    def reset(self):
        self._obs = self.venv.reset()
        return self._obs

    def step_async(self, actions):
        d_new = action_to_duty(np.asarray(actions, dtype=float).reshape(-1))
        d = filtered_duty(self._obs, d_new, self.alpha) if self.alpha else d_new
        self._dd = d - _last_duty(self._obs)
        self.venv.step_async(duty_to_action(d)[:, None].astype(np.float32))

    def step_wait(self):
        obs, reward, done, infos = self.venv.step_wait()
        self._obs = obs
        if self.penalty:
            reward = (reward - self.penalty * self._dd ** 2).astype(np.float32)
        return obs, reward, done, infos
