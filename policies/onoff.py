"""Hysteresis ON-OFF: the classic unsynchronised mode switching of an SBAR (RM or SM, nothing between).

The SBAR output current ``I_L`` (measured, filtered by a first-order low-pass of time constant
``tau_s``) is held in a band around the command: above ``I* + band`` -> short mode, below
``I* - band`` -> rectification mode, in between keep the mode. A zero command means short mode.
Every decision switches the coil between its RM and SM steady states at once, so each RM -> SM
switch excites the link's ringing exactly like the paper's step.
"""

from __future__ import annotations

import numpy as np

from mission_sim.contract import OBS_INDEX, PolicyContext, denormalise_obs

__all__ = ["HysteresisPolicy"]


class HysteresisPolicy:
    """Bang-bang duty (0 = RM, 1 = SM) with hysteresis ``band_a`` [A] on the filtered output current."""

    name = "hysteresis"

    def __init__(self, ctx: PolicyContext = PolicyContext(), band_a: float = 0.5, tau_s: float = 1e-3):
        if not (np.isfinite(band_a) and band_a >= 0):
            raise ValueError(f"band_a={band_a!r} is invalid; valid range: [0, inf)")
        if not (np.isfinite(tau_s) and tau_s > 0):
            raise ValueError(f"tau_s={tau_s!r} is invalid; valid range: (0, inf)")
        self.ctx = ctx
        self.band_a = float(band_a)
        self.alpha = ctx.control_period_s / (tau_s + ctx.control_period_s)
        self.reset(1)

    def reset(self, n: int = 1) -> None:
        self.n = int(n)
        self._f = None
        self._d = None

    def act(self, obs):
        phys = denormalise_obs(np.atleast_2d(obs))
        il, cmd = phys[:, OBS_INDEX["rect_current_a"]], phys[:, OBS_INDEX["charge_cmd_a"]]
        if self._f is None or len(self._f) != len(il):
            self._f = il.copy()
            self._d = np.round(phys[:, OBS_INDEX["last_d_short"]])
        self._f += self.alpha * (il - self._f)
        d = np.where(self._f > cmd + self.band_a, 1.0, np.where(self._f < cmd - self.band_a, 0.0, self._d))
        d = np.where(cmd <= 0.0, 1.0, d)
        self._d = d
        return d.copy()
