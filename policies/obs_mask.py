"""Observation fields hidden from a network for good: exactly 0 at its input, whatever the statistics do.

The imitation stage (:mod:`policies.imitation`) hides fields from the student (``--imitation-mask``, e.g. the
currents for a feed-forward student) by giving them a huge variance in the input normalisation. PPO's
``VecNormalize`` keeps updating its running statistics during fine-tuning, so that variance decays
(~1e8 / steps) and the fields leak back in (~140x attenuated after 500k steps). Here the mask is part
of the normalisation instead:

* :class:`MaskedVecNormalize` (training and evaluation envs): ``VecNormalize`` whose normalised
  observation has the masked columns set to exactly 0, and whose running statistics of those
  columns stay frozen at their starting values;
* the metadata's ``obs_norm["masked"]`` lists the masked column indices (of the stacked observation);
  :class:`policies.rl.RLPolicy` (and so the stacked seed rows of :mod:`policies.batched`) multiplies
  them by a scale of exactly 0. Models without the key (every model trained before) load as before.
"""
from __future__ import annotations

import numpy as np
from stable_baselines3.common.vec_env import VecNormalize

from mission_sim.contract import OBS_INDEX


def masked_indices(fields, history: int, obs_dim: int) -> list:
    """Column indices of ``fields`` in every one of ``history`` stacked frames of width ``obs_dim / history``."""
    width = int(obs_dim) // int(history)
    return sorted(int(k * width + OBS_INDEX[f]) for f in fields for k in range(int(history)))


class MaskedVecNormalize(VecNormalize):
    """``VecNormalize`` with the columns ``masked`` set to exactly 0 after normalisation and their running
    mean / variance frozen (kept at the values they had when the mask was set)."""

    def __init__(self, venv, masked=(), **kwargs):
        super().__init__(venv, **kwargs)
        self.set_mask(masked)

    def set_mask(self, masked) -> None:
        self.masked = np.asarray(sorted(int(i) for i in masked), dtype=np.int64)
        self._frozen = (self.obs_rms.mean[self.masked].copy(), self.obs_rms.var[self.masked].copy())

    def _freeze(self) -> None:
        if self.masked.size:
            self.obs_rms.mean[self.masked], self.obs_rms.var[self.masked] = self._frozen

    def normalize_obs(self, obs):
        out = super().normalize_obs(obs)
        if self.masked.size:
            out[..., self.masked] = 0.0
        return out

    def step_wait(self):
        res = super().step_wait()
        self._freeze()
        return res

    def reset(self):
        obs = super().reset()
        self._freeze()
        return obs


def obs_norm_meta(vn) -> dict:
    """The metadata's ``obs_norm`` of ``vn``: mean, var, clip, epsilon, and ``masked`` (column indices held at
    exactly 0 after normalisation) for a :class:`MaskedVecNormalize` with a mask."""
    meta = {"mean": vn.obs_rms.mean.tolist(), "var": vn.obs_rms.var.tolist(),
            "clip": float(vn.clip_obs), "epsilon": float(vn.epsilon)}
    masked = getattr(vn, "masked", None)
    if masked is not None and len(masked):
        meta["masked"] = [int(i) for i in masked]
    return meta
