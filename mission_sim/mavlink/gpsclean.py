"""Rejection of implausible GPS fixes (corrupt bytes, glitches) before a log is replayed.

A DataFlash record has no checksum: one flipped byte in a GPS record gives a fix 92 km away or
118 km high that the replay would fly to. Each fix (sorted by time) is checked, and rejected
ones are counted by reason in ``FlightLog.gps_rejected``:

``quality``   HDOP above :data:`MAX_HDOP` or fewer than :data:`MIN_SATS` satellites, where logged
``origin``    (a .tlog) GLOBAL_POSITION_INT's altitude farther than :data:`ORIGIN_TOL_M` from the GPS
              receiver's own altitude (GPS_RAW_INT.alt) reported with it: the autopilot's estimator
              had no GPS origin yet and reported its height above the boot spot as AMSL (the
              dronekit tlog shows 0.22 m AMSL before, 590 m after, the origin was set at a reboot)
``altitude``  outside [-500, 10000] m AMSL (the range :class:`~mission_sim.mavlink.geodesy.GeoPoint` takes)
``jump``      farther from the median of its neighbours (centred window of :data:`WINDOW` fixes)
              than a vehicle at :data:`MAX_SPEED_M_S` horizontally / :data:`MAX_VSPEED_M_S`
              vertically could have moved, plus :data:`SLACK_M` of GPS noise:
              d_h > SLACK_M + MAX_SPEED_M_S * dt, d_v > SLACK_M + MAX_VSPEED_M_S * dt, with dt the
              longest time from the fix to a neighbour in the window (capped at :data:`MAX_DT_S`).
              Two passes: a second one on the survivors catches a spike that bent a median.

So no accepted fix lies farther than :func:`max_excursion_m` from the flight's own extent.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .geodesy import GeoPoint, geodetic_to_enu

__all__ = ["reject_outliers", "max_excursion_m", "MAX_SPEED_M_S", "MAX_VSPEED_M_S", "SLACK_M", "MAX_HDOP",
           "MIN_SATS", "WINDOW", "MAX_DT_S", "ORIGIN_TOL_M"]

MAX_SPEED_M_S = 60.0     # horizontal: racing quads and a quadplane's cruise (27.8 m/s in the VTOL log) stay below
MAX_VSPEED_M_S = 30.0    # vertical
SLACK_M = 15.0           # GPS noise and glitches a real receiver reports
MAX_HDOP = 10.0          # "poor" fixes (DOP > 10) are not positions to fly
MIN_SATS = 4             # a 3D fix needs four satellites
WINDOW = 9               # neighbours for the median: up to 4 corrupt fixes in a row are outvoted
MAX_DT_S = 5.0           # a gap longer than this (drop-out) allows no more motion than 5 s would
ALT_RANGE_M = (-500.0, 10000.0)
ORIGIN_TOL_M = 100.0     # estimator vs GPS altitude: baro drift and GPS vertical error stay well below


def max_excursion_m() -> tuple[float, float]:
    """(horizontal, vertical) metres an accepted fix can lie beyond its neighbours' median."""
    return SLACK_M + MAX_SPEED_M_S * MAX_DT_S, SLACK_M + MAX_VSPEED_M_S * MAX_DT_S


def _window_dt(t: np.ndarray) -> np.ndarray:
    """Longest time from each sample to another one in its centred window (capped at MAX_DT_S)."""
    h = WINDOW // 2
    lo = t[np.maximum(np.arange(len(t)) - h, 0)]
    hi = t[np.minimum(np.arange(len(t)) + h, len(t) - 1)]
    return np.minimum(np.maximum(t - lo, hi - t), MAX_DT_S)


def _jumps(t, e, n, u) -> np.ndarray:
    """Mask of fixes too far from the median of their neighbours (see the module docstring)."""
    med = pd.DataFrame({"e": e, "n": n, "u": u}).rolling(WINDOW, center=True, min_periods=1).median()
    dt = _window_dt(t)
    d_h = np.hypot(e - med["e"].to_numpy(), n - med["n"].to_numpy())
    d_v = np.abs(u - med["u"].to_numpy())
    return (d_h > SLACK_M + MAX_SPEED_M_S * dt) | (d_v > SLACK_M + MAX_VSPEED_M_S * dt)


def reject_outliers(pos: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, int]]:
    """``pos`` (t_s, lat_deg, lon_deg, alt_m, optional hdop, sats, gps_alt_m; sorted by t_s) without
    the implausible fixes, and the number rejected per reason."""
    counts = {"quality": 0, "origin": 0, "altitude": 0, "jump": 0}
    if not len(pos):
        return pos, counts
    bad = np.zeros(len(pos), dtype=bool)
    if "hdop" in pos:
        bad |= pos["hdop"].to_numpy(float) > MAX_HDOP           # nan (not logged) passes
    if "sats" in pos:
        bad |= pos["sats"].to_numpy(float) < MIN_SATS
    counts["quality"] = int(bad.sum())
    alt = pos["alt_m"].to_numpy(float)
    if "gps_alt_m" in pos:
        origin = ~bad & (np.abs(alt - pos["gps_alt_m"].to_numpy(float)) > ORIGIN_TOL_M)   # nan passes
        counts["origin"] = int(origin.sum())
        bad |= origin
    off = ~bad & ~((alt >= ALT_RANGE_M[0]) & (alt <= ALT_RANGE_M[1]))
    counts["altitude"] = int(off.sum())
    keep = pos[~(bad | off)]
    for _ in range(2):
        if len(keep) < 3:
            break
        ref = GeoPoint(float(np.clip(keep["lat_deg"].median(), -89.999, 89.999)), float(keep["lon_deg"].median()),
                       float(keep["alt_m"].median()))
        e, n, u = geodetic_to_enu(keep["lat_deg"].to_numpy(), keep["lon_deg"].to_numpy(), keep["alt_m"].to_numpy(), ref)
        jump = _jumps(keep["t_s"].to_numpy(float), e, n, u)
        counts["jump"] += int(jump.sum())
        keep = keep[~jump]
    return keep.reset_index(drop=True), counts
