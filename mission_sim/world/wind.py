"""Seeded wind and the hover position error it causes.

* Wind = mean + gusts. Gusts per axis are first-order Gauss-Markov processes (the low-order
  form of the Dryden turbulence model, MIL-HDBK-1797: variance ``sigma^2``, correlation time
  ``tau = L / V``), sampled exactly: ``w_k = a w_{k-1} + sigma sqrt(1 - a^2) xi_k``,
  ``a = exp(-dt/tau)``, started from the stationary distribution. Vertical gusts have half the
  horizontal sigma.
* Drag force on the airframe ``F = 0.5 rho Cd S |w - v| (w - v)``.
* Hover position error: the position-hold loop is a second-order system
  ``e'' + 2 zeta w_p e' + w_p^2 e = (F - F_mean) / m`` (the mean force is absorbed by the
  loop's integral action as a steady tilt); discretised once (ZOH) and run with ``lfilter``.
* Tilt: the thrust vector balances weight, drag and the commanded acceleration,
  ``n ~ (m a - F_xy, m g)``; the receiver coil's normal is the thrust direction.

Defaults: 3 m/s mean wind (a light breeze, Beaufort 2), gust sigma 0.6 m/s, tau 2 s
(Dryden low-altitude length scale of order 10-20 m at a few m/s), hold loop 2 rad/s and
damping 0.8 (typical of multirotor position controllers), Cd S = 0.04 m^2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wpt_receiver.lti import lfilter, zoh_tf

from ..validation import check_number_fields
from .power import G_M_S2

__all__ = ["WindParams", "gust_series", "wind_series", "drag_force_n", "hold_filter", "hover_error_m", "tilt_from_force"]


@dataclass(frozen=True)
class WindParams:
    """Wind and position-hold parameters.

    speed_m_s (mean wind speed) [m/s], direction_deg (azimuth the wind blows *towards*, from +x, counter-clockwise),
    gust_sigma_m_s [m/s], gust_tau_s [s], hold_omega_rad_s [rad/s], hold_zeta [-], drag_area_m2 (Cd S) [m^2],
    air_density_kg_m3.
    """

    speed_m_s: float = 3.0
    direction_deg: float = 30.0
    gust_sigma_m_s: float = 0.6
    gust_tau_s: float = 2.0
    hold_omega_rad_s: float = 2.0
    hold_zeta: float = 0.8
    drag_area_m2: float = 0.04
    air_density_kg_m3: float = 1.225

    def __post_init__(self):
        check_number_fields(self)
        for name in ("speed_m_s", "gust_sigma_m_s"):
            v = float(getattr(self, name))
            if not math.isfinite(v) or v < 0 or v > 30:
                raise ValueError(f"{name}={v!r} is invalid; valid range: [0, 30] m/s")
        for name in ("gust_tau_s", "hold_omega_rad_s", "hold_zeta", "drag_area_m2", "air_density_kg_m3"):
            v = float(getattr(self, name))
            if not math.isfinite(v) or v <= 0:
                raise ValueError(f"{name}={v!r} is invalid; valid range: (0, inf)")
        if not math.isfinite(self.direction_deg):
            raise ValueError(f"direction_deg={self.direction_deg!r} is invalid; valid range: finite")


def gust_series(n: int, dt_s: float, sigma: float, tau_s: float, rng: np.random.Generator, state: list | None = None,
                first: bool = True) -> np.ndarray:
    """Stationary first-order Gauss-Markov samples (n,) with std ``sigma`` and correlation time ``tau_s``.

    In chunks: ``state`` (``[[0.0]]`` to start) carries the filter from one call to the next and
    ``first`` is True for the first chunk only (its first sample is the stationary start)."""
    a = math.exp(-dt_s / tau_s)
    xi = rng.standard_normal(n)
    if first:
        xi[0] *= sigma
        xi[1:] *= sigma * math.sqrt(1.0 - a * a)
    else:
        xi *= sigma * math.sqrt(1.0 - a * a)
    return lfilter([1.0], [1.0, -a], xi, state=state)


def wind_series(p: WindParams, n: int, dt_s: float, rng, states: list | None = None, first: bool = True) -> np.ndarray:
    """Wind velocity (n, 3) [m/s] on a uniform grid of step ``dt_s``: the x, y and z gusts drawn one
    after the other from ``rng``, or, in chunks, from ``rng`` = three generators (one per axis,
    each where its stream is) with ``states`` / ``first`` as for :func:`gust_series`."""
    d = math.radians(p.direction_deg)
    gens = (rng, rng, rng) if isinstance(rng, np.random.Generator) else rng
    states = states if states is not None else [None] * 3
    sig = p.gust_sigma_m_s
    w = np.empty((n, 3))
    w[:, 0] = p.speed_m_s * math.cos(d) + gust_series(n, dt_s, sig, p.gust_tau_s, gens[0], states[0], first)
    w[:, 1] = p.speed_m_s * math.sin(d) + gust_series(n, dt_s, sig, p.gust_tau_s, gens[1], states[1], first)
    w[:, 2] = gust_series(n, dt_s, 0.5 * sig, p.gust_tau_s, gens[2], states[2], first)
    return w


def drag_force_n(p: WindParams, wind_m_s, vel_m_s) -> np.ndarray:
    """Aerodynamic force on the airframe (n, 3) [N]: ``0.5 rho Cd S |w - v| (w - v)``."""
    rel = np.asarray(wind_m_s, dtype=float) - np.asarray(vel_m_s, dtype=float)
    return 0.5 * p.air_density_kg_m3 * p.drag_area_m2 * np.linalg.norm(rel, axis=-1, keepdims=True) * rel


def hold_filter(p: WindParams, dt_s: float):
    """``(num, den)`` of the position-hold loop (force / mass -> error) discretised with a ZOH."""
    w, z = p.hold_omega_rad_s, p.hold_zeta
    num, den = zoh_tf([1.0], [1.0, 2 * z * w, w * w], dt_s)
    return np.ravel(num), den


def hover_error_m(p: WindParams, force_n: np.ndarray, mass_kg: float | np.ndarray, dt_s: float,
                  state: list | None = None) -> np.ndarray:
    """Position error (n, 3) [m] of the hold loop driven by a force disturbance (n, 3) [N].

    Pass the force *fluctuation* (total drag minus the drag of the mean wind, which the loop's
    integral action absorbs). ``mass_kg``: the total mass [kg], a number or one per sample (n,) (a payload dropped
    on the way). ``state`` (three ``[0.0, 0.0]``, one per axis) continues the filter
    across chunks (see :func:`wpt_receiver.lti.lfilter`).
    """
    f = np.asarray(force_n, dtype=float)
    if len(f) == 0:
        return np.zeros((0, 3))
    m = np.asarray(mass_kg, dtype=float)
    dev = f / (m[:, None] if m.ndim else mass_kg)   # (a mass per sample: a payload dropped on the way)
    num, den = hold_filter(p, dt_s)
    return lfilter(num, den, dev, axis=0, state=state)


def tilt_from_force(mass_kg: float | np.ndarray, accel_m_s2: np.ndarray, force_n: np.ndarray):
    """Tilt magnitude [rad] and tilt-axis azimuth [rad] of the thrust vector (coil normal).

    The thrust's horizontal part is ``m a_xy - F_xy``; the coil normal leans that way. The axis
    azimuth follows :mod:`wpt_receiver.coupling`'s convention (normal leans to azimuth axis - pi/2).
    ``mass_kg``: the total mass [kg], a number or one per sample (n,).
    """
    a = np.asarray(accel_m_s2, dtype=float)
    f = np.asarray(force_n, dtype=float)
    m = np.asarray(mass_kg, dtype=float)
    h = (m[:, None] if m.ndim else mass_kg) * a[:, :2] - f[:, :2]   # (a mass per sample: a payload dropped)
    v = mass_kg * (G_M_S2 + a[:, 2]) - f[:, 2]
    tilt = np.arctan2(np.hypot(h[:, 0], h[:, 1]), np.maximum(v, 1e-9))
    axis = np.arctan2(h[:, 1], h[:, 0]) + 0.5 * math.pi
    return tilt, axis
