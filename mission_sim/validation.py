"""Validation of parameter dataclasses: one message format for every section of a mission."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

__all__ = ["check_positive", "read_toml_file"]


def check_positive(obj, *names: str, allow_zero: bool = False) -> None:
    """Raise ``ValueError`` naming the field, its value and the valid range unless every field
    ``names`` of ``obj`` is finite and > 0 (>= 0 with ``allow_zero``)."""
    for name in names:
        v = float(getattr(obj, name))
        if not (math.isfinite(v) and (v >= 0 if allow_zero else v > 0)):
            raise ValueError(f"{name}={v!r} is invalid; valid range: {'[0' if allow_zero else '(0'}, inf)")


def read_toml_file(path, what: str = "config file") -> dict:
    """Parse the TOML file ``path``; every failure is a one-line error naming ``what`` and the path:
    ``FileNotFoundError`` when missing, ``ValueError`` for a folder, a non-text (binary) file or bad
    TOML (with the parser's line and column), ``OSError`` when it cannot be read."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{what} {str(path)!r} is a folder; valid: a TOML file")
    if not path.exists():
        raise FileNotFoundError(f"{what} {str(path)!r} does not exist")
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{what} {str(path)!r} is not a UTF-8 text (TOML) file: byte {exc.object[exc.start]:#04x} "
                         f"at offset {exc.start}") from None
    except OSError as exc:
        raise OSError(f"{what} {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{what} {str(path)!r} is not valid TOML: {exc}") from None
