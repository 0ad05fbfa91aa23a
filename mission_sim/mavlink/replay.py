"""Replay a real flight log through the mission world: log -> flown track about a pad -> run_mission.

Pipeline (each step a small function):

1. :func:`mission_sim.mavlink.logs.read_log` -- position (GPS fix >= 3), attitude, armed state and
   battery tables on the log's own timeline.
2. :func:`track_from_log` -- local ENU metres about the pad (default pad: the first armed
   position, :func:`default_pad`), tilt from roll and pitch, time from 0 at the first fix.
   Heights below the pad (GPS/baro noise on the ground) are clipped to 0; ``ground_gap_m`` is
   added so that z is the receiver coil's height above the pad coil (the gap when landed).
3. :func:`resample_track` onto ``sim.traj_dt_s``, then ``run_mission(cfg, policy,
   trajectory=replay_trajectory(...))`` -- Lm(t), SBAR, battery. Phases: "ground" while
   disarmed (the pad stays off and the drone draws its avionics power only), "hover" below
   0.3 m/s (the pad may energise), else "flight".
4. :func:`compare_power` -- the logged electrical power (V I of the flight battery) against the
   simulator's propulsion-power model while airborne, with the error; :func:`fit_mass_kg` --
   the drone mass at which the model's energy matches the log's.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from ..validation import window_ok
from ..world import budget as _budget
from . import ground
from .geodesy import GeoPoint, geodetic_to_enu
from .flightlog import (LogParseError, NoPositionError, _fmt_counts, _no_position,  # noqa: F401 (re-exported)
                        check_decoded)
from .logs import FlightLog, read_log
from .takeoff import (  # noqa: F401 (one source: takeoff.py)
    STARTS_AIRBORNE_M, _airborne_start, default_pad, flown_periods, starts_airborne_warning, unknown_armed_state)

__all__ = ["NoPositionError", "FlightTrack", "default_pad", "track_from_log", "with_ground_gap", "flight_stats",
           "logged_energy_j", "compare_power", "fit_mass_kg", "equivalent_mass_warning", "resample_track", "replay_trajectory", "ReplayResult", "replay_log", "parse_window",
           "battery_voltage_warning", "warn_battery_voltage", "replay_summary_warnings",
           "choose_segment", "replay_span"]


MAX_TILT_RAD = np.radians(85.0)   # the mission world takes |tilt| < 90 deg; beyond is upside down
HOVER_SPEED_M_S = 0.3             # slower than this counts as hovering (pads may energise)
MIN_DT_S = 0.05                   # closer position samples are dropped (velocity by differences)
_MAX_GAP_S = 10.0                 # samples further apart are not integrated across
_EDGE_S = 1e-3                    # a battery sample this close outside the track's ends is in it (float rounding)


@dataclass(frozen=True)
class FlightTrack:
    """The flown track: ``t_s`` (N,) from 0, ``pos_m`` (N, 3) ENU about the pad, ``tilt_rad`` (N,).

    ``t_offset_s`` is the log time of ``t_s = 0``; ``height_m`` the height above the pad before
    the ground gap was added (>= 0).
    """

    t_s: np.ndarray
    pos_m: np.ndarray
    tilt_rad: np.ndarray
    height_m: np.ndarray
    t_offset_s: float
    pad: GeoPoint
    ground_gap_m: float
    armed: np.ndarray           # (N,) bool, inside an armed period of the log
    n_tilt_clipped: int = 0     # samples whose tilt exceeded MAX_TILT_RAD (flips, crashes)

    def phase(self, hover_speed_m_s: float = HOVER_SPEED_M_S) -> np.ndarray:
        """Mission phases: "ground" while disarmed, else "hover" below ``hover_speed_m_s``, else "flight"."""
        speed = np.linalg.norm(np.gradient(self.pos_m, self.t_s, axis=0), axis=1)
        return np.where(~self.armed, "ground", np.where(speed < hover_speed_m_s, "hover", "flight")).astype(object)


def parse_window(text: str | None) -> tuple[float, float] | None:
    """``"T0,T1"`` (seconds of log time, T0 < T1) -> (t0, t1); ``ValueError`` naming the format."""
    if text is None:
        return None
    fmt = "T0,T1 in seconds from the start of the log with 0 <= T0 < T1, e.g. 450,600"
    try:
        t0, t1 = (float(p) for p in str(text).split(","))
    except ValueError:
        raise ValueError(f"--window {text!r} is invalid; valid format: {fmt}") from None
    if not window_ok(t0, t1):
        raise ValueError(f"--window {text!r} is invalid; valid format: {fmt}")
    return t0, t1


def choose_segment(log: FlightLog) -> int:
    """The boot segment (0-based) a replay flies when the log has several (reboots): the one with
    the most armed time, ties broken by the number of positions (a never-armed log: the segment
    with the most positions)."""
    def score(span):
        a, b = span
        armed = sum(max(0.0, min(e, b) - max(s, a)) for s, e in log.armed_periods)
        t = log.position["t_s"].to_numpy(float)
        return armed, int(np.sum((t >= a) & (t <= b)))
    spans = log.segments
    return max(range(len(spans)), key=lambda k: score(spans[k]))


#: a window may end this much after the log (s): a log's end rounded up (``--window 440,1378`` for a log that ends at
#: 1377.03 s) is not refused; what lies past it is no part of the replay either way
WINDOW_END_SLACK_S = 1.0


def log_end_s(log: FlightLog) -> float:
    """The end of ``log``'s time (s): its latest record, or its latest position if that is later."""
    pos = log.position
    return max(float(log.duration_s), float(pos["t_s"].max()) if len(pos) else 0.0)


def check_window(log: FlightLog, window: tuple[float, float] | None) -> tuple[float, float] | None:
    """``window`` (log seconds, or None), a one-line ``ValueError`` naming it and the log's time range unless
    0 <= T0 < T1 <= the log's end (:func:`log_end_s`) plus :data:`WINDOW_END_SLACK_S`, both finite (a window ending
    later was cut to the log without a word; from Python a NaN end, T0 >= T1 or T0 < 0 passed, only the end was
    checked). The bound it prints (the end plus the slack, to the ms) is the one it takes."""
    if window is not None:
        end = log_end_s(log)
        bound = round(end + WINDOW_END_SLACK_S, 3)   # (the bound printed is the one taken)
        valid = (f"valid: 0 <= T0 < T1 <= {bound:.3f} s of log time (its time range 0..{end:.3f} s; "
                 f"{WINDOW_END_SLACK_S:g} s allowed for a rounded end)")
        try:
            t0, t1 = (float(v) for v in window)
        except (TypeError, ValueError):
            raise ValueError(f"window={window!r} is invalid; {valid}") from None
        if not window_ok(t0, t1, bound):
            past = f": the log ends at {end:.3f} s" if t1 > bound else ""
            raise ValueError(f"--window {t0:g},{t1:g} is invalid{past}; {valid}")
    return window


def replay_span(log: FlightLog, window: tuple[float, float] | None = None,
                segment: int | None = None) -> tuple[tuple[float, float] | None, dict]:
    """The part of ``log`` a replay flies and what to report about it: ``window`` (log seconds) if
    given (checked by :func:`track_from_log`, which cuts the log to it: :func:`check_window`), else boot segment ``segment``
    (1-based; None: :func:`choose_segment` when the log has more than one; both given: ``ValueError``). Returns (window
    or None for the whole log, facts for the summary)."""
    spans = log.segments
    n = len(spans)
    info = {"segments": n, "clock": log.clock.source if log.clock is not None else "the log's own (vehicle) clock",
            "segment_clock": log.clock.describe() if log.clock is not None else []}
    if segment is not None and window is not None:   # was: the window won, the segment silently ignored
        raise ValueError(f"--segment {segment!r} and --window {window[0]:g},{window[1]:g} exclude each other (a window "
                         "is log seconds, across boot segments); valid: one of them")
    if segment is not None and not 1 <= segment <= n:
        raise ValueError(f"--segment {segment!r} is invalid; valid range: 1..{n} (the log has {n} boot segment(s))")
    if window is not None:
        return window, {**info, "replayed_segment": None}
    if segment is None and n == 1:
        return None, {**info, "replayed_segment": 1}
    k = choose_segment(log) if segment is None else segment - 1
    a, b = spans[k]
    return (float(a), float(b)), {**info, "replayed_segment": k + 1, "segment_span_s": [round(a, 3), round(b, 3)]}


def track_from_log(log: FlightLog, pad: GeoPoint | None = None, ground_gap_m: float = 0.0,
                   window: tuple[float, float] | None = None) -> FlightTrack:
    """The flown track about ``pad`` (None: :func:`default_pad`; a pad without altitude takes the
    default pad's altitude), optionally cut to ``window`` = (t0, t1) seconds of log time (:func:`check_window`: a window is
    checked wherever the log is cut to it, here, for replay, calibrate, refly and the studies; it took a window past
    the log's end)."""
    check_window(log, window)
    _check_ground_gap(ground_gap_m)
    pos = log.position
    if window is not None:
        pos = pos[(pos["t_s"] >= window[0]) & (pos["t_s"] <= window[1])]
    if len(pos) < 2:
        where = f" in the window {window[0]:g}..{window[1]:g} s" if window else ""
        raise _no_position(log, f"{where}: {len(pos)} usable position sample(s), need at least 2")
    if pad is None or pad.alt_m is None:
        d = default_pad(log)
        pad = d if pad is None else GeoPoint(pad.lat_deg, pad.lon_deg, d.alt_m)
    t_log = pos["t_s"].to_numpy(float)
    keep = _min_spacing(t_log, MIN_DT_S)
    pos, t_log = pos[keep], t_log[keep]
    e, n, u = geodetic_to_enu(pos["lat_deg"].to_numpy(), pos["lon_deg"].to_numpy(), pos["alt_m"].to_numpy(), pad)
    height = np.maximum(u, 0.0)
    tilt = np.zeros_like(t_log)
    att = log.attitude
    if len(att) >= 2:
        tilt_att = np.arccos(np.clip(np.cos(att["roll_rad"].to_numpy()) * np.cos(att["pitch_rad"].to_numpy()), -1, 1))
        tilt = np.interp(t_log, att["t_s"].to_numpy(float), tilt_att)
    clipped = int(np.sum(tilt > MAX_TILT_RAD))
    return FlightTrack(t_s=t_log - t_log[0], pos_m=np.column_stack([e, n, height + ground_gap_m]),
                       tilt_rad=np.minimum(tilt, MAX_TILT_RAD), height_m=height, t_offset_s=float(t_log[0]),
                       pad=pad, ground_gap_m=float(ground_gap_m), armed=_in_periods(t_log, flown_periods(log)),
                       n_tilt_clipped=clipped)


def _check_ground_gap(ground_gap_m) -> None:
    if not np.isfinite(ground_gap_m) or ground_gap_m < 0:
        raise ValueError(f"ground_gap_m={ground_gap_m!r} is invalid; valid range: [0, inf) m")


def with_ground_gap(track: FlightTrack, ground_gap_m: float) -> FlightTrack:
    """``track`` (from :func:`track_from_log`, not resampled) with another coil gap on the ground: its heights plus
    ``ground_gap_m``, bit for bit the track :func:`track_from_log` gives for that gap (the log is not read, nor its
    window checked, again)."""
    _check_ground_gap(ground_gap_m)
    pos = track.pos_m.copy()
    pos[:, 2] = track.height_m + ground_gap_m
    return replace(track, pos_m=pos, ground_gap_m=float(ground_gap_m))


#: trajectory samples a replay may hold: each costs a sample (world.budget.SAMPLE_BYTES) and a row of the time series
#: held whole (world.budget.ROW_MEMORY_BYTES) within world.budget.MAX_MEMORY_BYTES beside its FIXED_BYTES
#: (394,763 today: 21.9 h at 0.2 s)
MAX_REPLAY_SAMPLES = int((_budget.MAX_MEMORY_BYTES - _budget.FIXED_BYTES) // (_budget.SAMPLE_BYTES + _budget.ROW_MEMORY_BYTES))


def resample_track(track: FlightTrack, dt_s: float) -> FlightTrack:
    """The track on a uniform grid of ``dt_s`` (linear interpolation; armed state held).

    Logged fixes come every 0.2-0.4 s with gaps of seconds (radio drop-outs, reboots); the
    mission runner holds Lm and the propulsion power over each trajectory sample, so a uniform
    grid at the simulator's ``sim.traj_dt_s`` keeps every held interval short.
    """
    if not (np.isfinite(dt_s) and dt_s > 0):
        raise ValueError(f"dt_s={dt_s!r} is invalid; valid range: (0, inf) s")
    span = float(track.t_s[-1])
    if span / dt_s > MAX_REPLAY_SAMPLES:   # before allocating: a joined or mis-stamped log may span years
        raise ValueError(f"the replayed track spans {span:.6g} s ({span / 3600:.3g} h; from {track.t_offset_s:.6g} s "
                         f"of the log), more than the {MAX_REPLAY_SAMPLES * dt_s / 3600:.3g} h that fit in memory at "
                         f"sim.traj_dt_s={dt_s:g}; valid: a part of it, --window T0,T1 (or --segment N)")
    t = np.arange(0.0, span, dt_s)
    t = np.append(t[t < track.t_s[-1] - 1e-9], track.t_s[-1])
    pos = np.column_stack([np.interp(t, track.t_s, track.pos_m[:, i]) for i in range(3)])
    held = np.clip(np.searchsorted(track.t_s, t, side="right") - 1, 0, len(track.t_s) - 1)
    return FlightTrack(t_s=t, pos_m=pos, tilt_rad=np.interp(t, track.t_s, track.tilt_rad),
                       height_m=np.interp(t, track.t_s, track.height_m), t_offset_s=track.t_offset_s,
                       pad=track.pad, ground_gap_m=track.ground_gap_m, armed=track.armed[held],
                       n_tilt_clipped=track.n_tilt_clipped)


def _min_spacing(t, min_dt) -> np.ndarray:
    """Mask keeping samples at least ``min_dt`` after the previously kept one (t sorted)."""
    keep = np.zeros(len(t), dtype=bool)
    last = -np.inf
    for i, ti in enumerate(t):
        if ti - last >= min_dt:
            keep[i] = True
            last = ti
    return keep


def flight_stats(log: FlightLog, track: FlightTrack) -> dict:
    """Log and track facts for the summary (times in s, lengths in m). ``flown_time_s`` / ``flown_periods_s``: the
    time the replay counts as flown within the replayed track (it starts and ends at a GPS fix;
    :func:`~mission_sim.mavlink.takeoff.flown_periods`). ``armed_time_s`` / ``armed_periods_s``: the armed time within
    the replayed track, ``log_armed_time_s`` the whole log's (what the log says); when the log's armed state is
    known these are the flown ones, when it is unknown (``armed_source`` None) all three are None: the replay counts
    the whole track as flown, the log says nothing of arming (they gave the whole track as "armed" until 2026-11-28,
    and ``log_armed_time_s`` 0)."""
    seg = np.diff(track.pos_m, axis=0)
    t0, t1 = track.t_offset_s, track.t_offset_s + float(track.t_s[-1])
    periods = [(max(a, t0), min(b, t1)) for a, b in flown_periods(log) if b > t0 and a < t1]
    flown_s = float(sum(b - a for a, b in periods))
    shown = [[round(a, 3), round(b, 3)] for a, b in periods]
    known = log.armed_source is not None
    return {
        "duration_s": float(log.duration_s),
        "position_span_s": float(track.t_s[-1]),
        "distance_m": float(np.sum(np.linalg.norm(seg, axis=1))),
        "horizontal_distance_m": float(np.sum(np.linalg.norm(seg[:, :2], axis=1))),
        "max_alt_m": float(np.max(track.height_m)),
        "max_range_m": float(np.max(np.linalg.norm(track.pos_m[:, :2], axis=1))),
        "flown_time_s": flown_s,
        "flown_periods_s": shown,
        "armed_time_s": flown_s if known else None,
        "armed_periods_s": shown if known else None,
        "log_armed_time_s": float(log.armed_time_s) if known else None,
        "armed_source": log.armed_source,
        "starts_armed": bool(log.starts_armed),
        "gps_rejected": {k: int(v) for k, v in log.gps_rejected.items()},
        "parse_errors": list(log.errors),
        "n_position_samples": int(len(track.t_s)),
        "bad_frames": int(log.bad_frames),
        "reboots": int(log.reboots),
        "flown": bool(flown_s > 0),
        "tilt_clipped_samples": int(track.n_tilt_clipped),
        "pad": {"lat_deg": track.pad.lat_deg, "lon_deg": track.pad.lon_deg, "alt_m": track.pad.alt_m},
    }


def _in_periods(t, periods) -> np.ndarray:
    t = np.asarray(t, dtype=float)
    mask = np.zeros(t.shape, dtype=bool)
    for a, b in periods:
        mask |= (t >= a) & (t <= b)
    return mask


def logged_energy_j(battery: pd.DataFrame, t0: float = -np.inf, t1: float = np.inf, periods=None) -> float:
    """Trapezoid integral of the logged V I [J] over [t0, t1] (and only inside ``periods`` if given)."""
    b = battery[(battery["t_s"] >= t0) & (battery["t_s"] <= t1)]
    if len(b) < 2:
        return float("nan")
    t = b["t_s"].to_numpy(float)
    p = b["power_w"].to_numpy(float)
    dt = np.diff(t)
    seg = 0.5 * (p[1:] + p[:-1]) * dt
    if periods is not None:
        seg = seg[_in_periods(t[:-1], periods) & _in_periods(t[1:], periods)]
    return float(np.sum(seg))


def compare_power(log: FlightLog, track: FlightTrack, sim_t_s, propulsion_w) -> tuple[pd.DataFrame, dict]:
    """Logged electrical power vs the modelled propulsion power on the log's battery samples.

    The model is sampled at each battery record's time (linear interpolation of the simulator's
    time series, mapped back to log time with ``track.t_offset_s``). Compared while *airborne*:
    armed and more than :data:`~mission_sim.mavlink.ground.GROUND_M` above the pad (armed on the ground the motors idle,
    while the model, which knows no ground contact, gives hover power; disarmed the logged
    power is the avionics alone). Returns the per-sample table and a summary:

    logged / model mean power [W], mean error (model - logged) [W], RMS error [W], energies [J]
    and their relative error, the correlation, the best-fit scale ``k`` (least squares,
    k * model ~ logged) and the RMS error left after it (how well the *shape* is modelled).
    """
    bat = log.battery
    sim_t = np.asarray(sim_t_s, dtype=float) + track.t_offset_s
    model_w = np.asarray(propulsion_w, dtype=float)
    b = bat[(bat["t_s"] >= sim_t[0] - _EDGE_S) & (bat["t_s"] <= sim_t[-1] + _EDGE_S)]
    t = b["t_s"].to_numpy(float)
    height = np.interp(t, track.t_s + track.t_offset_s, track.height_m) if len(t) else np.zeros(0)
    armed = _in_periods(t, flown_periods(log))
    table = pd.DataFrame({"t_s": t, "logged_w": b["power_w"].to_numpy(float),
                          "voltage_v": b["voltage_v"].to_numpy(float), "current_a": b["current_a"].to_numpy(float),
                          "model_w": np.interp(t, sim_t, model_w) if len(t) else np.zeros(0),
                          "height_m": height, "armed": armed, "airborne": armed & (height > ground.GROUND_M)})
    table["error_w"] = table["model_w"] - table["logged_w"]
    a = table[table["airborne"]]
    out: dict = {"battery_source": log.battery_source, "n_samples_airborne": int(len(a)),
                 "airborne_time_s": _mask_time(t, table["airborne"].to_numpy())}
    if len(a) >= 2:
        ta, lw, mw = a["t_s"].to_numpy(), a["logged_w"].to_numpy(), a["model_w"].to_numpy()
        dt = np.diff(ta)
        inside = dt < _MAX_GAP_S  # do not bridge a landing between two airborne stretches
        e_log = float(np.sum((0.5 * (lw[1:] + lw[:-1]) * dt)[inside]))
        e_mod = float(np.sum((0.5 * (mw[1:] + mw[:-1]) * dt)[inside]))
        k = float(np.dot(mw, lw) / np.dot(mw, mw)) if np.dot(mw, mw) > 0 else float("nan")
        out.update({
            "logged_mean_w": float(lw.mean()), "model_mean_w": float(mw.mean()),
            "mean_error_w": float((mw - lw).mean()), "rms_error_w": float(np.sqrt(np.mean((mw - lw) ** 2))),
            "logged_energy_airborne_j": e_log, "model_energy_airborne_j": e_mod,
            "energy_error_rel": (e_mod - e_log) / e_log if e_log > 0 else float("nan"),
            "correlation": float(np.corrcoef(mw, lw)[0, 1]) if mw.std() > 0 and lw.std() > 0 else float("nan"),
            "best_fit_scale": k,
            "rms_error_after_scale_w": float(np.sqrt(np.mean((k * mw - lw) ** 2))) if np.isfinite(k) else float("nan"),
        })
    return table, out


def _mask_time(t, mask) -> float:
    """Seconds covered by consecutive samples that are both inside ``mask`` (gaps < _MAX_GAP_S)."""
    if len(t) < 2:
        return 0.0
    dt = np.diff(t)
    return float(np.sum(dt[mask[1:] & mask[:-1] & (dt < _MAX_GAP_S)]))


def fit_mass_kg(traj, drone, target_energy_j: float, t_s, mask, runner_energy_j: float | None = None) -> float:
    """Drone mass [kg] that makes the model's propulsion energy over ``mask`` equal ``target_energy_j``.

    ``traj`` is the replayed :class:`~mission_sim.world.trajectory.Trajectory`; ``t_s``, ``mask`` the
    comparison samples (trajectory time). Bisection on [0.05, 50] kg (energy rises with mass), whatever
    ``drone.max_takeoff_mass_kg`` (:func:`equivalent_mass_warning` says when the result is above it);
    nan if the target is outside that range. ``runner_energy_j``: the runner's modelled energy
    over the same samples at ``drone.mass_kg``; the target is scaled by the ratio of the
    trajectory's to the runner's energy there (the runner holds the power over its steps), so
    that a rerun at the fitted mass closes the energy. One number that says which drone the
    log's power would correspond to under the model.
    """
    from dataclasses import replace

    t_s = np.asarray(t_s, dtype=float)
    mask = np.asarray(mask, dtype=bool)
    if not np.isfinite(target_energy_j) or target_energy_j <= 0 or mask.sum() < 2:
        return float("nan")
    dt = np.diff(t_s)
    seg = mask[1:] & mask[:-1] & (dt < _MAX_GAP_S)

    def energy(m):   # trial masses with the take-off limit off: 50 kg is a bracket, not a drone the user gave
        p = np.interp(t_s, traj.t_s, traj.propulsion_w(replace(drone, mass_kg=m, max_takeoff_mass_kg=None)))
        return float(np.sum((0.5 * (p[1:] + p[:-1]) * dt)[seg]))

    if runner_energy_j is not None and np.isfinite(runner_energy_j) and runner_energy_j > 0:
        target_energy_j *= energy(drone.mass_kg) / runner_energy_j
    lo, hi = 0.05, 50.0
    if not energy(lo) <= target_energy_j <= energy(hi):
        return float("nan")
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if energy(mid) < target_energy_j else (lo, mid)
    return 0.5 * (lo + hi)


def equivalent_mass_warning(name: str, mass_kg: float, drone) -> str | None:
    """The one-line warning when the equivalent mass ``mass_kg`` (:func:`fit_mass_kg`) plus ``drone.payload_kg`` is
    above ``drone.max_takeoff_mass_kg`` (None when unset, below it or nan)."""
    from ..world.power import takeoff_excess
    head = takeoff_excess(f"{name}: the equivalent mass", float(mass_kg), drone.payload_kg, drone.max_takeoff_mass_kg,
                          fmt=".2f")
    if head is None:
        return None
    return (f"{head}: the model needs more than the airframe's maximum take-off mass to match the logged energy (the drone "
            "spends more than the config's drone would; check its figure_of_merit, drive_efficiency, avionics_w)")


def replay_trajectory(track: FlightTrack):
    """A :class:`~mission_sim.world.trajectory.Trajectory` of the track whose propulsion power is the
    avionics alone while disarmed ("ground": the motors are off), momentum theory otherwise."""
    from ..world.trajectory import Trajectory   # "ground" is one of its motors-off phases
    return Trajectory.from_samples(track.t_s, track.pos_m, tilt_rad=track.tilt_rad, phase=track.phase())


class _PowerColumns:
    """A run's sink keeping only ``t_s`` and ``propulsion_w`` (as the time series computes them) of its rows."""

    def __init__(self):
        self.t, self.p = [], []

    def __call__(self, loop, arr) -> None:
        c = {name: j for j, name in enumerate(loop.columns)}
        self.t.append(arr[:, c["t_s"]].copy())
        self.p.append(arr[:, c["e_propulsion_j"]] / arr[:, c["dt_s"]])

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return tuple(np.concatenate(x) if x else np.zeros(0) for x in (self.t, self.p))


@dataclass
class ReplayResult:
    """A replayed log: the log, its track, the mission result and the summary (JSON-ready)."""

    log: FlightLog
    track: FlightTrack
    mission: object                 # mission_sim.world.results.MissionResult
    summary: dict
    power_table: pd.DataFrame | None = None
    files: list[str] = field(default_factory=list)


FAR_PAD_M = 10_000.0  # a pad farther than this from the whole track is almost surely a wrong --pad
GAP_WARN_S = 10.0     # positions missing longer than this while armed: the replay invents a straight line


def unknown_armed_check(log: FlightLog, track: FlightTrack) -> str | None:
    """None when ``log``'s armed state is known; unknown (``armed_source`` None): the warning that its whole track
    counts as flown (:func:`flown_periods`, the rule of the flown route `mission --plan LOG`), or ``ValueError``
    when the replayed track never rises :data:`~mission_sim.mavlink.ground.GROUND_M` above the pad (its
    GPS drift on the ground was said "never armed ... NOT FLOWN"; the armed state is unknown, not "never armed")."""
    if log.armed_source is not None:
        return None
    above = "its first position" if track.pad == default_pad(log) else "the pad"
    return unknown_armed_state(log.path.name, float(np.max(track.height_m)), above)


def replay_warnings(log: FlightLog, track: FlightTrack) -> list[str]:
    """One-line warnings about a replay that runs but may not mean what the user thinks: a log that
    ends while the vehicle is still armed (a truncated log, or a crash), and a pad far from the
    whole track (a wrong ``--pad``, e.g. latitude and longitude swapped)."""
    out = []
    if len(log.armed) and bool(log.armed["armed"].to_numpy(bool)[-1]):
        out.append(f"{log.path.name}: the log ends while the vehicle is armed (at {log.duration_s:.1f} s): "
                   "truncated log? the replay covers only what was recorded")
    if log.errors:
        out.append(f"{log.path.name}: reading stopped early: {log.errors[0]}")
    airborne = starts_airborne_warning(log)
    if airborne is not None:
        out.append(airborne)
    if log.armed_source is None:   # the whole track counts as armed (flown_periods); replay refuses a ground log
        try:
            out.append(unknown_armed_check(log, track))
        except ValueError as e:   # (the studies and the re-flight list it)
            out.append(str(e))
    elif not np.any(track.armed):
        out.append(f"{log.path.name}: the vehicle never armed in the replayed part: the track is marked NOT FLOWN "
                   "(its distance and height are GPS drift on the ground; nothing here was a flight)")
    gaps = np.flatnonzero((np.diff(track.t_s) > GAP_WARN_S) & track.armed[:-1] & track.armed[1:])
    if len(gaps):
        i = int(gaps[np.argmax(np.diff(track.t_s)[gaps])])
        t0, t1 = track.t_offset_s + float(track.t_s[i]), track.t_offset_s + float(track.t_s[i + 1])
        out.append(f"{log.path.name}: no position for {t1 - t0:.1f} s while armed (log {t0:.1f}..{t1:.1f} s"
                   + (f"; {len(gaps)} such gaps" if len(gaps) > 1 else "") + "): the replay flies a straight line "
                   f"across it; to leave it out, replay the part before or after it: --window T0,{t0:.1f} or "
                   f"--window {t1:.1f},T1")
    dist = float(np.min(np.hypot(track.pos_m[:, 0], track.pos_m[:, 1])))
    if dist > FAR_PAD_M:
        out.append(f"the pad ({track.pad.lat_deg:.6f}, {track.pad.lon_deg:.6f}) is {dist / 1e3:.0f} km from the "
                   "nearest point of the track: the drone never comes near it (no charging); check --pad")
    return out


def battery_voltage_warning(log: FlightLog, battery, run: str = "replay") -> str | None:
    """One line when the log's battery voltage (the median of its positive samples) lies outside the model pack's
    open-circuit range ``n_series x [OCV(0), OCV(1)]`` (8S: 21.2-32.8 V): the ``run`` (the replay, the re-flight)
    flies the config's drone and pack, not the logged ones. Names the cell count whose OCV at SoC 0.5 is nearest the
    logged voltage and what modelling the logged drone takes: its pack and a link made for its voltage (the config's
    link was designed for the config's pack: on the config's link a 3S pack takes ~nothing from a pad). None when
    the log has no battery voltage or it fits."""
    from ..world.battery import ocv_cell_v

    if not len(log.battery) or "voltage_v" not in log.battery:
        return None
    v = log.battery["voltage_v"].to_numpy(float)
    v = v[np.isfinite(v) & (v > 0)]
    if not len(v):
        return None
    med, n = float(np.median(v)), battery.n_series
    lo, hi = n * float(ocv_cell_v(0.0)), n * float(ocv_cell_v(1.0))
    if lo <= med <= hi:
        return None
    fit = int(min(32, max(1, round(med / float(ocv_cell_v(0.5))))))
    return (f"{log.path.name}: the logged battery voltage (median {med:.1f} V) is outside the model pack's "
            f"open-circuit range {lo:.1f}-{hi:.1f} V (battery.n_series={n} x {lo / n:.3f}-{hi / n:.3f} V per cell); "
            f"it fits a {fit}-cell pack: the {run} flies the config's drone and pack, not the logged ones (a \"what "
            f"if our drone flew this route\" study); to model the logged drone give its pack (--set "
            f"battery.n_series={fit} and its battery.capacity_ah) and a link made for its voltage (link.*: the "
            f"config's is made for its {n}-cell pack)")


def warn_battery_voltage(log: FlightLog, battery, run: str = "replay") -> str | None:
    """:func:`battery_voltage_warning`, also raised (once) as a :class:`wpt_receiver.notices.DronewptWarning`."""
    text = battery_voltage_warning(log, battery, run)
    if text is not None:
        from wpt_receiver.notices import warn
        warn(text)
    return text


def replay_summary_warnings(log: FlightLog, track: FlightTrack, voltage: str | None,
                            mission_summary: dict | None = None, cfg=None) -> list[str]:
    """The replay summary's ``warnings``, the one list ``dronewpt replay`` (with or without ``--pads``) prints and the
    replay studies count (``n_warnings``): :func:`replay_warnings`, the logged voltage's (``voltage``:
    :func:`battery_voltage_warning`'s text or None), with the mission config ``cfg`` its pads more than 120 m above or
    below the replay's pad frame origin (:func:`~mission_sim.setup_warnings.far_pad_warnings`, as the run warns them)
    and, with the replay's ``mission_summary``, where the battery ran out (the power comparison stops there; the
    re-flight passes none: its two runs' depletion is in its summary's ``battery_depleted_*`` flags)."""
    out = replay_warnings(log, track) + [w for w in (voltage,) if w]
    if cfg is not None:
        from ..setup_warnings import REPLAY_ORIGIN, far_pad_warnings
        out += far_pad_warnings(cfg, REPLAY_ORIGIN)
    if mission_summary is not None and mission_summary.get("battery_depleted"):
        from ..world.results import depletion_text
        out.append(f"{depletion_text(mission_summary)} (the power comparison covers the flight up to that point)")
    return out


def replay_log(log, cfg, policy, *, pad: GeoPoint | None = None, ground_gap_m: float | None = None,
               window: tuple[float, float] | None = None, progress: bool = False,
               segment: int | None = None, frame: bool = True, warn: bool = True) -> ReplayResult:
    """Build the track of ``log`` (a :class:`FlightLog` or a path), run the mission world along it,
    compare the power.

    ``ground_gap_m`` None: ``cfg.mission.hover_gap_m`` (the nominal gap), i.e. landed on the pad
    the receiver coil sits at its nominal height above the pad coil. A log with reboots replays one
    boot segment (:func:`replay_span`; ``segment`` 1-based, None: the one with the most armed
    time) unless ``window`` is given; the summary names it (``replayed_segment``).
    ``frame=False``: summary only (``mission.timeseries`` is None; the power comparison reads the two
    columns it needs from the rows as they are produced, the same numbers).
    ``warn``: the setup warnings (:func:`~mission_sim.world.runner.run_mission`'s and the logged battery voltage's,
    :func:`battery_voltage_warning`) as ``DronewptWarning`` before the run; they are in the summary's ``warnings``
    either way.
    Raises :class:`NoPositionError` (a ``ValueError``) if the log has no usable position.
    """
    from ..world.runner import run_mission

    if not isinstance(log, FlightLog):
        log = read_log(log)
    if ground_gap_m is None:
        ground_gap_m = cfg.mission.hover_gap_m
    window, span_info = replay_span(log, window, segment)
    track = track_from_log(log, pad=pad, ground_gap_m=ground_gap_m, window=window)
    unknown_armed_check(log, track)   # the armed state unknown and the track on the ground: ValueError
    grid = resample_track(track, cfg.sim.traj_dt_s)
    traj = replay_trajectory(grid)
    cols = _PowerColumns()
    voltage = (warn_battery_voltage if warn else battery_voltage_warning)(log, cfg.battery)
    mission = run_mission(cfg, policy, trajectory=traj, progress=progress, frame=frame, sink=None if frame else cols,
                          warn=warn)
    ts = mission.timeseries
    sim_t, sim_p = (ts["t_s"].to_numpy(), ts["propulsion_w"].to_numpy()) if frame else cols.arrays()
    summary = flight_stats(log, track)
    summary.update(span_info)
    ms = mission.summary
    summary.update({
        "rectifier_output_j": float(ms["rectifier_output_j"]),
        "battery_charge_in_j": float(ms["battery_charge_in_j"]),
        "propulsion_energy_j": float(ms["propulsion_energy_j"]),
        "energy_from_source_j": float(ms["energy_from_source_j"]),
        "final_soc": float(ms["final_soc"]),
        "min_soc": float(ms["min_soc"]),
        "battery_depleted": bool(ms["battery_depleted"]),
        "depleted_at_s": ms["depleted_at_s"],
        "peak_i2_a": float(ms["peak_i2_a"]),
        "sim_time_s": float(ms["sim_time_s"]),
        "window_s": list(window) if window else None,
        "battery_source": log.battery_source,
        "warnings": replay_summary_warnings(log, track, voltage, ms, cfg),
    })
    table = None
    if len(log.battery):
        t0, t1 = track.t_offset_s, track.t_offset_s + float(track.t_s[-1])
        summary["logged_energy_j"] = logged_energy_j(log.battery, t0 - _EDGE_S, t1 + _EDGE_S)
        table, cmp = compare_power(log, track, sim_t, sim_p)
        air = table["airborne"].to_numpy()
        cmp["drone_mass_kg"] = float(cfg.drone.mass_kg)
        cmp["equivalent_mass_kg"] = fit_mass_kg(traj, cfg.drone, cmp.get("logged_energy_airborne_j", np.nan),
                                                table["t_s"].to_numpy() - track.t_offset_s, air,
                                                cmp.get("model_energy_airborne_j"))
        heavy = equivalent_mass_warning(log.path.name, cmp["equivalent_mass_kg"], cfg.drone)
        if heavy is not None:
            summary["warnings"].append(heavy)
        summary["power_comparison"] = cmp
    return ReplayResult(log=log, track=track, mission=mission, summary=summary, power_table=table)
