"""The world around the link as the environment needs it: hover pose error -> true Lm, the battery,
the hover power. Thin views on the mission world, no second model:

* pose error and tilt: :mod:`mission_sim.world.wind` (Dryden-type gusts, drag, position-hold loop,
  thrust tilt) for a drone of :class:`mission_sim.world.power.DroneParams`;
* Lm of a pose: :func:`wpt_receiver.coupling.default_coupling` (Neumann integrals, tabulated);
* battery: :class:`mission_sim.world.battery.BatteryParams` (8S LiPo ECM: OCV(SoC), R0, R1-C1);
* hover power: :func:`mission_sim.world.power.hover_power_w`.

Time scales. Gusts have a 2 s correlation time and the position-hold loop 2 rad/s, so over a
30 ms charging window the pose (and Lm) hardly moves; it differs a lot *between* windows. The
coupling model costs ~30 us per pose, too much to call for every episode of a 1024-wide vector
env, so for each wind level (1 m/s steps) a 60 s "weather record" (pose and Lm every 20 ms, fixed
seed, after a 10 s warm-up) is computed once per process; an episode starts at a random instant of
the record and interpolates Lm along it in time. A window only starts where the pad sees
adequate coupling (Lm within :data:`LM_WINDOW_RANGE` of the nominal value over the whole window,
as a transmitter that checks coupling before it powers up would). The hold loop is driven by the
drag *fluctuation* (total drag minus the drag of the mean wind, which its integral action absorbs;
as :func:`mission_sim.world.trajectory.plan_mission` does), while the tilt sees the total drag. Measured
horizontal hover error along the records (RMS / max): 1 m/s 0.2 / 0.5 cm, 2 m/s 1.3 / 2.9 cm,
3 m/s 2.0 / 5.1 cm, 4 m/s 4.0 / 13.5 cm (Lm 0.62-1.10 x nominal, 97 % of the record within range),
6 m/s 7.8 / 24 cm (79 %), 8 m/s 13 / 30 cm (49 %): only strong winds with this hold loop
(2 rad/s) take the drone far enough off the pad that charging would not be attempted.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from mission_sim.world.battery import BatteryParams
from mission_sim.world.power import DroneParams, hover_power_w
from mission_sim.world.wind import WindParams, drag_force_n, hover_error_m, tilt_from_force, wind_series
from wpt_receiver.coupling import NOMINAL_GAP_M, default_coupling

__all__ = ["RECORD_DT_S", "RECORD_S", "GUST_INTENSITY", "lm_record", "lm_window_h", "LM_WINDOW_RANGE", "battery_operating_point",
           "ENV_BATTERY", "default_hover_power_w"]

LM_WINDOW_RANGE = (0.75, 1.5)
RECORD_DT_S = 0.02
RECORD_S = 60.0
WARMUP_S = 10.0
GUST_INTENSITY = 0.2    # gust sigma / mean wind speed (turbulence intensity; 0.6 at 3 m/s as WindParams)
_DRONE = DroneParams()
#: the envs' pack (:class:`mission_sim.world.battery.BatteryParams` defaults): :func:`battery_operating_point`'s
ENV_BATTERY = BatteryParams()


@lru_cache(maxsize=64)
def lm_record(wind_level_m_s: int):
    """``(lm_h, pose)`` along the weather record of one wind level: Lm [H] (n,) and pose (n, 4)
    = (dx, dy, dz, tilt) [m, m, m, rad] every :data:`RECORD_DT_S` (deterministic, cached)."""
    n = int(round(RECORD_S / RECORD_DT_S))
    w = float(wind_level_m_s)
    if w == 0.0:
        return np.full(n, default_coupling().lm_h(0.0, 0.0, NOMINAL_GAP_M, 0.0)), np.zeros((n, 4))
    wp = WindParams(speed_m_s=w, gust_sigma_m_s=GUST_INTENSITY * w)
    nw = int(round(WARMUP_S / RECORD_DT_S))
    rng = np.random.default_rng(10_000 + int(wind_level_m_s))
    wind = wind_series(wp, n + nw, RECORD_DT_S, rng)
    force = drag_force_n(wp, wind, np.zeros(3))
    d = np.radians(wp.direction_deg)
    mean_wind = np.array([[w * np.cos(d), w * np.sin(d), 0.0]])
    # the hold loop's integral action absorbs the mean drag: only the fluctuation moves the drone
    err = hover_error_m(wp, force - drag_force_n(wp, mean_wind, np.zeros(3)), _DRONE.total_mass_kg, RECORD_DT_S)
    acc = np.gradient(np.gradient(err, RECORD_DT_S, axis=0), RECORD_DT_S, axis=0)
    tilt, axis = tilt_from_force(_DRONE.total_mass_kg, acc, force)
    err, tilt, axis = err[nw:], tilt[nw:], axis[nw:]
    lm = default_coupling().lm_h(err[:, 0], err[:, 1], NOMINAL_GAP_M + err[:, 2], tilt, tilt_axis_rad=axis)
    return np.asarray(lm, dtype=float), np.column_stack([err, tilt])


@lru_cache(maxsize=64)
def _valid_starts(wind_level_m_s: int, n_span: int):
    lm, _ = lm_record(wind_level_m_s)
    nominal = default_coupling().lm_h(0.0, 0.0, NOMINAL_GAP_M, 0.0)
    ok = (lm >= LM_WINDOW_RANGE[0] * nominal) & (lm <= LM_WINDOW_RANGE[1] * nominal)
    # a start index i is valid when samples i .. i + n_span are all ok
    bad = np.convolve(~ok, np.ones(n_span + 1, dtype=int), mode="valid") > 0
    starts = np.flatnonzero(~bad)
    if len(starts) == 0:
        raise ValueError(f"wind speed {wind_level_m_s} m/s never leaves the drone within Lm range "
                         f"{LM_WINDOW_RANGE} x nominal; valid: a lower wind speed")
    return starts


@lru_cache(maxsize=64)
def _constant(wind_level_m_s: int) -> bool:
    """The wind level's Lm record is one value (no wind)."""
    lm, _ = lm_record(wind_level_m_s)
    return bool(np.all(lm == lm[0]))


def lm_window_h(wind_speed_m_s, start_frac, t_s):
    """True Lm [H] (n, len(t_s)) for n windows: wind speed (rounded to the 1 m/s record levels),
    start at fraction ``start_frac`` in [0, 1) of the record's valid starts, sampled at times
    ``t_s`` after the start (linear interpolation between the 20 ms record samples: the arithmetic
    of ``np.interp``, on all windows of a wind level at once)."""
    t_s = np.asarray(t_s, dtype=float)
    n_span = int(np.ceil(t_s[-1] / RECORD_DT_S)) + 1
    level = np.rint(np.asarray(wind_speed_m_s, dtype=float)).astype(int)  # round half to even, as round()
    u = np.asarray(start_frac, dtype=float)
    xp = np.arange(n_span + 1) * RECORD_DT_S
    j = np.minimum(np.maximum(np.searchsorted(xp, t_s, side="right") - 1, 0), n_span - 1)
    out = np.empty((len(u), len(t_s)))
    for lv in sorted(set(level.tolist())):  # a handful of wind levels, not one pass per window
        rows = np.flatnonzero(level == lv)
        rows = slice(None) if len(rows) == len(u) else rows   # one level for all: plain slices, not a gather
        lm, _ = lm_record(int(lv))
        starts = _valid_starts(int(lv), n_span)
        if _constant(int(lv)):   # no wind: one Lm along the record (np.interp of a constant is that number)
            out[rows] = lm[0]
            continue
        i0 = starts[np.minimum((u[rows] * len(starts)).astype(int), len(starts) - 1)]
        seg = lm[i0[:, None] + np.arange(n_span + 1)]
        out[rows] = _interp_rows(xp, seg, t_s, j)
    return out


def _interp_rows(xp, fp, x, j):
    """``np.interp(x, xp, fp[r])`` for every row r of ``fp`` (x inside [xp[0], xp[-1]], ``j`` the
    left sample of each x): numpy's formula ``slope (x - xp[j]) + fp[j]``, exact at the samples."""
    slope = (fp[:, j + 1] - fp[:, j]) / (xp[j + 1] - xp[j])
    val = slope * (x - xp[j]) + fp[:, j]
    val = np.where(x == xp[j], fp[:, j], val)
    return np.where(x >= xp[-1], fp[:, -1:], val)


def battery_operating_point(soc, params: BatteryParams = ENV_BATTERY):
    """The pack's equivalent circuit at ``soc`` (vectorised): ``(ocv_v, docv_dsoc_v, r0_ohm, r1_ohm,
    tau1_s, capacity_ah)``, arrays of shape (n,)."""
    s = np.asarray(soc, dtype=float)
    # dOCV/dSoC: central difference inside, one-sided at the ends (OCV(SoC) is clipped to [0, 1], so
    # a central difference across an end would halve the slope)
    h = 1e-4
    # np.minimum/np.maximum: np.clip is slow on tiny arrays
    lo, hi = np.minimum(np.maximum(s - h, 0.0), 1.0), np.minimum(np.maximum(s + h, 0.0), 1.0)
    n = s.size
    ocv = params.ocv_v(np.concatenate([s.ravel(), hi.ravel(), lo.ravel()]))   # one call, elementwise: same numbers
    ocv_s, ocv_hi, ocv_lo = (ocv[i * n:(i + 1) * n].reshape(s.shape) for i in range(3))
    one = np.ones_like(s)
    return (ocv_s, (ocv_hi - ocv_lo) / (hi - lo), params.r0_ohm * one,
            params.r1_ohm * one, params.tau1_s * one, params.capacity_ah * one)


@lru_cache(maxsize=1)
def default_hover_power_w() -> float:
    """Electrical hover power [W] of the default drone (momentum theory, :mod:`mission_sim.world.power`)."""
    return float(hover_power_w(_DRONE))
