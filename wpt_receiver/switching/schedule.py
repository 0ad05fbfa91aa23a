"""Drive schedule of the switching-level model: inverter commutations and SBAR gate windows.

The inverter switches at ``k T`` (``T`` = half the inverter period), optionally followed by a
dead time. The SBAR gate comes from the controller's own clock: the short window of rectifier
period ``n`` is centred at ``n T + phase / omega`` and lasts ``d_short[n] T``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Schedule", "make_schedule", "duty_windows"]


@dataclass(frozen=True)
class Schedule:
    """Piecewise-constant drive: interval ``j`` is ``[t[j], t[j+1])`` with inverter command
    ``cmd[j]`` (+1, -1, or 0 = dead time) and SBAR gate ``gate[j]`` (1 = lower switches on)."""

    t: np.ndarray
    cmd: np.ndarray
    gate: np.ndarray

    def gate_at(self, ts):
        j = np.clip(np.searchsorted(self.t, ts, side="right") - 1, 0, len(self.gate) - 1)
        return self.gate[j]


def make_schedule(t0_s: float, t_end_s: float, T: float, d_window, phase_rad: float, dead_time_s: float = 0.0,
                  omega: float | None = None) -> Schedule:
    """Build the drive schedule on ``[t0_s, t_end_s]``.

    ``d_window(n)`` gives the short duty of the window centred at ``n T + phase/omega`` (n may be
    negative or past the end: callers clip). Windows of duty 1 touch their neighbours: the gate
    then stays on.
    """
    omega = math.pi / T if omega is None else omega
    off = phase_rad / omega
    n_lo = int(math.floor((t0_s - off) / T)) - 1
    n_hi = int(math.ceil((t_end_s - off) / T)) + 1
    n = np.arange(n_lo, n_hi + 1)
    d = np.clip(np.asarray(d_window(n), dtype=float), 0.0, 1.0)
    c = n * T + off
    k = np.arange(int(math.floor(t0_s / T)), int(math.ceil(t_end_s / T)) + 1)
    edges = np.concatenate([c - 0.5 * d * T, c + 0.5 * d * T, k * T, k * T + dead_time_s, [t0_s, t_end_s]])
    edges = np.unique(edges[(edges >= t0_s) & (edges <= t_end_s)])
    # edges closer than 1e-9 T (6 fs at 85 kHz) are one edge: adjacent d = 1 windows then touch
    # exactly instead of leaving round-off gaps of ~1e-19 s
    edges = edges[np.concatenate([[True], np.diff(edges) > 1e-9 * T])]
    edges[-1] = t_end_s
    mid = 0.5 * (edges[:-1] + edges[1:])
    kk = np.floor(mid / T)
    cmd = np.where(mid - kk * T < dead_time_s, 0, np.where(kk % 2 == 0, 1, -1)).astype(int)
    nn = np.round((mid - off) / T).astype(int)
    dn = np.clip(np.asarray(d_window(nn), dtype=float), 0.0, 1.0)
    gate = (np.abs(mid - (nn * T + off)) < 0.5 * dn * T).astype(int)
    # merge intervals with identical drive
    keep = np.concatenate([[True], (np.diff(cmd) != 0) | (np.diff(gate) != 0)])
    return Schedule(np.append(edges[:-1][keep], t_end_s), cmd[keep], gate[keep])


def duty_windows(d_short, control_period_s: float, T: float, phase_rad: float, omega: float):
    """Map a duty per control period to a duty per gate window (window n -> control period of
    its centre ``n T + phase/omega``; before 0 the first duty, after the end the last)."""
    d = np.asarray(d_short, dtype=float)
    off = phase_rad / omega

    def fn(n):
        j = np.floor((np.asarray(n) * T + off) / control_period_s + 1e-9).astype(int)
        return d[np.clip(j, 0, len(d) - 1)]
    return fn
