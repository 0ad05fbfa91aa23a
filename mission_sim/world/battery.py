"""Equivalent-circuit battery (OCV(SoC), series R0, one R1-C1 pair) and a CC-CV charge manager.

Batched: every array has one entry per battery, so an environment can hold N batteries at once.

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
* CC at 1 C (1.3 A), cut-off at C/10: the usual LiPo charging rule.
* Recharge: a full battery starts a new charge cycle when its voltage falls ``recharge_drop_cell_v``
  (default 100 mV) per cell below the CV voltage: the recharge threshold of charger ICs (e.g. TI
  BQ25601D, register bit VRECHG: "recharge threshold 100 mV (default) or 200 mV" below VREG; TI's
  other single-cell chargers use the same convention). The voltage compared is the charger's own
  estimate without the ohmic drop, ``(OCV(SoC) + v1) / n`` (the quantity its CV law regulates), so
  the propulsion load's ``R0 i`` does not trigger it; 100 mV/cell is SoC ~0.87 on this OCV curve.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..validation import check_positive

__all__ = ["BatteryParams", "ocv_cell_v", "ocv_cell_energy_v", "held_current_step", "scalar_stepper", "Battery", "StepEnergies", "CcCvParams",
           "CcCvCharger"]


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
        if int(self.n_series) != self.n_series or not 1 <= self.n_series <= 32:
            raise ValueError(f"n_series={self.n_series!r} is invalid; valid range: integer 1..32")
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


def _ocv_cell_scalar(s: float) -> float:
    s = 0.0 if s < 0.0 else (1.0 if s > 1.0 else s)
    return -1.031 * math.exp(-35.0 * s) + 3.685 + 0.2156 * s - 0.1178 * s * s + 0.3201 * s * s * s


def scalar_stepper(p: BatteryParams):
    """Scalar (pure Python, for hot loops) version of :meth:`Battery.step` for one battery.

    Returns ``step(soc, v1_v, current_a, dt_s) -> (soc1, v1_1, chem_j, r0_loss_j, r1_loss_j,
    c1_delta_j, mean_terminal_v)`` with the constants of ``p`` bound; same formulas as the
    batched step (exact for the held current; OCV held at its start-of-step value).
    """
    r0, r1, tau, c1 = p.r0_ohm, p.r1_ohm, p.tau1_s, p.c1_f
    n_cells, cap = p.n_series, p.capacity_c
    exp = math.exp

    def step(soc, v1_v, i, dt_s):
        e = exp(-dt_s / tau)
        vinf = r1 * i
        dv = v1_v - vinf
        int_v = vinf * dt_s + dv * tau * (1.0 - e)
        int_v2 = vinf * vinf * dt_s + 2.0 * vinf * dv * tau * (1.0 - e) + dv * dv * 0.5 * tau * (1.0 - e * e)
        s = 0.0 if soc < 0.0 else (1.0 if soc > 1.0 else soc)
        ocv = n_cells * (-1.031 * exp(-35.0 * s) + 3.685 + 0.2156 * s - 0.1178 * s * s + 0.3201 * s * s * s)
        dq = i * dt_s
        v1n = vinf + dv * e
        return (soc + dq / cap, v1n, ocv * dq, r0 * i * i * dt_s, int_v2 / r1, 0.5 * c1 * (v1n * v1n - v1_v * v1_v),
                ocv + r0 * i + int_v / dt_s)
    return step


def held_current_step(p: BatteryParams, soc: float, v1_v: float, current_a: float, dt_s: float):
    """One scalar battery step (see :func:`scalar_stepper`); returns its 7-tuple."""
    return scalar_stepper(p)(soc, v1_v, current_a, dt_s)


@dataclass
class StepEnergies:
    """Energies of one battery step [J] (arrays over the batch): terminal = chem + r0 + r1 + d_c1."""

    terminal_j: np.ndarray
    chem_j: np.ndarray
    r0_loss_j: np.ndarray
    r1_loss_j: np.ndarray
    c1_delta_j: np.ndarray


class Battery:
    """A batch of ``n`` equivalent-circuit batteries with states ``soc`` and ``v1_v`` (RC voltage)."""

    def __init__(self, params: BatteryParams = BatteryParams(), n: int = 1, soc=None):
        self.p = params
        self.n = int(n)
        self.soc = np.full(self.n, params.initial_soc, dtype=float) if soc is None else \
            np.broadcast_to(np.asarray(soc, dtype=float), (self.n,)).copy()
        self.v1_v = np.zeros(self.n)

    def ocv_v(self):
        return self.p.ocv_v(self.soc)

    def terminal_v(self, current_a):
        """Terminal voltage [V] for an instantaneous current (charging > 0)."""
        return self.ocv_v() + self.p.r0_ohm * np.asarray(current_a, dtype=float) + self.v1_v

    def rc_mean(self, dt_s: float):
        """``(a, b)`` with mean RC voltage over a step = ``a + b i`` for a held current ``i``."""
        tau = self.p.tau1_s
        e = np.exp(-dt_s / tau)
        frac = tau * (1.0 - e) / dt_s
        return self.v1_v * frac, self.p.r1_ohm * (1.0 - frac)

    def mean_terminal_v(self, current_a, dt_s: float):
        """Mean terminal voltage [V] over a step with the current held: OCV + R0 i + mean(v1)."""
        a, b = self.rc_mean(dt_s)
        i = np.asarray(current_a, dtype=float)
        return self.ocv_v() + a + (self.p.r0_ohm + b) * i

    def step(self, current_a, dt_s: float) -> StepEnergies:
        """Advance by ``dt_s`` with ``current_a`` held; returns the step's energies (exact)."""
        p = self.p
        i = np.broadcast_to(np.asarray(current_a, dtype=float), (self.n,))
        tau = p.tau1_s
        e = np.exp(-dt_s / tau)
        vinf = p.r1_ohm * i
        dv = self.v1_v - vinf
        int_v = vinf * dt_s + dv * tau * (1.0 - e)
        int_v2 = vinf**2 * dt_s + 2.0 * vinf * dv * tau * (1.0 - e) + dv**2 * 0.5 * tau * (1.0 - e * e)
        ocv = self.ocv_v()
        dq = i * dt_s
        v1_new = vinf + dv * e
        out = StepEnergies(
            terminal_j=(ocv + p.r0_ohm * i) * dq + i * int_v,
            chem_j=ocv * dq,
            r0_loss_j=p.r0_ohm * i * i * dt_s,
            r1_loss_j=int_v2 / p.r1_ohm,
            c1_delta_j=0.5 * p.c1_f * (v1_new**2 - self.v1_v**2),
        )
        self.v1_v = v1_new
        self.soc = self.soc + dq / p.capacity_c
        return out


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


class CcCvCharger:
    """Battery-management side of charging: turns the battery state into the SBAR command ``I_L*``.

    The command is the DC current the rectifier should deliver: the propulsion current plus the
    battery charge current, which is ``cc_current_a`` in CC and, in CV, the model-based current
    that puts the terminal voltage at the CV limit, ``(V_cv - OCV - v1) / R0``. When that drops
    below the cut-off the battery is *full*: the command becomes 0 (short mode) and stays 0 until
    the battery's voltage without its ohmic drop, ``OCV + v1``, falls ``recharge_drop_cell_v`` per
    cell below the CV voltage (the recharge threshold of a real charger; module notes): then
    *full* and *cv* clear and a new CC-CV cycle starts. Batched like :class:`Battery`.
    """

    def __init__(self, params: CcCvParams, battery: Battery):
        self.p = params
        self.bat = battery
        self.full = np.zeros(battery.n, dtype=bool)
        self.cv = np.zeros(battery.n, dtype=bool)

    def reset(self):
        self.full[:] = False
        self.cv[:] = False

    def battery_target_a(self):
        """Charge current wanted by the battery now [A] (0 when full)."""
        b = self.bat
        v_cv = self.p.cv_cell_v * b.p.n_series
        v_rest = b.ocv_v() + b.v1_v
        recharge = self.full & (v_rest < (self.p.cv_cell_v - self.p.recharge_drop_cell_v) * b.p.n_series)
        self.full &= ~recharge
        self.cv &= ~recharge
        i_cv = (v_cv - v_rest) / b.p.r0_ohm
        self.cv |= i_cv < self.p.cc_current_a
        tgt = np.minimum(self.p.cc_current_a, i_cv)
        self.full |= self.cv & (tgt < self.p.cutoff_current_a)
        return np.where(self.full, 0.0, np.maximum(tgt, 0.0))

    def command_a(self, propulsion_current_a):
        """SBAR command ``I_L*`` [A]: propulsion current + battery target, or 0 when full."""
        tgt = self.battery_target_a()
        return np.where(self.full, 0.0, tgt + np.asarray(propulsion_current_a, dtype=float))
