"""The shipped models (``policies/pretrained/``): each learned kind's default file (``--policy rl``, ``make("rl")``) and
the prefix of its training seeds' files, one table. Imports nothing heavy (no numpy, no stable-baselines3), so that
:func:`policies.compare.check_row_labels` can tell ``rl`` and ``rl:policies/pretrained/rl_s0.zip`` apart cheaply."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["PRETRAINED_DIR", "SHIPPED", "OTHER_PLAYERS", "default_model", "model_of"]

PRETRAINED_DIR = Path(__file__).parent / "pretrained"

#: learned kind -> (prefix of its seeds' files, extension): ``<prefix><k><ext>`` for seeds k = 0..4, seed 0 the
#: kind's default model (``oracle_imitation_filtered`` plays ``oracle_imitation``'s sequences)
SHIPPED = {"rl": ("rl_s", ".zip"), "ppo_lagrangian": ("ppo_lagrangian_s", ".zip"), "residual": ("residual_s", ".zip"),
           "imitation": ("imitation_s", ".zip"), "slow_budget": ("slow_budget_s", ".zip"),
           "oracle_imitation": ("oracle_imitation_s", ".npz"), "oracle_imitation_filtered": ("oracle_imitation_s", ".npz")}

#: kinds that play a file another way than every other kind loading it (``oracle_imitation_filtered``: the
#: oracle's sequences through a filter): another policy of the same file, its own row in ``compare``
OTHER_PLAYERS = frozenset({"oracle_imitation_filtered"})


def default_model(kind: str) -> Path:
    """The model file a bare ``kind`` loads (its seed 0 in :data:`PRETRAINED_DIR`)."""
    prefix, ext = SHIPPED[kind]
    return PRETRAINED_DIR / f"{prefix}0{ext}"


def model_of(spec) -> tuple[str, str] | None:
    """``(kind, real path)`` of the model file a policy name loads (``kind:PATH`` an existing file, a bare shipped
    ``kind`` its :func:`default_model`), or None (a classical policy, ``model_based_budget:0.02``, a missing file)."""
    kind, colon, arg = str(spec).partition(":")
    if not colon:
        return (kind, os.path.realpath(default_model(kind))) if kind in SHIPPED else None
    return (kind, os.path.realpath(arg)) if os.path.isfile(arg) else None
