"""What-if re-flight of a logged flight with charging pads added (``dronewpt replay LOG --pads FILE``).

The logged track (:mod:`mission_sim.mavlink.replay`: ENU about the take-off spot, resampled on
``sim.traj_dt_s``) is flown again with one detour per pad, inserted where the airborne track
passes horizontally closest to it (pads farther than ``reach_m`` from the track are left out):
fly to above the pad at the current height, descend to the charging gap, charge for the pad's
``hover_time_s`` (default ``mission.hover_time_s``), climb back, return to the track and go on
(the rest of the log shifted in time). The detour legs use the mission planner's rest-to-rest
trapezoidal profiles (:class:`mission_sim.world.trajectory._Path`). Then:

* the re-flight with the pads on and off (:func:`~mission_sim.world.runner.run_mission`), and
* the logged flight as flown, pads off,

so the summary reports the flight time the pads buy against the logged flight (usable battery
energy left over the hover power, :func:`~mission_sim.world.runner.flight_time_gain_s`), the same
against the re-flight without charging (what the charging alone gives, the detours' cost taken
out), the energy into the battery and the detours' time and propulsion energy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..mavlink import ground

__all__ = ["Detour", "plan_detours", "refly_track", "ReflyResult", "refly_base", "plan_refly", "refly_log",
           "DEFAULT_REACH_M", "check_refly_size"]

DEFAULT_REACH_M = 500.0   # a pad farther than this (horizontally) from the airborne track is not visited


@dataclass(frozen=True)
class Detour:
    """One pad visit: pad index, the track sample it leaves from, its distance [m], hover [s]."""

    pad: int
    sample: int
    distance_m: float
    hover_s: float


def plan_detours(track, pads_xyz: np.ndarray, hover_s, reach_m: float = DEFAULT_REACH_M):
    """Detours (sorted by track sample) and the skipped pads as (index, distance_m): each pad is
    visited from the airborne, armed sample horizontally closest to it, if within ``reach_m``."""
    air = np.flatnonzero(track.armed & (track.height_m > ground.GROUND_M))   # (airborne: as the replay's)
    if len(air) == 0:
        return [], [(k, math.inf) for k in range(len(pads_xyz))]
    out, skipped = [], []
    for k, p in enumerate(np.asarray(pads_xyz, dtype=float)):
        d = np.hypot(track.pos_m[air, 0] - p[0], track.pos_m[air, 1] - p[1])
        j = int(np.argmin(d))
        if d[j] <= reach_m:
            out.append(Detour(k, int(air[j]), float(d[j]), float(hover_s[k])))
        else:
            skipped.append((k, float(d[j])))
    return sorted(out, key=lambda dt: (dt.sample, dt.pad)), skipped


def _sample(segs, t0: float, dt: float):
    """Sample planner segments on a grid of ``dt`` from one step after ``t0`` to their end: (t, pos, phase)."""
    ends = np.cumsum([sg[3] for sg in segs])
    n = max(1, int(math.ceil(ends[-1] / dt)))
    tau = np.minimum(np.arange(1, n + 1) * dt, ends[-1])
    which = np.minimum(np.searchsorted(ends, tau, side="left"), len(segs) - 1)
    pos = np.empty((n, 3))
    phase = np.empty(n, dtype=object)
    for k, (ph, p0, u, dur, ev) in enumerate(segs):
        m = which == k
        pos[m] = p0 if ev is None else p0 + ev(tau[m] - (ends[k] - dur))[0][:, None] * u
        phase[m] = ph
    return t0 + tau, pos, phase


def _detour_segs(track, pads_xyz, d: Detour, mission) -> list:
    """The planner segments of detour ``d``: to above the pad, down to the charging gap, the hover, up, back."""
    from ..world.trajectory import _Path
    p0 = track.pos_m[d.sample]
    pad = pads_xyz[d.pad]
    path = _Path(mission, p0)
    path.move([pad[0], pad[1], p0[2]], "transit")
    path.move([pad[0], pad[1], pad[2] + mission.hover_gap_m], "approach")
    path.hold(d.hover_s, "charge")
    path.move([pad[0], pad[1], p0[2]], "depart")
    path.move(p0, "transit")
    return path.segs


def refly_track(track, pads_xyz, detours, mission, dt_s: float):
    """The re-flown track (a copy of ``track`` with the detours) and the phase per sample
    ("approach" / "charge" / "depart" / "transit" on the detours, None on logged samples)."""
    cuts = [0] + [d.sample + 1 for d in detours] + [len(track.t_s)]
    t, pos, tilt, height, armed, phase = [], [], [], [], [], []
    shift = 0.0
    for i, d in enumerate([None] + list(detours)):
        if d is not None:
            tt, pp, ph = _sample(_detour_segs(track, pads_xyz, d, mission), float(track.t_s[d.sample]) + shift, dt_s)
            shift = tt[-1] - float(track.t_s[d.sample])
            t.append(tt), pos.append(pp), phase.append(ph), tilt.append(np.zeros(len(tt)))
            height.append(np.maximum(pp[:, 2] - track.ground_gap_m, 0.0)), armed.append(np.ones(len(tt), bool))
        sl = slice(cuts[i], cuts[i + 1])
        t.append(track.t_s[sl] + shift), pos.append(track.pos_m[sl]), tilt.append(track.tilt_rad[sl])
        height.append(track.height_m[sl]), armed.append(track.armed[sl])
        phase.append(np.full(cuts[i + 1] - cuts[i], None, dtype=object))
    new = replace(track, t_s=np.concatenate(t), pos_m=np.concatenate(pos), tilt_rad=np.concatenate(tilt),
                  height_m=np.concatenate(height), armed=np.concatenate(armed))
    return new, np.concatenate(phase)


def _gain_s(cfg, s: dict, o: dict, detour_s: float) -> float:
    """Flight time [s] the pads buy against the logged flight: the usable battery energy left over
    the hover power; a depleted run ends early, so the difference of the times flown along the
    logged route (the re-flight's minus its detours) is added then."""
    from ..world.runner import flight_time_gain_s
    gain = flight_time_gain_s(cfg, s["final_soc"], o["final_soc"])
    if s["battery_depleted"] or o["battery_depleted"]:
        gain += (s["sim_time_s"] - detour_s) - o["sim_time_s"]
    return float(gain)


@dataclass
class ReflyResult:
    """The logged flight as flown (pads off), its re-flight with the pads, the summary (JSON-ready)."""

    original: object      # MissionResult of the logged track, pads off
    refly: object         # MissionResult of the re-flight, pads on (its summary has the pads-off run's SoC)
    track: object         # FlightTrack of the logged flight (resampled)
    refly_track: object   # FlightTrack of the re-flight
    pads_xyz: np.ndarray
    detours: list
    summary: dict


def _trajectory(track, phase=None):
    from ..mavlink.replay import replay_trajectory
    traj = replay_trajectory(track)
    if phase is not None:
        mark = np.array([p is not None for p in phase])
        traj.phase[mark] = phase[mark]
    return traj


def refly_base(base: dict, pads, origin, pads_name: str = "pads") -> dict:
    """The re-flight's mission dict (not yet validated; lay ``--set`` overrides over it, then
    :func:`~mission_sim.config.config_from_dict`): ``base`` (``config_to_dict`` of the ``--config``
    mission) without its route (the log is the route) and with the pads ``pads``
    (:class:`~mission_sim.plans.pads.GeoPad` records, ``read_pads``) about the replay's frame origin
    ``origin`` (the take-off spot, or ``--pad``). ``dronewpt replay --pads`` and the replay studies of
    ``dronewpt sweep`` both build their missions here."""
    import copy

    from .pads import check_distinct
    from .route import pads_to_local
    check_distinct(pads, pads_name)           # (a pad listed twice: a detour to each copy, charged twice)
    d = copy.deepcopy(base)
    d["waypoints"] = []                       # the log is the route
    d["mission"]["file"] = ""
    d["pads"] = pads_to_local(pads, origin, pads_name, "the replay's pad frame origin (the take-off spot, or --pad)")
    # the cruise altitude is the built-in pattern's, which a re-flight never flies (its detours climb from the log's
    # track): above every pad, as a route's pads are exempt (a pad on a 30 m roof was refused for
    # mission.cruise_altitude_m=5, a key replay refuses to --set); the hover gap's top (1 m) so --set of it passes
    from ..validation import CRUISE_ALTITUDE_RANGE, HOVER_GAP_RANGE
    top = max((p["z_m"] for p in d["pads"]), default=-math.inf) + HOVER_GAP_RANGE.hi + 1.0
    if top >= d["mission"]["cruise_altitude_m"]:
        d["mission"]["cruise_altitude_m"] = min(top, CRUISE_ALTITUDE_RANGE.hi)
    return d


def _segment_window(log, window, segment):
    """``window``, or boot segment ``segment``'s span (1-based) when one is asked for and no window is
    given; without either the whole log is re-flown (a log with reboots included). (The window is checked by
    ``track_from_log``.)"""
    from ..mavlink.replay import replay_span
    return window if segment is None else replay_span(log, window, segment)[0]


def plan_refly(log, cfg, *, pad=None, ground_gap_m=None, window=None, reach_m: float = DEFAULT_REACH_M,
               segment: int | None = None, track=None):
    """The logged track (resampled), the pads (K, 3) of ``cfg``, the detours and the skipped pads;
    ``ValueError`` (one line) if no pad is within ``reach_m`` of the airborne track, or ``segment``
    (1-based boot segment, re-flown alone when no ``window`` is given) is out of range. ``track``: the logged track
    the caller has already (``track_from_log`` of this log about ``pad`` over this window or segment, any ground gap,
    not resampled), laid at the re-flight's gap (:func:`~mission_sim.mavlink.replay.with_ground_gap`) instead of made
    again."""
    from ..mavlink.replay import resample_track, track_from_log, with_ground_gap
    gap = cfg.mission.hover_gap_m if ground_gap_m is None else ground_gap_m
    window = _segment_window(log, window, segment)
    track = track_from_log(log, pad=pad, ground_gap_m=gap, window=window) if track is None else \
        with_ground_gap(track, gap)
    track = resample_track(track, cfg.sim.traj_dt_s)
    pads_xyz = np.array([[p.x_m, p.y_m, p.z_m] for p in cfg.pads])
    detours, skipped = plan_detours(track, pads_xyz, _hovers(cfg), reach_m)
    if not detours and all(math.isinf(d) for _, d in skipped):   # (was: "pad 0 at inf m", as if the pads were far)
        where = "the log" if window is None else f"the window {window[0]:g}..{window[1]:g} s"
        if segment is not None:
            where = f"boot segment {segment} ({where[4:]})"
        raise ValueError(f"{log.path.name}: the vehicle is not airborne (armed and more than {ground.GROUND_M:g} m above "
                         f"the take-off spot) anywhere in {where}, so there is no track to make a detour from; valid: "
                         "a --window or --segment in which it flew")
    if not detours:
        far = ", ".join(f"pad {k} at {d:.0f} m" for k, d in skipped)
        raise ValueError(f"{log.path.name}: no pad within --reach {reach_m:g} m of the airborne track ({far}); "
                         "valid: pads near where the vehicle flew (pad frame: ENU about the take-off spot)")
    check_refly_size(track, pads_xyz, detours, cfg)
    return track, pads_xyz, detours, skipped


def _hovers(cfg) -> list:
    """Each pad's charging hover [s]: its own ``hover_time_s``, else ``mission.hover_time_s``."""
    return [cfg.mission.hover_time_s if p.hover_time_s is None else p.hover_time_s for p in cfg.pads]


def check_refly_size(track, pads_xyz, detours, cfg) -> None:
    """``ValueError`` (one line naming the longest hover's key, its value and the valid range) when the re-flight
    (the logged samples plus the detours' at ``sim.traj_dt_s``, their hovers as ``cfg`` sets them) holds more
    samples than a replay may (:data:`~mission_sim.mavlink.replay.MAX_REPLAY_SAMPLES`, the limit of the logged track
    alone): a charging hover of days would run for minutes and take gigabytes before anything checked it.
    :func:`plan_refly` calls it; the replay studies call it per case on a plan they keep."""
    from ..mavlink.replay import MAX_REPLAY_SAMPLES
    hover = _hovers(cfg)
    detours = [replace(d, hover_s=float(hover[d.pad])) for d in detours]
    dt = cfg.sim.traj_dt_s
    durs = [sum(sg[3] for sg in _detour_segs(track, pads_xyz, d, cfg.mission)) for d in detours]
    n = len(track.t_s) + sum(max(1, math.ceil(t / dt)) for t in durs)
    if n <= MAX_REPLAY_SAMPLES:
        return
    d = max(detours, key=lambda dt_: (dt_.hover_s, -dt_.pad))
    key = "mission.hover_time_s" if cfg.pads[d.pad].hover_time_s is None else f"pads.{d.pad}.hover_time_s"
    shared = sum(1 for x in detours if cfg.pads[x.pad].hover_time_s is None) if key.startswith("mission.") else 1
    room = max(0.0, d.hover_s - (n - MAX_REPLAY_SAMPLES + len(detours)) * dt / shared)
    raise ValueError(f"{key}={d.hover_s:g} is invalid: the re-flight would hold {n} samples at sim.traj_dt_s={dt:g} "
                     f"(the logged {float(track.t_s[-1]):.0f} s + {sum(durs):.0f} s of pad detours, "
                     f"{sum(x.hover_s for x in detours):.0f} s of them charging), more than the {MAX_REPLAY_SAMPLES} "
                     f"that fit in memory; valid range: [0, {room:.6g}] s (the other hovers as they are)")


def refly_log(log, cfg, policy, *, pad=None, ground_gap_m=None, window=None, reach_m: float = DEFAULT_REACH_M,
              progress: bool = False, segment: int | None = None, frame: bool = True,
              warn: bool = True, plan=None) -> ReflyResult:
    """Re-fly ``log`` (a FlightLog) with the pads of ``cfg`` (pad frame = ENU about ``pad``, default
    the take-off spot, as in :func:`~mission_sim.mavlink.replay.replay_log`) and compare; see the
    module docstring and :func:`plan_refly` (its errors). ``frame=False``: summary only (the runs keep
    no time series; the summary is the same, see :func:`~mission_sim.world.runner.run_mission`). ``warn``: the setup
    warnings as ``DronewptWarning`` before the runs (as :func:`~mission_sim.mavlink.replay.replay_log`); the summary's
    ``warnings`` has the replay's (:func:`~mission_sim.mavlink.replay.replay_summary_warnings`: the log's, the logged
    voltage's and a pad far above or below the pad frame origin). ``plan``: :func:`plan_refly`'s result for the same
    arguments, when the caller has it (the command line plans first, for its errors), else planned here."""
    from ..mavlink.replay import battery_voltage_warning, replay_summary_warnings, warn_battery_voltage
    from ..world.runner import run_mission
    track, pads_xyz, detours, skipped = plan or plan_refly(log, cfg, pad=pad, ground_gap_m=ground_gap_m,
                                                           window=window, reach_m=reach_m, segment=segment)
    new, phase = refly_track(track, pads_xyz, detours, cfg.mission, cfg.sim.traj_dt_s)
    voltage = (warn_battery_voltage if warn else battery_voltage_warning)(log, cfg.battery, "re-flight")
    original = run_mission(cfg, policy, trajectory=_trajectory(track), charge=False, progress=progress, frame=frame,
                           warn=warn)
    refly = run_mission(cfg, policy, trajectory=_trajectory(new, phase), progress=progress, frame=frame, warn=warn)
    s, o = refly.summary, original.summary
    summary = {
        "log": str(log.path), "pad_frame_origin": {"lat_deg": track.pad.lat_deg, "lon_deg": track.pad.lon_deg,
                                                   "alt_m": track.pad.alt_m},
        "pads": [{"x_m": float(p[0]), "y_m": float(p[1]), "z_m": float(p[2])} for p in pads_xyz],
        "detours": [{"pad": d.pad, "from_log_t_s": float(track.t_s[d.sample] + track.t_offset_s), "distance_m": d.distance_m,
                     "hover_s": d.hover_s} for d in detours],
        "skipped_pads": [{"pad": k, "distance_m": d} for k, d in skipped],
        "logged_flight_time_s": float(o["sim_time_s"]), "refly_time_s": float(s["sim_time_s"]),
        "detour_time_s": float(new.t_s[-1] - track.t_s[-1]),
        "detour_propulsion_j": float(s.get("propulsion_energy_j", 0.0) - o["propulsion_energy_j"]),
        "energy_from_pads_j": float(s["energy_from_source_j"]), "rectifier_output_j": float(s["rectifier_output_j"]),
        "battery_charge_in_j": float(s["battery_charge_in_j"]), "charge_time_s": float(s["charge_time_s"]),
        "final_soc_logged_flight": float(o["final_soc"]), "final_soc_refly": float(s["final_soc"]),
        "final_soc_refly_without_charging": float(s["final_soc_without_charging"]),
        "min_soc_logged_flight": float(o["min_soc"]), "min_soc_refly": float(s["min_soc"]),
        "peak_i2_a": float(s["peak_i2_a"]), "peak_i2_envelope_a": float(s["peak_i2_envelope_a"]),
        "rated_i2_a": float(s["rated_i2_a"]),
        "time_above_rated_s": float(s["time_above_rated_s"]),
        "flight_time_gain_s": _gain_s(cfg, s, o, float(new.t_s[-1] - track.t_s[-1])),
        "flight_time_gain_vs_refly_without_charging_s": float(s["flight_time_gain_s"]),
        "net_battery_energy_gain_j": float(cfg.battery.usable_energy_j(s["final_soc"])
                                           - cfg.battery.usable_energy_j(o["final_soc"])),
        "battery_depleted_logged_flight": bool(o["battery_depleted"]), "battery_depleted_refly": bool(s["battery_depleted"]),
        "warnings": replay_summary_warnings(log, track, voltage, cfg=cfg),
    }
    return ReflyResult(original, refly, track, new, pads_xyz, detours, summary)
