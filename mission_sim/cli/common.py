"""What every subcommand shares: the user-error type and argument converters that name the bad value and its range."""

from __future__ import annotations

import argparse

__all__ = ["CliError", "float_arg", "positive_float", "finite_float", "nonneg_int", "parse_set", "write_mission"]


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def float_arg(name, positive=False, lo=0.0, hi=float("inf")):
    """argparse type: a finite float (in ``[lo, hi]`` and > 0 if ``positive``), errors naming the value and range."""
    if positive:
        valid = f"[{lo:g}, {hi:g}]" if lo > 0 else (f"(0, {hi:g}]" if hi < float("inf") else "(0, inf)")
    else:
        valid = "finite"

    def conv(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}={text!r} is not a number") from None
        if v != v or abs(v) == float("inf") or (positive and not (0 < v <= hi and v >= lo)):
            raise argparse.ArgumentTypeError(f"{name}={text!r} is invalid; valid range: {valid}")
        return v
    return conv


def positive_float(name):
    return float_arg(name, positive=True)


def finite_float(name):
    return float_arg(name)


def parse_set(items):
    import tomllib
    out = {}
    for item in items or ():
        if "=" not in item:
            raise CliError(f"--set {item!r} is invalid; valid form: KEY=VALUE (e.g. battery.capacity_ah=2.0)")
        key, text = item.split("=", 1)
        try:
            value = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            value = text
        out[key.strip()] = value
    return out


def nonneg_int(name):
    def conv(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}={text!r} is not an integer") from None
        if v < 0:
            raise argparse.ArgumentTypeError(f"{name}={text!r} is invalid; valid range: integer >= 0")
        return v
    return conv


def write_mission(result, out_dir, plots: bool) -> list[str]:
    """Write a mission's data files and, unless ``plots`` is false, its figures; returns the paths."""
    files = [str(f) for f in result.write(out_dir)]
    if plots:
        from ..figures.mission import plot_mission
        files.extend(str(f) for f in plot_mission(result, out_dir))
    return files
