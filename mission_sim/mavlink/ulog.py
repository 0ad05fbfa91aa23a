"""PX4 ULog (.ulg) files into the same :class:`~mission_sim.mavlink.flightlog.FlightLog` tables as
the ArduPilot logs, with pyulog.

===========  ==============================================================================
table        topics (the first that the log holds; multi-instance topics: instance 0)
===========  ==============================================================================
position     vehicle_global_position (lat, lon [deg], alt [m AMSL]); else vehicle_local_position
             with a global reference (xy_global, z_global: ref_lat/ref_lon/ref_alt + x north,
             y east, z down [m]); else vehicle_gps_position (lat/lon 1e-7 deg, alt mm) or
             sensor_gps (latitude_deg, longitude_deg, altitude_msl_m), fix_type >= 3 with hdop
             and satellites_used for the outlier filter (gpsclean.py)
attitude     vehicle_attitude quaternion q[0..3] (w, x, y, z) -> roll, pitch [rad]
armed        vehicle_status.arming_state (2 = ARMED), else actuator_armed.armed, else
             actuator_outputs (motor PWM, armed.py)
battery      battery_status voltage_v [V], current_a [A, + = discharging]; current_a = -1 is PX4's
             "unknown" (battery_status.msg; PX4's simulated battery), as SYS_STATUS's -1: not a charge
===========  ==============================================================================

Time: ``t_s`` = (timestamp - the log's start timestamp) [s]. The logger writes the current
value of each topic when logging starts, with the time it was published; such samples (before the
start) are placed at 0, so a log that starts armed is armed from 0. The duration is the last good
sample minus the start, judged on the time-sorted samples by the rule of the MAVLink logs
(:func:`~mission_sim.mavlink.flightlog.good_timestamps`): a stray timestamp, e.g. the sample
log's one ``mission`` sample at 1174 s while everything else ends at 6.5 s, is left out of every
table and counted in ``bad_frames``. Epoch time comes from the GPS (time_utc_usec) when present.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pandas as pd

from .armed import infer_armed, starts_armed
from .flightlog import (ARMED_COLUMNS, ATTITUDE_COLUMNS, BATTERY_COLUMNS, POSITION_COLUMNS, FlightLog,
                        clean_time, good_timestamps)
from .geodesy import GeoPoint, enu_to_geodetic
from .gpsclean import reject_outliers

__all__ = ["read_ulog"]

_ARMING_STATE_ARMED = 2
_CURRENT_UNKNOWN_A = -1.0   # battery_status.current_a: "-1 if unknown" (PX4's battery_status.msg)


class _Topics:
    """Topic data of one ULog as DataFrames with ``t_s`` from the log start (instance 0); samples
    beyond the timeline's end (stray timestamps, see the module docstring) are left out."""

    def __init__(self, ulog):
        self.start = int(ulog.start_timestamp)
        self.data = {d.name: d.data for d in sorted(ulog.data_list, key=lambda d: d.multi_id, reverse=True)}
        every = [(d.data["timestamp"].astype(np.int64) - self.start) * 1e-6 for d in ulog.data_list]
        every = np.sort(np.maximum(np.concatenate(every), 0.0)) if every else np.zeros(0)
        good = good_timestamps(every)  # the rule of the MAVLink logs, on the time-sorted samples
        self.duration_s = float(every[good].max()) if good.any() else 0.0
        self.n_records = int(len(every))
        self.n_stray = int(np.sum(~good))

    def __call__(self, name: str, *fields: str) -> pd.DataFrame | None:
        d = self.data.get(name)
        if d is None or not len(d["timestamp"]) or any(f not in d for f in fields):
            return None
        t = (d["timestamp"].astype(np.int64) - self.start) * 1e-6
        keep = t <= self.duration_s
        if not keep.any():
            return None
        return pd.DataFrame({"t_s": np.maximum(t[keep], 0.0),
                             **{f: np.asarray(d[f], dtype=float)[keep] for f in fields}})


def _global_position(top: _Topics) -> pd.DataFrame | None:
    g = top("vehicle_global_position", "lat", "lon", "alt")
    if g is not None:
        return g.rename(columns={"lat": "lat_deg", "lon": "lon_deg", "alt": "alt_m"})
    lp = top("vehicle_local_position", "x", "y", "z", "ref_lat", "ref_lon", "ref_alt", "xy_global", "z_global")
    if lp is None:
        return None
    lp = lp[(lp["xy_global"] > 0) & (lp["z_global"] > 0)]
    if not len(lp):
        return None
    ref = GeoPoint(float(lp["ref_lat"].iloc[0]), float(lp["ref_lon"].iloc[0]), float(lp["ref_alt"].iloc[0]))
    lat, lon, alt = enu_to_geodetic(lp["y"].to_numpy(), lp["x"].to_numpy(), -lp["z"].to_numpy(), ref)
    return pd.DataFrame({"t_s": lp["t_s"].to_numpy(), "lat_deg": lat, "lon_deg": lon, "alt_m": alt})


def _gps_position(top: _Topics) -> pd.DataFrame | None:
    for name in ("vehicle_gps_position", "sensor_gps"):
        g = top(name, "lat", "lon", "alt", "fix_type", "hdop", "satellites_used")
        if g is not None:
            g = g.assign(lat_deg=g["lat"] * 1e-7, lon_deg=g["lon"] * 1e-7, alt_m=g["alt"] * 1e-3)
        else:
            g = top(name, "latitude_deg", "longitude_deg", "altitude_msl_m", "fix_type", "hdop", "satellites_used")
            if g is None:
                continue
            g = g.assign(lat_deg=g["latitude_deg"], lon_deg=g["longitude_deg"], alt_m=g["altitude_msl_m"])
        g = g[(g["fix_type"] >= 3) & (g["lat_deg"] != 0) & (g["lon_deg"] != 0)]
        return g.rename(columns={"satellites_used": "sats"})[[*POSITION_COLUMNS, "hdop", "sats"]]
    return None


def _position(top: _Topics):
    pos = _global_position(top)
    if pos is None:
        pos = _gps_position(top)
    if pos is None:
        return clean_time(pd.DataFrame(), POSITION_COLUMNS), {"quality": 0, "altitude": 0, "jump": 0}
    pos = pos[pos["lat_deg"].between(-90, 90) & pos["lon_deg"].between(-180, 180) & np.isfinite(pos["alt_m"])]
    pos, rejected = reject_outliers(clean_time(pos, [c for c in (*POSITION_COLUMNS, "hdop", "sats") if c in pos]))
    return pos[list(POSITION_COLUMNS)].reset_index(drop=True), rejected


def _attitude(top: _Topics) -> pd.DataFrame:
    q = top("vehicle_attitude", "q[0]", "q[1]", "q[2]", "q[3]")
    if q is None:
        return clean_time(pd.DataFrame(), ATTITUDE_COLUMNS)
    w, x, y, z = (q[f"q[{k}]"].to_numpy() for k in range(4))
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1, 1))
    return clean_time(pd.DataFrame({"t_s": q["t_s"], "roll_rad": roll, "pitch_rad": pitch}), ATTITUDE_COLUMNS)


def _armed(top: _Topics):
    vs = top("vehicle_status", "arming_state")
    if vs is not None:
        df = pd.DataFrame({"t_s": vs["t_s"], "armed": vs["arming_state"] == _ARMING_STATE_ARMED})
        return clean_time(df, ARMED_COLUMNS, dedupe=False), "vehicle_status"
    aa = top("actuator_armed", "armed")
    if aa is not None:
        return clean_time(pd.DataFrame({"t_s": aa["t_s"], "armed": aa["armed"] > 0}), ARMED_COLUMNS, dedupe=False), \
            "actuator_armed"
    d = top.data.get("actuator_outputs", {})
    chans = [f"output[{k}]" for k in range(16) if f"output[{k}]" in d]
    ao = top("actuator_outputs", *chans) if chans else None
    tables = {"pwm": (ao.rename(columns={c: f"ch{i + 1}" for i, c in enumerate(chans)}), "actuator_outputs")} \
        if ao is not None else {}
    return infer_armed(tables)


def _battery(top: _Topics):
    b = top("battery_status", "voltage_v", "current_a")
    if b is None:
        return pd.DataFrame(columns=list(BATTERY_COLUMNS)), None
    b = b.assign(current_a=b["current_a"].where(b["current_a"] != _CURRENT_UNKNOWN_A))   # (-1: unknown, not -1 A)
    b = b[np.isfinite(b["voltage_v"]) & np.isfinite(b["current_a"]) & (b["voltage_v"] > 0)]
    if not len(b):   # (as the MAVLink logs: no source without a value, so replay and calibrate say "no battery data")
        return pd.DataFrame(columns=list(BATTERY_COLUMNS)), None
    return clean_time(b.assign(power_w=b["voltage_v"] * b["current_a"]), BATTERY_COLUMNS), "battery_status"


def _t0_epoch_s(top: _Topics) -> float:
    g = top("vehicle_gps_position", "time_utc_usec")
    g = top("sensor_gps", "time_utc_usec") if g is None else g
    if g is None or not np.any(g["time_utc_usec"] > 0):
        return float("nan")
    i = int(np.flatnonzero(g["time_utc_usec"].to_numpy() > 0)[0])
    return float(g["time_utc_usec"].iloc[i] * 1e-6 - g["t_s"].iloc[i])


#: the pyulog version ``CutSafeULog`` was tested with (its private ``ULog._check_packet_corruption(header)`` and
#: ``ULog._file_handle``). Upstream: PX4/pyulog PR #31 (2018, merged) added the corruption check and the rewind to
#: just after a corrupt header that loops here; PR #32 proposed the same rewind (closed for #31); PR #44 (2019, merged)
#: added the sync-message recovery beside it.
PYULOG_TESTED = "1.3.0"


@functools.cache
def _ulog_class():
    """pyulog's ``ULog``, except that a corrupt message header whose message runs past the end of the file ends the
    parse: in the definitions section pyulog (1.3) then seeks back 2 + the header's size, more than it read, and
    re-reads the same bytes forever (a truncated log with a flipped byte hung ``replay`` / ``mission --plan``).

    The override hooks pyulog's private internals (:data:`PYULOG_TESTED`), so a pyulog that renamed them must not
    pass silently (the hang back, caught only by a test's alarm): without ``_check_packet_corruption`` this returns
    plain ``ULog`` and says so in a ``RuntimeWarning``; without ``_file_handle`` the override raises, and the log is
    reported unreadable naming it (``tests/test_fuzz_inputs.py`` asserts the override runs on a cut log)."""
    import os
    import warnings
    from importlib.metadata import version

    from pyulog import ULog

    if not callable(getattr(ULog, "_check_packet_corruption", None)):
        warnings.warn(f"pyulog {version('pyulog')} has no ULog._check_packet_corruption (pyulog "
                      f"{PYULOG_TESTED} had): a ULog cut after a corrupt message header may hang; reading ULogs "
                      "with plain pyulog", RuntimeWarning, stacklevel=2)
        return ULog

    class CutSafeULog(ULog):
        def _check_packet_corruption(self, header):
            corrupt = super()._check_packet_corruption(header)
            fh = getattr(self, "_file_handle", None)
            if fh is None:
                raise RuntimeError(f"pyulog {version('pyulog')} has no ULog._file_handle (pyulog "
                                   f"{PYULOG_TESTED} had); dronewpt's CutSafeULog needs it")
            if corrupt and fh.tell() >= os.fstat(fh.fileno()).st_size:   # at the end: nothing left to resync on
                return False   # (pyulog then skips the message: the end of the file)
            return corrupt
    return CutSafeULog


def read_ulog(path) -> FlightLog:
    """Read a PX4 ULog into a :class:`FlightLog`; a pyulog failure is reported in ``errors``."""
    ulog = _ulog_class()
    path = Path(path)
    try:
        with open(path, "rb") as fh:   # (given a name, pyulog left its file open when the parse failed: a ResourceWarning)
            top = _Topics(ulog(fh))
    except Exception as exc:  # noqa: BLE001 -- untrusted bytes: report what failed
        empty = clean_time(pd.DataFrame(), POSITION_COLUMNS)
        return FlightLog(path=path, kind="ulog", t0_epoch_s=float("nan"), duration_s=0.0, position=empty,
                         attitude=clean_time(pd.DataFrame(), ATTITUDE_COLUMNS),
                         armed=clean_time(pd.DataFrame(), ARMED_COLUMNS), battery=pd.DataFrame(columns=list(BATTERY_COLUMNS)),
                         battery_source=None, bad_frames=0, n_records=0,
                         errors=[f"pyulog: {type(exc).__name__}: {exc}"])
    position, rejected = _position(top)
    armed, armed_source = _armed(top)
    battery, source = _battery(top)
    return FlightLog(path=path, kind="ulog", t0_epoch_s=_t0_epoch_s(top), duration_s=top.duration_s,
                     position=position, attitude=_attitude(top), armed=armed, battery=battery, battery_source=source,
                     bad_frames=top.n_stray, n_records=top.n_records, armed_source=armed_source,
                     starts_armed=starts_armed(armed), gps_rejected=rejected)
