"""Reading MAVLink telemetry logs (.tlog) and ArduPilot DataFlash logs (.bin) into pandas tables.

:func:`read_log` never raises on bad *content*: corrupt frames are counted (``bad_frames``) and
skipped, and a parser failure ends the read with what was decoded so far (``errors``). Only a
missing file raises (``FileNotFoundError``).

Tables of a :class:`FlightLog` (time ``t_s`` in seconds since the first record of the log, taken
from the log's own timestamps ``msg._timestamp`` -- ground-station clock in a .tlog, GPS-aligned
in a .bin. A .tlog's tables are all put on ONE time base, the vehicle's boot clock mapped onto
the receive clock per boot segment (clock.py): positions and attitude by their ``time_boot_ms``,
battery and armed-state records by their receive time through the same fitted map; reboots split
the log into segments, ``FlightLog.segments``):

==========  =================================================================================
table       columns (SI units; converted once, in :data:`_CONVERT`)
==========  =================================================================================
position    t_s, lat_deg, lon_deg, alt_m (AMSL) -- GPS fix type >= 3 only; in a .tlog also checked
            against GPS_RAW_INT's own altitude (gpsclean.py: an EKF without a GPS origin)
attitude    t_s, roll_rad, pitch_rad
armed       t_s, armed (bool) -- every armed-state report of the vehicle
battery     t_s, voltage_v, current_a (+ = discharging), power_w = voltage_v * current_a
airspeed    t_s, airspeed_m_s -- only from an airspeed sensor (VFR_HUD with SYS_STATUS's
            differential-pressure bit, DataFlash ARSP); empty without one
==========  =================================================================================

pymavlink must be imported with ``MAVLINK20=1`` (shared/notes/mavlink.md): :func:`mavutil`
sets it and checks it took effect.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
from pathlib import Path

import numpy as np
import pandas as pd

from .armed import armed_periods, infer_armed, starts_armed
from .flightlog import (TIME_SPIKE_S as _TIME_SPIKE_S, ARMED_COLUMNS, ATTITUDE_COLUMNS, BATTERY_COLUMNS, POSITION_COLUMNS, FlightLog,
                        clean_time as _clean_time, good_timestamps as _good_timestamps)
from .clock import ClockMap, fit_clock, identity_clock
from .gpsclean import reject_outliers

__all__ = ["mavutil", "FlightLog", "read_log", "armed_periods", "POSITION_COLUMNS", "BATTERY_COLUMNS",
           "BATTERY_SOURCES"]


_MAV_AUTOPILOT_INVALID = 8          # ground stations and companions send heartbeats with this
_MAV_MODE_FLAG_SAFETY_ARMED = 128
_SENSOR_DIFFERENTIAL_PRESSURE = 0x10  # MAV_SYS_STATUS_SENSOR_DIFFERENTIAL_PRESSURE: an airspeed sensor
_UINT16_MAX = 65535
_T_MIN_S, _T_MAX_S = 0.0, 4102444800.0  # plausible record times: boot-relative .. year 2100 (Unix s)
_DF_ARMED_EVENTS = {10: True, 11: False}  # DataFlash EV Id: ARMED, DISARMED
_DF_INT_CHARS = set("bBhHiIqQ")           # DataFlash format chars stored as plain integers


def mavutil():
    """``pymavlink.mavutil`` with the MAVLink 2 dialect loaded (MAVLINK20=1 set before the import)."""
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil as mu
    if mu.mavlink.WIRE_PROTOCOL_VERSION != "2.0":
        raise RuntimeError("pymavlink.mavutil was imported before MAVLINK20=1 was set; MAVLink 2 "
                           "messages cannot be encoded. Import mission_sim.mavlink.logs first.")
    return mu


# ----------------------------------------------------------------------------- unit conversion
def _nan_if(value, *invalid):
    return float("nan") if value in invalid else float(value)


def _battery_status_voltage_v(msg) -> float:
    """BATTERY_STATUS: cell voltages in mV, 65535 = unused; some vehicles put the pack in cell 0."""
    cells = [v for v in list(msg.voltages) + list(getattr(msg, "voltages_ext", []) or []) if 0 < v < _UINT16_MAX]
    return sum(cells) * 1e-3 if cells else float("nan")


def _df_scale(msg, column: str, int_scale: float) -> float:
    """DataFlash: integer columns (old CURR: cV, cA) get ``int_scale``; float columns are in SI already."""
    fmt = msg.fmt
    char = fmt.format[fmt.colhash[column]] if column in fmt.colhash else "f"
    return int_scale if char in _DF_INT_CHARS else 1.0


#: The ONE place where raw log fields become SI values: message type -> (table, row function).
#: DFReader already applies the DataFlash format multipliers (L: 1e-7 deg, c/e: 0.01), except on
#: plain integer columns such as the old CURR Volt/Curr in cV/cA.
_CONVERT = {
    "GLOBAL_POSITION_INT": ("position", lambda m: {
        "lat_deg": m.lat * 1e-7, "lon_deg": m.lon * 1e-7, "alt_m": m.alt * 1e-3,
        "time_boot_s": m.time_boot_ms * 1e-3}),
    "GPS_RAW_INT": ("fix", lambda m: {"fix_type": int(m.fix_type), "hdop": _nan_if(m.eph, _UINT16_MAX) * 1e-2,
                                      "sats": _nan_if(m.satellites_visible, 255), "gps_alt_m": m.alt * 1e-3}),
    "GPS": ("df_gps", lambda m: {
        "fix_type": int(m.Status), "lat_deg": float(m.Lat), "lon_deg": float(m.Lng), "alt_m": float(m.Alt),
        "gps_id": int(getattr(m, "I", getattr(m, "Instance", 0))),
        "hdop": float(getattr(m, "HDop", float("nan"))), "sats": float(getattr(m, "NSats", float("nan")))}),
    "ATTITUDE": ("attitude", lambda m: {"roll_rad": float(m.roll), "pitch_rad": float(m.pitch),
                                        "time_boot_s": m.time_boot_ms * 1e-3}),
    "ATT": ("attitude", lambda m: {"roll_rad": math.radians(m.Roll), "pitch_rad": math.radians(m.Pitch)}),
    "HEARTBEAT": ("heartbeat", lambda m: {
        "armed": bool(m.base_mode & _MAV_MODE_FLAG_SAFETY_ARMED), "autopilot": int(m.autopilot),
        "mav_type": int(m.type)}),
    "EV": ("armed", lambda m: {"armed": _DF_ARMED_EVENTS.get(int(m.Id))}),
    "ARM": ("armed", lambda m: {"armed": bool(m.ArmState)}),
    "SERVO_OUTPUT_RAW": ("pwm", lambda m: {f"ch{k}": float(getattr(m, f"servo{k}_raw")) for k in range(1, 9)}),
    "RCOU": ("pwm", lambda m: {f"ch{c.lstrip('Ch')}": float(getattr(m, c)) for c in m.fmt.columns
                               if c.lstrip("Ch").isdigit()}),
    "ESC": ("esc", lambda m: {"rpm": float(m.RPM)}),
    "VFR_HUD": ("throttle", lambda m: {"throttle": float(m.throttle), "airspeed_m_s": float(m.airspeed)}),
    "ARSP": ("df_airspeed", lambda m: {"airspeed_m_s": float(m.Airspeed),
                                       "sensor_id": int(getattr(m, "I", getattr(m, "Instance", 0)))}),
    "CTUN": ("throttle", lambda m: {"throttle": float(getattr(m, "ThO", getattr(m, "ThrOut", float("nan"))))}),
    "SYS_STATUS": ("sys_status", lambda m: {
        "airspeed_sensor": bool(m.onboard_control_sensors_present & m.onboard_control_sensors_enabled
                                & _SENSOR_DIFFERENTIAL_PRESSURE),
        "voltage_v": _nan_if(m.voltage_battery, 0, _UINT16_MAX) * 1e-3,
        "current_a": _nan_if(m.current_battery, -1) * 1e-2}),
    "BATTERY_STATUS": ("battery_status", lambda m: {
        "voltage_v": _battery_status_voltage_v(m),
        "current_a": _nan_if(m.current_battery, -1) * 1e-2, "battery_id": int(m.id)}),
    "CURR": ("df_curr", lambda m: {
        "voltage_v": m.Volt * _df_scale(m, "Volt", 1e-2), "current_a": m.Curr * _df_scale(m, "Curr", 1e-2)}),
    "BAT": ("df_bat", lambda m: {
        "voltage_v": float(m.Volt), "current_a": float(m.Curr),
        "battery_id": int(getattr(m, "Inst", getattr(m, "Instance", 0)))}),
}


# ----------------------------------------------------------------------------- reading
def open_log(path: Path, mu):
    """(reader, kind). DataFlash by magic bytes or suffix; everything else is read as a .tlog.

    The readers are built directly: ``mavlink_connection`` would execute a path containing /bin/ (and
    treat one with a ':' as a UDP address). DataFlash corrupt-byte reports are Python prints: callers
    capture stdout and stderr around reading.
    """
    from pymavlink import DFReader
    with open(path, "rb") as fh:
        head = fh.read(2)
    if head == b"\xa3\x95" or path.suffix.lower() == ".bin":
        # the Python indexer: the compiled one reports corrupt bytes on the C stderr, uncapturable
        old = os.environ.get("PYMAVLINK_FAST_INDEX")
        os.environ["PYMAVLINK_FAST_INDEX"] = "0"
        try:
            return _built(DFReader.DFReader_binary, path), "dataflash"
        finally:
            if old is None:
                os.environ.pop("PYMAVLINK_FAST_INDEX")
            else:
                os.environ["PYMAVLINK_FAST_INDEX"] = old
    if path.suffix.lower() == ".log" and DFReader.DFReader_is_text_log(str(path)):
        return _built(DFReader.DFReader_text, path), "dataflash"
    try:
        return _built(mu.mavmmaplog, path), "tlog"
    except Exception:  # noqa: BLE001 -- pymavlink's indexer, e.g. AttributeError "'NoneType' object has no
        # attribute '_instance_field'" on a .tlog that joins two vehicles' logs; the streaming reader reads it.
        return mu.mavlogfile(str(path)), "tlog"


def _built(cls, path: Path):
    """``cls(path)``, a pymavlink reader; one whose constructor fails (its indexer on untrusted bytes: a DataFlash
    format char it does not know, a .tlog joining two vehicles) has its half-built map and file closed before the error
    goes on (they were left to the collector: a ResourceWarning, in a later test's ``gc.collect()``)."""
    reader = cls.__new__(cls)
    try:
        reader.__init__(str(path))
    except BaseException:
        close_log(reader)
        raise
    return reader


def close_log(reader) -> None:
    """Close a reader of :func:`open_log` (also a half-built one): its memory map and file (left to the
    collector they were a ResourceWarning each)."""
    for part in (getattr(reader, "data_map", None), getattr(reader, "f", None), getattr(reader, "filehandle", None)):
        if part is not None:
            try:
                part.close()
            except (OSError, ValueError, BufferError):
                pass


def _collect(reader, kind: str, raw: dict, stats: dict) -> None:
    """Decode every record into ``raw[table]`` rows (with t and source); BAD_DATA only counted.

    Records are read unfiltered: with a type filter pymavlink skips .tlog frames without checking
    them (corrupt frames would go uncounted), and the duration is over all records.
    """
    while True:
        msg = reader.recv_match(blocking=False)
        if msg is None:
            return
        t = getattr(msg, "_timestamp", None)
        if isinstance(t, (int, float)) and not _T_MIN_S <= t <= _T_MAX_S and msg.get_type() != "BAD_DATA":
            stats["bad_time"] = stats.get("bad_time", 0) + 1   # a frame that decodes, with a stamp out of range
            stats.setdefault("first_bad_time", float(t))
        t = float(t) if isinstance(t, (int, float)) and _T_MIN_S <= t <= _T_MAX_S else float("nan")
        rec = len(stats["ts"])
        stats["ts"].append(t)
        mtype = msg.get_type()
        stats["bad_rec"].append(mtype == "BAD_DATA")
        if mtype == "BAD_DATA" or t != t:
            continue
        if kind == "tlog":
            buf = msg.get_msgbuf()
            ver = 2 if buf[:1] == b"\xfd" else 1
            stats["versions"][ver] = stats["versions"].get(ver, 0) + 1
        conv = _CONVERT.get(mtype)
        if conv is None:
            continue
        table, fn = conv
        try:
            row = fn(msg)
        except (AttributeError, TypeError, ValueError, KeyError, OverflowError):
            stats["bad_rec"][rec] = True
            continue
        row["t"] = t
        row["rec"] = rec
        row["src"] = (msg.get_srcSystem(), msg.get_srcComponent()) if kind == "tlog" else (0, 0)
        raw.setdefault(table, []).append(row)


def _is_ulog(path: Path) -> bool:
    """PX4 ULog by its magic bytes ("ULog" 01 12 35) or the .ulg suffix."""
    with open(path, "rb") as fh:
        return fh.read(7) == b"ULog\x01\x12\x35" or path.suffix.lower() == ".ulg"


def read_log(path) -> FlightLog:
    """Read a .tlog, DataFlash or PX4 ULog (ulog.py) log into a :class:`FlightLog`; never raises on bad content.

    Raises ``FileNotFoundError`` if ``path`` does not exist or is not a file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"log {str(path)!r} does not exist or is not a file")
    if _is_ulog(path):
        from .ulog import read_ulog
        return read_ulog(path)
    mu = mavutil()
    raw: dict[str, list[dict]] = {}
    stats = {"ts": [], "bad_rec": [], "bad": 0, "versions": {}}
    errors: list[str] = []
    kind = "dataflash" if path.suffix.lower() == ".bin" else "tlog"
    captured = io.StringIO()
    if path.stat().st_size > 0:
        # DFReader reports skipped corrupt bytes with print(); count those reports as bad frames.
        with contextlib.redirect_stderr(captured), contextlib.redirect_stdout(captured):
            reader = None
            try:
                reader, kind = open_log(path, mu)
                _collect(reader, kind, raw, stats)
            except Exception as exc:  # noqa: BLE001 -- untrusted bytes: keep what was decoded, report
                errors.append(f"{type(exc).__name__}: {exc}")
            finally:
                if reader is not None:
                    close_log(reader)
    text = captured.getvalue()
    stats["bad"] += text.count("Skipped ") + text.count("Failed to parse")
    return _assemble(path, kind, raw, stats, errors)


class _Tables:
    """``raw`` rows as DataFrames: records with a good timestamp only, time ``t_s`` on the log's one
    time base (a .tlog: :attr:`clock`, fitted here from the vehicle's boot-stamped records; other
    logs: their own clock from ``t0``); for a .tlog, :meth:`vehicle` keeps the vehicle's own
    messages (by the first autopilot heartbeat's system and component id)."""

    def __init__(self, raw: dict, good: np.ndarray, t0: float, kind: str):
        self.raw, self.good, self.t0, self.kind = raw, good, t0, kind
        self.clock: ClockMap | None = None
        hb = self("heartbeat")
        veh = hb[hb["autopilot"] != _MAV_AUTOPILOT_INVALID] if len(hb) else hb
        self.ids = {}
        if kind == "tlog" and len(veh):
            src = veh["src"].iloc[0]
            self.ids = {"sysid": int(src[0]), "compid": int(src[1]), "mav_type": int(veh["mav_type"].iloc[0])}
        self.clock = self._fit_clock() if kind == "tlog" else identity_clock("the log's own (vehicle) clock")

    def _fit_clock(self) -> ClockMap:
        """The boot clock of the vehicle's position and attitude records, fitted to their receive times."""
        parts = [df[["rec", "t_s", "time_boot_s"]] for df in (self.vehicle("position"), self.vehicle("attitude"))
                 if len(df) and "time_boot_s" in df]
        if not parts:
            return identity_clock("log clock (no time_boot_ms in the log)")
        both = pd.concat(parts)
        return fit_clock(both["rec"].to_numpy(), both["t_s"].to_numpy(float), both["time_boot_s"].to_numpy(float))

    def __call__(self, name: str) -> pd.DataFrame:
        df = pd.DataFrame(self.raw.get(name, []))
        if len(df):
            df = df[self.good[df["rec"].to_numpy()]]
            t = df.pop("t").to_numpy(float) - self.t0
            if self.clock is not None and self.kind == "tlog":
                boot = df["time_boot_s"].to_numpy(float) if "time_boot_s" in df else None
                t = self.clock.map(df["rec"].to_numpy(), t, boot, spike_s=_TIME_SPIKE_S)
            df.insert(0, "t_s", t)
        return df

    def vehicle(self, name: str) -> pd.DataFrame:
        df = self(name)
        if not len(df) or self.kind != "tlog":
            return df
        if self.ids:
            return df[df["src"] == (self.ids["sysid"], self.ids["compid"])]
        return df[df["src"].map(lambda s: s[0]) != 255]  # no autopilot heartbeat: drop the usual GCS id


def _tlog_position(tab: _Tables):
    """GLOBAL_POSITION_INT of the vehicle with the last GPS_RAW_INT fix report before it (record
    order): (positions with fix >= 3, reboots, fix_checked)."""
    pos = tab.vehicle("position")
    fix = tab("fix")
    if tab.ids and len(fix):
        fix = fix[fix["src"].map(lambda s: s[0]) == tab.ids["sysid"]]
    reboots = len(tab.clock.segments) - 1
    if len(pos) and len(fix):
        pos = pd.merge_asof(pos.sort_values("rec"), fix[["rec", "fix_type", "hdop", "sats", "gps_alt_m"]].sort_values("rec"),
                            on="rec", direction="backward")
        return pos[pos["fix_type"].fillna(0) >= 3], reboots, True
    return pos, reboots, not len(pos)


def _position(tab: _Tables):
    """(position table, reboots, fix_checked, rejected counts): fix >= 3, plausible, sorted."""
    if tab.kind == "tlog":
        pos, reboots, fix_checked = _tlog_position(tab)
    else:
        pos, reboots, fix_checked = tab("df_gps"), 0, True
        if len(pos):
            pos = pos[(pos["fix_type"] >= 3) & (pos["gps_id"] == pos["gps_id"].min())]  # first receiver
    if len(pos):
        ok = (pos["lat_deg"] != 0) & (pos["lon_deg"] != 0) & pos["lat_deg"].between(-90, 90) \
            & pos["lon_deg"].between(-180, 180) & np.isfinite(pos["alt_m"])
        pos = pos[ok]
    extra = [c for c in ("hdop", "sats", "gps_alt_m") if c in pos]
    pos, rejected = reject_outliers(_clean_time(pos, (*POSITION_COLUMNS, *extra)))
    return pos[list(POSITION_COLUMNS)].reset_index(drop=True), reboots, fix_checked, rejected


def _armed(tab: _Tables):
    """(armed table, source, starts_armed): records of the log, else inferred (armed.py)."""
    if tab.kind == "tlog":
        hb = tab.vehicle("heartbeat")
        df = hb[hb["autopilot"] != _MAV_AUTOPILOT_INVALID][["t_s", "armed"]] if len(hb) else hb
        source, events = "HEARTBEAT", False
    else:
        df = tab("armed")
        df = df[df["armed"].notna()] if len(df) else df
        source, events = "EV / ARM events", True
    armed = _clean_time(df, ARMED_COLUMNS, dedupe=False)
    if len(armed):
        armed["armed"] = armed["armed"].astype(bool)
        # events: a first event that is a disarm means armed from the start; reports: a first armed report
        return armed, source, (not armed["armed"].iloc[0]) if events else starts_armed(armed)
    names = {"pwm": "SERVO_OUTPUT_RAW" if tab.kind == "tlog" else "RCOU", "esc": "ESC",
             "throttle": "VFR_HUD" if tab.kind == "tlog" else "CTUN"}
    tables = {k: (_clean_time(tab.vehicle(k), ["t_s", *[c for c in tab.vehicle(k) if c.startswith(("ch", "rpm", "thr"))]]),
                  names[k]) for k in names if len(tab.vehicle(k))}
    inferred, source = infer_armed(tables)
    return inferred, source, starts_armed(inferred)


#: the battery tables a log is read from, the first with values taken: (table, the name a message gives it); a PX4
#: ULog's battery_status fills BATTERY_STATUS's table
_BATTERY_TABLES = (("battery_status", "BATTERY_STATUS"), ("sys_status", "SYS_STATUS"), ("df_bat", "BAT"),
                   ("df_curr", "CURR"))
#: what a message names as the battery sources (``replay``'s "no battery data", ``calibrate``'s refusal): one spelling
BATTERY_SOURCES = " / ".join(label for _, label in _BATTERY_TABLES) + " / PX4 battery_status"


def _battery(tab: _Tables):
    """(battery table, source) from the first of :data:`_BATTERY_TABLES` (BATTERY_STATUS, SYS_STATUS, BAT, CURR) with
    values."""
    for name, label in _BATTERY_TABLES:
        df = tab.vehicle(name)
        if "battery_id" in df and len(df):
            df = df[df["battery_id"] == df["battery_id"].min()]
        if len(df):
            df = df[np.isfinite(df["voltage_v"]) & np.isfinite(df["current_a"])]
        if len(df):
            df = df.assign(power_w=df["voltage_v"] * df["current_a"])
            return _clean_time(df, BATTERY_COLUMNS), label
    return pd.DataFrame(columns=list(BATTERY_COLUMNS)), None


def _airspeed(tab: _Tables) -> pd.DataFrame:
    """(t_s, airspeed_m_s) where the vehicle measures airspeed: a .tlog's VFR_HUD.airspeed only when
    SYS_STATUS reports a differential-pressure sensor present and enabled (without one ArduPilot
    reports an estimate); a DataFlash log's ARSP (first sensor). Empty otherwise."""
    cols = ("t_s", "airspeed_m_s")
    if tab.kind == "tlog":
        ss = tab.vehicle("sys_status")
        df = tab.vehicle("throttle") if len(ss) and ss["airspeed_sensor"].any() else pd.DataFrame()
    else:
        df = tab("df_airspeed")
        if len(df):
            df = df[df["sensor_id"] == df["sensor_id"].min()]
    if len(df):
        df = df[np.isfinite(df["airspeed_m_s"]) & (df["airspeed_m_s"] >= 0)]
    return _clean_time(df, cols) if len(df) else pd.DataFrame({c: pd.Series(dtype=float) for c in cols})


def _assemble(path: Path, kind: str, raw: dict, stats: dict, errors: list[str]) -> FlightLog:
    ts = np.asarray(stats["ts"], dtype=float)
    good = _good_timestamps(ts)
    stats["bad"] += int(np.sum(~good | np.asarray(stats["bad_rec"], dtype=bool)))
    t0 = float(ts[good][0]) if good.any() else float("nan")
    tab = _Tables(raw, good, t0, kind)
    duration = 0.0
    if good.any():    # the latest record on the log's time base (not the latest receive time: its clock may step)
        idx = np.flatnonzero(good)
        duration = max(float(np.max(tab.clock.map(idx, ts[idx] - t0))), 0.0)
    position, reboots, fix_checked, rejected = _position(tab)
    attitude = _clean_time(tab.vehicle("attitude"), ATTITUDE_COLUMNS)
    armed, armed_source, starts_armed = _armed(tab)
    battery, source = _battery(tab)
    return FlightLog(path=path, kind=kind, t0_epoch_s=float(t0), duration_s=float(duration),
                     position=position, attitude=attitude, armed=armed, battery=battery,
                     battery_source=source, bad_frames=int(stats["bad"]), n_records=int(len(ts)),
                     mavlink_frames=dict(stats["versions"]), reboots=reboots, fix_checked=fix_checked,
                     vehicle=tab.ids, errors=errors, armed_source=armed_source, starts_armed=starts_armed,
                     gps_rejected=rejected, clock=tab.clock if kind == "tlog" else None,
                     airspeed=_airspeed(tab), bad_time=int(stats.get("bad_time", 0)),
                     first_bad_time_s=float(stats.get("first_bad_time", float("nan"))))

