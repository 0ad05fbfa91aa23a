"""Uniformly random duties: the floor every learned policy must beat."""

from __future__ import annotations

import numpy as np

from mission_sim.contract import PolicyContext

__all__ = ["RandomPolicy"]


class RandomPolicy:
    """``d_short ~ U(0, 1)`` every control period (``discrete=True``: RM or SM with probability 1/2)."""

    name = "random"

    def __init__(self, ctx: PolicyContext = PolicyContext(), seed: int | None = 0, discrete: bool = False):
        self.ctx = ctx
        self.seed = seed
        self.discrete = bool(discrete)
        self.reset(1)

    def reset(self, n: int = 1) -> None:
        self.n = int(n)
        self._rng = np.random.default_rng(self.seed)

    def act(self, obs):
        n = np.atleast_2d(obs).shape[0]
        return self._rng.integers(0, 2, n).astype(float) if self.discrete else self._rng.uniform(0.0, 1.0, n)
