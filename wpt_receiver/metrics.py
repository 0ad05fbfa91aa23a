"""Metrics of an RM -> SM transition computed from envelope time series (plain arrays, SI)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["TransitionMetrics", "transition_metrics"]


@dataclass(frozen=True)
class TransitionMetrics:
    rm_current_a: float        # I2 amplitude just before the switch [A]
    final_current_a: float     # I2 amplitude at the end of the window (mean of the last 2 %) [A]
    max_current_a: float       # max I2 amplitude after the switch [A]
    overshoot_pct: float       # (max - final) / final * 100 [%]
    settling_time_s: float     # time after the switch until |I2 - final| stays within 2 % of final [s] (0: never
                               # outside the band, e.g. a link whose RM and SM currents differ by less than 2 %)
    peak_i1_a: float           # max primary amplitude after the switch [A]
    energy_to_battery_j: float  # integral of V2 I2 / 2 after the switch (fundamental power) [J]

    def as_dict(self) -> dict:
        return asdict(self)


def transition_metrics(t_s, i2_a, t_switch_s: float, i1_a=None, v2_v=None, band: float = 0.02,
                       i2_fund_a=None) -> TransitionMetrics:
    """Metrics of the I2 envelope ``i2_a(t_s)`` around a switch at ``t_switch_s``.

    ``v2_v`` (the rectifier fundamental, same grid) gives the battery energy
    ``E = int V2 I2 / 2 dt`` from the switch on (lossless rectifier: fundamental power = DC power).
    That product needs the *fundamental* amplitude of i2: when ``i2_a`` is something else (the
    instantaneous peak of the modal and switching plants, ~2-3 % above the fundamental in a
    partial short), pass the fundamental as ``i2_fund_a`` (same grid); ``i2_a`` is used otherwise.
    """
    t = np.asarray(t_s, dtype=float)
    i2 = np.asarray(i2_a, dtype=float)
    if t.shape != i2.shape or t.ndim != 1 or len(t) < 3:
        raise ValueError("t_s and i2_a must be 1-D arrays of the same length >= 3")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(i2))):
        k = int(np.argmin(np.isfinite(t) & np.isfinite(i2)))
        raise ValueError(f"i2_a[{k}]={float(i2[k])!r} at t_s={float(t[k])!r} is not finite; valid: finite samples")
    before = t < t_switch_s
    after = ~before
    if not before.any() or after.sum() < 2:
        raise ValueError(f"t_switch_s={t_switch_s!r} must lie inside ({t[0]}, {t[-1]})")
    rm = float(i2[before][-1])
    tail = max(1, int(0.02 * len(t)))
    final = float(np.mean(i2[-tail:]))
    i2a = i2[after]
    ta = t[after]
    mx = float(np.max(i2a))
    if final == 0.0:
        raise ValueError("final_current_a = 0.0 (mean of the last 2 % of i2_a): the overshoot (max - final) / final "
                         "is undefined; valid: a transition that ends with current")
    outside = np.abs(i2a - final) > band * abs(final)
    settle = float(ta[np.nonzero(outside)[0][-1] + 1] - t_switch_s) if outside.any() and np.nonzero(outside)[0][-1] + 1 < len(ta) else (
        0.0 if not outside.any() else float("nan"))
    peak_i1 = float(np.max(np.asarray(i1_a)[after])) if i1_a is not None else float("nan")
    if v2_v is not None:
        i2f = i2a if i2_fund_a is None else np.asarray(i2_fund_a, dtype=float)[after]
        p = 0.5 * np.asarray(v2_v, dtype=float)[after] * i2f
        energy = float(np.trapezoid(p, ta))
    else:
        energy = float("nan")
    return TransitionMetrics(rm, final, mx, 100.0 * (mx - final) / final, settle, peak_i1, energy)
