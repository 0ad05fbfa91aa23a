"""The take-off spot of a flight log (:func:`default_pad`), the replay's default pad and the flown route's home.

Low level on purpose (it imports only the log's tables and geodesy, no world and no config): the replay
(:mod:`mission_sim.mavlink.replay`) and the flown route (:func:`mission_sim.plans.items.flown_mission`) both take it
from here, one source (the route importing it from the replay closed an import circle through the world).
"""

from __future__ import annotations

import numpy as np

from . import ground
from .flightlog import FlightLog, _no_position
from .geodesy import GeoPoint

__all__ = ["STARTS_AIRBORNE_M", "VALID_FLIGHT", "default_pad", "flown_periods",
           "starts_airborne_warning", "unknown_armed_state"]



def flown_periods(log: FlightLog) -> list[tuple[float, float]]:
    """The periods (log seconds) of ``log`` that count as flown, one rule for the flown route
    (:func:`mission_sim.plans.items.flown_mission`) and the replay: its armed periods when its armed state is known
    (``armed_source`` set; none for a log that never armed), else (no armed-state record and no motor output, the armed
    state unknown) its whole GPS track, first to last position (checked by :func:`unknown_armed_state`)."""
    if log.armed_source is not None:
        return list(log.armed_periods)
    t = log.position["t_s"].to_numpy(float)
    return [(float(t.min()), float(t.max()))] if len(t) else []


#: what a command that reads a log's flown track takes instead of a log on the ground (:func:`unknown_armed_state`)
VALID_FLIGHT = "the log of a flight"


def unknown_armed_state(name: str, top_m: float, above: str = "its first position", valid: str = VALID_FLIGHT) -> str:
    """For a log whose armed state is unknown (``armed_source`` None; :func:`flown_periods` is its whole track): the
    warning saying so, or ``ValueError`` when the track never rises :data:`~mission_sim.mavlink.ground.GROUND_M`
    above ``above`` (its
    highest point ``top_m``): a log on the ground (its GPS drift would fly as a 1 s route, or replay as a flight).
    ``valid``: what the command takes instead (``replay`` and ``calibrate``: the log of a flight; ``mission --plan
    LOG`` also a log holding an uploaded mission, which only it flies)."""
    what = "the armed state is unknown (no armed-state record and no motor output in the log)"
    if not top_m >= ground.GROUND_M:
        raise ValueError(f"{name}: no flown track: {what} and its GPS track never rises {ground.GROUND_M:g} m above "
                         f"{above} (max {top_m:.2f} m): a log on the ground; valid: {valid}")
    return (f"{name}: {what}: its whole GPS track counts as flown, time on the ground included (with armed-state "
            "records, HEARTBEAT / vehicle_status / EV, or motor outputs it is the armed time only)")

STARTS_AIRBORNE_M = 5.0   # a log that starts armed this much above where its first flight's disarm is started in the air
LANDED_GAP_S = 5.0        # the last position of the first armed period must be this close to its disarm (on the ground)


def _airborne_start(log: FlightLog):
    """(first armed position's index, the first armed period's last position's index, metres between them) when the
    log starts armed and its first armed position is more than :data:`STARTS_AIRBORNE_M` (beyond GPS height noise)
    above where that armed period ends in a disarm (on the ground: its last position, within :data:`LANDED_GAP_S` of
    the disarm): logging began in the air (a PX4 log of a flight already under way), so the first armed position is
    no take-off spot; else None.

    The end of the first flight, not its lowest point: PX4 logs start at arming, so many start armed on the ground,
    and a take-off from high ground that flies down into a valley went more than 5 m below its first position (the
    pad moved into the valley). A flight that took off from higher ground than it landed on also matches (the
    warning says so); a log that ends armed (no disarm: the end may be in the air) never does."""
    pos, periods, arm = log.position, log.armed_periods, log.armed
    if not (log.starts_armed and periods and len(pos) and len(arm)):
        return None
    t0, t1 = periods[0]
    arm_t, arm_on = arm["t_s"].to_numpy(float), arm["armed"].to_numpy(bool)
    if not np.any((arm_t == t1) & ~arm_on):   # the first armed period does not end in a disarm (the log ends armed)
        return None
    t = pos["t_s"].to_numpy(float)
    first = np.flatnonzero((t >= t0) & (t <= t1))
    if len(first) < 2 or t1 - t[first[-1]] > LANDED_GAP_S:
        return None
    alt = pos["alt_m"].to_numpy(float)
    drop = float(alt[first[0]] - alt[first[-1]])
    return (int(first[0]), int(first[-1]), drop) if drop > STARTS_AIRBORNE_M else None


def starts_airborne_warning(log: FlightLog) -> str | None:
    """The one warning (one source: ``replay`` / ``calibrate``'s :func:`mission_sim.mavlink.replay.replay_warnings` and
    ``mission --plan LOG``'s :func:`mission_sim.plans.items.flown_mission`) for a log whose take-off spot
    :func:`default_pad` moved to where its first flight ends (:func:`_airborne_start`); None when it did not."""
    start = _airborne_start(log)
    if start is None:
        return None
    t0, t1 = (float(log.position["t_s"].iloc[k]) for k in start[:2])
    return (f"{log.path.name}: the log starts armed {start[2]:.1f} m above where its first flight ends (its first "
            f"armed position at {t0:.1f} s against its last before the disarm, at {t1:.1f} s): logging began in the "
            "air, or the vehicle landed lower than it took off; heights are about that landing spot (replay's default "
            "pad, the flown route's home); replay takes --pad=LAT,LON,ALT for another, mission --plan LOG has no "
            "other home")


def default_pad(log: FlightLog) -> GeoPoint:
    """The first position at or after the first arming (the take-off spot), else the first position. A log that starts
    armed more than :data:`STARTS_AIRBORNE_M` above where its first armed period ends in a disarm
    (:func:`_airborne_start`: logging began in the air) takes that spot instead, the last position before the disarm
    (its landing), so that heights are above the ground it landed on, not above where logging began (its track was
    clipped to 0 there)."""
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
