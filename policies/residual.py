"""The residual policy behind the ``Policy`` protocol: the paper's model-based duty plus a bounded
learned correction, ``d = clip(d_base + scale a, 0, 1)`` with ``a in [-1, 1]`` from an SB3 model
trained by ``dronewpt train --residual`` (:class:`policies.constrained.ResidualVecEnv`). The model
sees the contract observation plus the base duty (as an action in [-1, 1]); with ``a = 0`` this is
exactly :class:`policies.classical.ModelBasedPolicy` (or its budgeted variant when the model was
trained with ``--residual-base-budget``).
"""

from __future__ import annotations

import numpy as np

from mission_sim.contract import PolicyContext, duty_to_action

from .budgeted import BudgetedModelBasedPolicy
from .rl import RLPolicy
from .shipped import default_model

__all__ = ["ResidualPolicy", "PRETRAINED_RESIDUAL"]

PRETRAINED_RESIDUAL = default_model("residual")   # seeds _s0.._s4 shipped


def residual_obs(obs: np.ndarray, d_base: np.ndarray) -> np.ndarray:
    """Contract observation + the base duty as an action in [-1, 1] (field 8), float32."""
    return np.concatenate([obs, duty_to_action(d_base)[:, None]], axis=1).astype(np.float32)


def residual_duty(d_base, action, scale: float) -> np.ndarray:
    """``clip(d_base + scale a, 0, 1)``: the duty a residual agent's action ``a`` gives."""
    return np.clip(np.asarray(d_base, dtype=float) + scale * np.asarray(action, dtype=float).reshape(-1), 0.0, 1.0)


class ResidualPolicy:
    """Model-based duty + ``scale`` x the SB3 model's action (``path``: a ``train --residual`` output)."""

    name = "residual"

    def __init__(self, ctx: PolicyContext = PolicyContext(), path=None, fast: bool = True):
        self.ctx = ctx
        self.rl = RLPolicy(ctx, PRETRAINED_RESIDUAL if path is None else path, fast=fast, residual=True)
        res = self.rl.meta.get("residual")
        if not res:
            raise ValueError(f"{self.rl.path.name} is not a residual model (train it with `dronewpt train --residual`)")
        self.scale = float(res["scale"])
        self.base_budget = float(res.get("base_budget", 0.0))
        self.base = BudgetedModelBasedPolicy(ctx, budget=self.base_budget)
        self.n = 1

    def reset(self, n: int = 1) -> None:
        self.n = int(n)
        self.base.reset(n)
        self.rl.reset(n)

    def act(self, obs):
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float32))
        d_base = np.asarray(self.base.act(obs), dtype=float).reshape(len(obs))
        a = 2.0 * self.rl.act(residual_obs(obs, d_base)) - 1.0   # RLPolicy maps a -> (a + 1) / 2 (clipped)
        return residual_duty(d_base, a, self.scale)
