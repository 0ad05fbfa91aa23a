"""Equivalent-circuit battery (OCV(SoC), series R0, one R1-C1 pair) and a CC-CV charge manager: parameters.

The parameters, their sources and the OCV curve (numpy, for the environments, the config's ranges
and the usable energy) live here; the mission's battery step and charger run compiled, in
:mod:`.loop_kernel` (``_bat_step``, ``_charger_command``: the one implementation of the formulas below).

Circuit (charging current ``i > 0``)::

    v_terminal = OCV(SoC) + R0 i + v1,        C1 dv1/dt = i - v1 / R1,      dQ/dt = i

Stepping is exact for a current held over the step (zero-order hold): ``v1`` follows its
exponential in closed form, and every energy of the step is integrated in closed form, so

    terminal energy = OCV_k dQ + R0 i^2 dt + (R1 losses) + d(C1 v1^2 / 2)

holds to rounding (OCV is held at its value at the start of the step: the chemistry's energy is
``sum OCV_k dQ_k``).

Default values (``BatteryParams()``): an 8S lithium-polymer pack (29.6 V nominal, 33.6 V full)
of 1.3 Ah, sized for a ~1 kg drone.

* OCV(SoC) per cell: the fitted curve of Chen & Rincon-Mora, "Accurate electrical battery model
  capable of predicting runtime and I-V performance", IEEE Trans. Energy Conversion 21(2), 2006:
  ``-1.031 exp(-35 SoC) + 3.685 + 0.2156 SoC - 0.1178 SoC^2 + 0.3201 SoC^3`` V (a polymer cell;
  it reaches 4.10 V at SoC = 1, so the CV threshold default is 4.10 V/cell).
* R0 = 12 mOhm/cell, R1 = 6 mOhm/cell, C1 = 2500 F/cell (tau = 15 s): an assumption in the range
  hobby chargers report for high-rate 1-2 Ah LiPo packs (3-15 mOhm/cell internal resistance); not
  from a datasheet. The RC pair gives the slow relaxation seen after load steps.
* CC at 1 C (1.3 A), cut-off at C/10: the usual LiPo charging rule. The charge manager's command
  is the DC current the rectifier should deliver: the load current (propulsion + avionics, ``P / VL``)
  plus the battery current, ``cc_current_a`` in CC and, in CV, the model-based ``(V_cv - OCV - v1) / R0``
  that puts the terminal voltage at the CV limit (never above ``cc_current_a``); below the cut-off the
  battery is *full*.
* Power path: a *full* battery's command is the load current, less the CV law's current where that is
  negative: ``max(P / VL + min(0, (V_cv - OCV - v1) / R0), 0)``. Over an energised pad the pad feeds the
  motors and the avionics and the pack is held at or below the CV voltage, as a charger IC with a power
  path does (TI BQ25601/BQ25601D, "power path management": the input powers the system, charging
  terminated or not; the battery joins in, "supplement mode", only when the input is overloaded); a pack
  above CV (a receiver that delivered more than the load) is drawn back to it in proportion, with no on-off
  switching. Over-voltage trip: above ``V_cv + TRIP_MARGIN_CELL_V`` per cell (20 mV/cell) the command is 0
  (short mode) until the pack is back below it. The command follows the load at each BMS update outside
  the dead band (``sim.cmd_deadband_a``; entering or leaving *full* is always applied). The hold depends on
  the policy delivering its command: the pack carries the difference between the load and what the
  rectifier delivers, which neither the dead band nor the charger bounds. Measured
  (``tests/test_mission_recharge.py``), 600 s hovering over pad 0 without wind from SoC 0.985, model_based:
  full at 0.9934 after ~100 s, then down to 0.9850 at the end (the policy delivers ~0.07 A less than its
  command: the feed-forward's shortfall), 1.3 kJ into the pack, 64.4 kJ from the pad; ``hysteresis``, same
  hover: its delivery swings between ~0 and ~6 A in bursts of seconds, and for ~130 s it delivers ~0.14 A
  against a 3.0 A command, so the pack falls to the recharge threshold (min SoC 0.8993), charges again and
  ends at 0.9725 (max 0.9934, 33.1 kJ into the pack). With the command 0 when full (before 2026-11-27)
  model_based flew on its pack down to the recharge threshold (min SoC 0.901), final 0.988, 14.6 kJ into the
  pack, 65.5 kJ from the pad. With no load (``P = 0``) the command is 0: short mode. The default mission
  with ``hysteresis``: max SoC 0.9899, at most 3.6 mV/cell above CV (11.4 s above CV, 0.6 s above
  ``V_cv + R0 deadband``, the excess below which the correction is under the dead band), final 0.9669,
  20.7 kJ from the pads (SoC 1.006 with the command 0 when full and no CV rule, main before 2026-11-27).
  A policy that overshoots its command by amperes for seconds can still take the pack a little past CV:
  ``hysteresis`` from SoC 0.999 (above CV's SoC 0.9965 at rest, where the CV correction, 0.2 A, is under
  the dead band) reaches SoC 1.0015 (max 13.6 mV/cell above CV).
* New charge cycle at each pad: a pad switching on (input power appearing) clears *full*, as a drone's
  host restarts the charger's cycle on arrival (TI BQ25601D: toggling CE or CHG_CONFIG starts a new
  cycle), so the pack is topped off at every pad visit (CC/CV, then *full* again at the cut-off) instead of
  floating at whatever SoC it arrived with.
* Recharge: a full battery starts a new charge cycle when its voltage falls ``recharge_drop_cell_v``
  (default 100 mV) per cell below the CV voltage: the recharge threshold of charger ICs (e.g. TI
  BQ25601D, register bit VRECHG: "recharge threshold 100 mV (default) or 200 mV" below VREG; TI's
  other single-cell chargers use the same convention). The voltage compared is the charger's own
  estimate without the ohmic drop, ``(OCV(SoC) + v1) / n`` (the quantity its CV law regulates), so
  the propulsion load's ``R0 i`` does not trigger it; 100 mV/cell is SoC ~0.87 on this OCV curve. The
  charger looks at it at its BMS updates, i.e. over an energised pad: a full pack that the flight
  between pads has run below the threshold starts its new cycle at the next pad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..validation import Range, check_number, check_number_fields, check_positive

__all__ = ["BatteryParams", "ocv_cell_v", "ocv_cell_energy_v", "CcCvParams", "TRIP_MARGIN_CELL_V"]

#: over-voltage trip of a *full* pack [V per cell]: above ``cv_cell_v`` + this, ``OCV + v1`` per cell, the charger's
#: command is 0 (short mode) until the pack is back below it (module notes). 20 mV/cell = 160 mV on the default 8S
#: pack = R0 x 1.7 A: above what the CV hold leaves for a policy's tracking error (the hold drains the pack with
#: ``(V_cv - OCV - v1) / R0``), so the trip acts only on a gross over-delivery.
TRIP_MARGIN_CELL_V = 0.02


def ocv_cell_v(soc):
    """Open-circuit voltage of one cell [V] (Chen & Rincon-Mora 2006 fit); SoC clipped into [0, 1]."""
    s = np.clip(np.asarray(soc, dtype=float), 0.0, 1.0)
    return -1.031 * np.exp(-35.0 * s) + 3.685 + 0.2156 * s - 0.1178 * s**2 + 0.3201 * s**3


def ocv_cell_energy_v(soc):
    """``int_0^soc OCV(s) ds`` per cell [V] (closed form); times ``n_series * capacity_c`` gives joules."""
    s = np.clip(np.asarray(soc, dtype=float), 0.0, 1.0)
    return (-1.031 / 35.0 * (1.0 - np.exp(-35.0 * s)) + 3.685 * s + 0.2156 / 2 * s**2 - 0.1178 / 3 * s**3
            + 0.3201 / 4 * s**4)


@dataclass(frozen=True)
class BatteryParams:
    """Battery pack parameters (see the module notes for the sources).

    n_series [-], capacity_ah [A h], r0_ohm_cell / r1_ohm_cell [ohm per cell], c1_f_cell [F per cell],
    initial_soc [-].
    """

    n_series: int = 8
    capacity_ah: float = 1.3
    r0_ohm_cell: float = 0.012
    r1_ohm_cell: float = 0.006
    c1_f_cell: float = 2500.0
    initial_soc: float = 0.9

    def __post_init__(self):
        check_number_fields(self)
        # a Python int from any whole number; a string such as "6" refused (it passed float() and failed later)
        object.__setattr__(self, "n_series", check_number("n_series", self.n_series, Range(1, 32, integer=True)))
        check_positive(self, "capacity_ah", "r0_ohm_cell", "r1_ohm_cell", "c1_f_cell")
        if not 0.0 <= self.initial_soc <= 1.0:
            raise ValueError(f"initial_soc={self.initial_soc!r} is invalid; valid range: [0, 1]")

    @property
    def r0_ohm(self) -> float:
        return self.n_series * self.r0_ohm_cell

    @property
    def r1_ohm(self) -> float:
        return self.n_series * self.r1_ohm_cell

    @property
    def c1_f(self) -> float:
        return self.c1_f_cell / self.n_series

    @property
    def tau1_s(self) -> float:
        return self.r1_ohm * self.c1_f

    @property
    def capacity_c(self) -> float:
        return 3600.0 * self.capacity_ah

    def ocv_v(self, soc):
        """Pack open-circuit voltage [V]."""
        return self.n_series * ocv_cell_v(soc)

    def usable_energy_j(self, soc):
        """Chemical energy between SoC = 0 and ``soc`` [J]: ``n Q int_0^soc OCV ds``."""
        return self.n_series * self.capacity_c * ocv_cell_energy_v(soc)


@dataclass(frozen=True)
class CcCvParams:
    """CC-CV charge management: battery current limit, CV voltage per cell, cut-off current [A].

    cc_current_a : charge current in CC (default 1 C = 1.3 A)
    cv_cell_v : terminal voltage per cell held in CV (default 4.10 V: the OCV curve's top)
    cutoff_current_a : CV current below which the battery counts as full (default C/10)
    recharge_drop_cell_v : a full battery is charged again once ``(OCV + v1) / n`` falls this far
        below ``cv_cell_v`` [V per cell] (default 0.1 V: the recharge threshold of charger ICs, see
        the module notes); valid range [0.005, 0.5] V
    """

    cc_current_a: float = 1.3
    cv_cell_v: float = 4.10
    cutoff_current_a: float = 0.13
    recharge_drop_cell_v: float = 0.1

    def __post_init__(self):
        check_number_fields(self)
        check_positive(self, "cc_current_a", "cv_cell_v", "cutoff_current_a")
        lo, hi = float(ocv_cell_v(0.0)), float(ocv_cell_v(1.0))
        if not lo <= self.cv_cell_v <= hi:  # above the OCV at SoC 1 the CV phase never ends: SoC > 1
            raise ValueError(f"cv_cell_v={self.cv_cell_v!r} is invalid; valid range: [{lo:.4f}, "
                             f"{math.floor(hi * 1e4) / 1e4:.4f}] V (the cell's open-circuit voltage from SoC 0 to 1)")
        if not 0.005 <= self.recharge_drop_cell_v <= 0.5:
            raise ValueError(f"recharge_drop_cell_v={self.recharge_drop_cell_v!r} is invalid; valid range: "
                             "[0.005, 0.5] V per cell below cv_cell_v")
        if self.cutoff_current_a >= self.cc_current_a:
            raise ValueError(f"cutoff_current_a={self.cutoff_current_a!r} is invalid; valid range: "
                             f"(0, cc_current_a={self.cc_current_a!r})")
