"""The take-off spot of a flight log (:func:`default_pad`), the replay's default pad and the flown route's home.

Low level on purpose (it imports only the log's tables and geodesy, no world and no config): the replay
(:mod:`mission_sim.mavlink.replay`) and the flown route (:func:`mission_sim.plans.items.flown_mission`) both take it
from here, one source (the route importing it from the replay closed an import circle through the world).
"""

from __future__ import annotations

import numpy as np

from .flightlog import FlightLog, _no_position
from .geodesy import GeoPoint

__all__ = ["STARTS_AIRBORNE_M", "default_pad"]

STARTS_AIRBORNE_M = 5.0   # a log that starts armed and goes this much lower in its first flight started in the air


def _airborne_start(log: FlightLog):
    """(first armed position's index, lowest position's index in the first armed period, metres between them) when
    the log starts armed and its first flight goes more than :data:`STARTS_AIRBORNE_M` (beyond GPS height noise) below
    its first position: logging began in the air (a PX4 log of a flight already under way), so the first armed
    position is no take-off spot; else None."""
    pos, periods = log.position, log.armed_periods
    if not (log.starts_armed and periods and len(pos)):
        return None
    t = pos["t_s"].to_numpy()
    first = np.flatnonzero((t >= periods[0][0]) & (t <= periods[0][1]))
    if len(first) < 2:
        return None
    alt = pos["alt_m"].to_numpy(float)[first]
    k = int(np.argmin(alt))
    drop = float(alt[0] - alt[k])
    return (int(first[0]), int(first[k]), drop) if drop > STARTS_AIRBORNE_M else None


def default_pad(log: FlightLog) -> GeoPoint:
    """The first position at or after the first arming (the take-off spot), else the first position. A log that starts
    armed in the air (:func:`_airborne_start`: its first flight goes more than :data:`STARTS_AIRBORNE_M` below its
    first position) has no take-off spot: the lowest position of that flight (its landing) is taken instead, so that
    heights are above the ground it landed on, not above where logging began (its track was clipped to 0 there)."""
    pos = log.position
    if len(pos) == 0:
        raise _no_position(log, " in the log" if not log.errors else "")
    i = 0
    periods = log.armed_periods
    if periods:
        after = np.flatnonzero(pos["t_s"].to_numpy() >= periods[0][0])
        i = int(after[0]) if len(after) else len(pos) - 1
    start = _airborne_start(log)
    if start is not None:
        i = start[1]
    row = pos.iloc[i]
    return GeoPoint(float(row.lat_deg), float(row.lon_deg), float(row.alt_m))
