"""Policies behind one protocol (:class:`mission_sim.contract.Policy`), made by name.

>>> from policies import make
>>> pol = make("model_based")
"""

from __future__ import annotations

from typing import Callable

from mission_sim.contract import Policy, PolicyContext

from .classical import ModelBasedPolicy, RampPolicy, StepPolicy
from .onoff import HysteresisPolicy
from .online import OnlineLmModelBasedPolicy
from .random_policy import RandomPolicy


def _rl(ctx, **kwargs):
    from .rl import RLPolicy   # imports stable-baselines3 (torch): only when asked for
    return RLPolicy(ctx, **kwargs)


__all__ = ["make", "available", "register", "Policy", "PolicyContext"]

_REGISTRY: dict[str, Callable[..., Policy]] = {
    "step": StepPolicy,
    "ramp": RampPolicy,
    "model_based": ModelBasedPolicy,
    "model_based_online": OnlineLmModelBasedPolicy,
    "hysteresis": HysteresisPolicy,
    "random": RandomPolicy,
    "rl": _rl,
}


def register(name: str, factory: Callable[..., Policy]) -> None:
    """Add a policy factory ``factory(ctx, **kwargs) -> Policy`` under ``name``."""
    _REGISTRY[name] = factory


def available() -> list[str]:
    return sorted(_REGISTRY)


def make(name: str, ctx: PolicyContext | None = None, **kwargs) -> Policy:
    """A fresh policy by name; raises ``ValueError`` naming the valid names."""
    if name not in _REGISTRY:
        raise ValueError(f"policy={name!r} is invalid; valid values: {', '.join(available())}")
    return _REGISTRY[name](ctx or PolicyContext(), **kwargs)
