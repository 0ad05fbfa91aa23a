"""Validation of parameter dataclasses: one message format for every section of a mission."""

from __future__ import annotations

import math

__all__ = ["check_positive"]


def check_positive(obj, *names: str, allow_zero: bool = False) -> None:
    """Raise ``ValueError`` naming the field, its value and the valid range unless every field
    ``names`` of ``obj`` is finite and > 0 (>= 0 with ``allow_zero``)."""
    for name in names:
        v = float(getattr(obj, name))
        if not (math.isfinite(v) and (v >= 0 if allow_zero else v > 0)):
            raise ValueError(f"{name}={v!r} is invalid; valid range: {'[0' if allow_zero else '(0'}, inf)")
