"""The objective of the domain: overshoot of the secondary coil current at the stop command, the
episode cost built from it, and whether the receiver reached short mode.

Definitions (one episode = one charging window; step ``k`` is "after the stop" when the command it
is scored against is the stop, i.e. ``k dt >= t_stop``; the policy already sees the zero command
in the observation that chose the step's duty):

* **short-mode current of the true link** ``I2_sm(Lm) = w Lm V1 / (R1 R2 + (w Lm)^2)``: the steady
  ``I2`` for ``V2 = 0`` (paper eq. 4 in steady state, :func:`wpt_receiver.steady_state`), the
  largest steady ``|I2|`` any duty can give (``I2 = (w Lm V1 - R1 V2)/det`` falls with ``V2 >= 0``);
  evaluated with the true Lm of the step (it moves with the hover pose). With real devices R1 holds
  the inverter's two channels (``+ 2 Ron``) and R2 the two shorted SBAR channels (``+ 2 Ron``): the
  short mode's resistances. An envelope (fundamental) value: no ripple.
* **overshoot** ``= max over the steps after the stop of |I2|_pk,k / I2_sm(Lm_k) - 1`` (a fraction;
  ``|I2|_pk`` the step's instantaneous peak, the envelope's peak magnitude plus the SBAR's harmonic
  ripple, see ``envs.vector_kernel._link_step`` and :mod:`envs.peaks`). Negative when
  the current never reaches the short-mode level after the stop (e.g. a policy that stays in RM).
* **episode cost** ``= max(0, overshoot)``. It is handed out per step as the increase of the
  running maximum, ``cost_k = max(0, m_k) - max(0, m_{k-1})`` with ``m_k`` the running maximum of
  the step ratios, so the per-step costs (``info["cost"]``) sum exactly to the episode cost: a
  Monitor's sum of ``cost`` and a Lagrangian penalty ``lambda * cost_k`` both see the episode
  overshoot.
* **reached short mode**: the SBAR output current ``I_L`` (step mean) fell below
  :data:`SHORT_MODE_IL_A` within :data:`SHORT_MODE_WITHIN_S` after the stop and stayed there: every
  step that ends at or after ``t_stop + SHORT_MODE_WITHIN_S`` has ``I_L < SHORT_MODE_IL_A`` (and at
  least one such step exists in the window). A policy that stays in RM fails it, and so does one
  that only dips below the threshold now and then (random duties). The paper's controller decays
  with ``2 L1 / R1 ~ 4.4 ms`` and gets 7 A below 0.5 A in ~12 ms; the shortest window after the stop
  is 30 - 16 = 14 ms, so every episode of the built-in scenarios can reach it.

This module holds the definitions and what a reset needs (short-mode current, stop step); the
per-step update (running overshoot, step cost, short-mode flag, ``t_since_stop_s``) is the env
step's (``envs.vector_kernel._objective``, ``_t_since``), once for both envs.
"""

from __future__ import annotations

import numpy as np

from wpt_receiver import LinkParams, steady_state
from wpt_receiver.devices import IDEAL

__all__ = ["SHORT_MODE_IL_A", "SHORT_MODE_WITHIN_S", "short_mode_i2_a", "stop_step"]

SHORT_MODE_IL_A = 0.5
SHORT_MODE_WITHIN_S = 14e-3


def short_mode_i2_a(link: LinkParams, lm_h, devices=IDEAL) -> np.ndarray:
    """Steady short-mode ``I2`` [A] of the true link (``V2 = 0`` with ideal devices) for each true Lm
    [H] (any shape); ``devices`` (a :class:`wpt_receiver.devices.DeviceSet`) adds the driven
    inverter channels to R1 and the shorted SBAR channels to R2."""
    if not devices.is_ideal:
        link = link.with_(r1_ohm=link.r1_ohm + devices.inv_r_ohm, r2_ohm=link.r2_ohm + devices.short_r_ohm)
    return steady_state(link, 0.0, lm_h=np.asarray(lm_h, dtype=float))[1]


def stop_step(t_stop_s, dt_s: float, n_steps: int) -> np.ndarray:
    """Index of the first step scored against the stop: the least ``k`` with ``k dt >= t_stop`` on the
    same time grid as :func:`envs.scenario.command_profile` (``n_steps + 1`` if it never comes)."""
    t = np.arange(n_steps + 1) * dt_s
    return np.searchsorted(t, np.asarray(t_stop_s, dtype=float), side="left")
