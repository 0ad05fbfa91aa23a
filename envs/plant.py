"""The world around the link, as the environment needs it: hover pose error -> Lm, and the battery.

Thin views on the mission world (:mod:`wpt_receiver.coupling`, :mod:`mission_sim.battery`,
:mod:`mission_sim.wind`); nothing here is a second model.

PROVISIONAL: until branch issue4 is merged the three functions below carry minimal stand-ins.
"""

from __future__ import annotations

import numpy as np

__all__ = ["lm_at_pose_h", "hover_pose_error", "battery_operating_point"]


def lm_at_pose_h(dx_m, dy_m, dz_m, tilt_rad):
    """True mutual inductance [H] at a hover pose error (offsets from the nominal pose), vectorised."""
    # PROVISIONAL stand-in (issue4 coupling pending): Gaussian fall-off with lateral offset and gap
    r2 = np.asarray(dx_m) ** 2 + np.asarray(dy_m) ** 2
    return 6.25e-6 * np.exp(-r2 / (2 * 0.06**2)) * np.exp(-np.asarray(dz_m) / 0.05) * np.cos(tilt_rad)


def hover_pose_error(wind_speed_m_s, innov, dt_s: float):
    """Hover pose error ``(dx, dy, dz, tilt)`` [m, m, m, rad] on a grid of step ``dt_s``.

    ``innov`` (n, k, 4) standard normals, ``wind_speed_m_s`` (n,). Returns four (n, k) arrays.
    """
    # PROVISIONAL stand-in (issue4 wind/hover model pending): Ornstein-Uhlenbeck per axis
    w = np.asarray(wind_speed_m_s, dtype=float)[:, None]
    sigma = np.array([0.004, 0.004, 0.002, 0.01])[None, :] * (1.0 + w)   # (n, 4)
    tau = np.array([0.3, 0.3, 0.3, 0.1])
    phi = np.exp(-dt_s / tau)
    x = np.empty_like(innov)
    x[:, 0] = sigma * innov[:, 0]
    for j in range(1, innov.shape[1]):
        x[:, j] = phi * x[:, j - 1] + sigma * np.sqrt(1 - phi**2) * innov[:, j]
    return x[..., 0], x[..., 1], x[..., 2], x[..., 3]


def battery_operating_point(soc):
    """Battery equivalent circuit linearised at ``soc`` (vectorised).

    Returns ``(ocv_v, docv_dsoc_v, r0_ohm, r1_ohm, tau1_s, capacity_ah)``, arrays of shape (n,).
    """
    # PROVISIONAL stand-in (issue4 battery pending): 8S Li-ion, 5 Ah
    s = np.asarray(soc, dtype=float)
    cell = 3.3 + 0.9 * s - 0.25 * np.exp(-20 * s)
    dcell = 0.9 + 5.0 * np.exp(-20 * s)
    one = np.ones_like(s)
    return 8 * cell, 8 * dcell, 0.02 * one, 0.015 * one, 10.0 * one, 5.0 * one
