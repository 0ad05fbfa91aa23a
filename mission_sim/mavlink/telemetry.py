"""Live MAVLink 2 telemetry of a simulated mission and a .tlog writer (``--follow``: follow.py).

The simulated drone appears to a ground station as an ArduCopter quadrotor (autopilot
ARDUPILOTMEGA, so MAVProxy and QGroundControl decode its custom mode). :func:`stream` sends, on
the simulation clock, paced at ``speed`` times real time:

===================  ============================================================================
message              content (from the mission time series; units as the MAVLink spec)
===================  ============================================================================
HEARTBEAT            at every whole second of simulated time (1 Hz, also in follow mode):
                     quadrotor, ArduCopter custom mode LOITER (5) while hovering (over a pad,
                     charging), LAND (9) in the final descent and on the ground after it, AUTO (3)
                     in transit; base_mode as ArduCopter sets it
                     (CUSTOM_MODE_ENABLED | STABILIZE_ENABLED | GUIDED_ENABLED |
                     MANUAL_INPUT_ENABLED | SAFETY_ARMED), system status ACTIVE
EXTENDED_SYS_STATE  with every HEARTBEAT: landed state TAKEOFF / IN_AIR / LANDING / ON_GROUND by phase
end of stream        the vehicle lands and disarms, as ArduCopter does after a LAND: 0.5 s after the
                     last tick (if it was still in the air) a HEARTBEAT in LAND with landed state
                     LANDING, 1 s after it a HEARTBEAT without the armed flag (system status
                     STANDBY) and landed state ON_GROUND. So a ground station sees DISARMED before
                     the link goes quiet (a stream cut by ``duration_s`` ends the same way)
every tick at ``rate_hz``:
SYS_STATUS           sensors present = enabled: gyro, accelerometer, GPS, battery, pre-arm check; health: those
                     (battery bit cleared below 5 % charge) plus the geofence bit (no fence, so no
                     breach); battery voltage [mV], current [cA, + = discharging], remaining [%]
BATTERY_STATUS       pack voltage in cell 0 [mV], current [cA], consumed [mAh, hJ], remaining [%],
                     charge_state CHARGING (7) while the battery current is a net charge, else
                     OK / LOW / CRITICAL / EMERGENCY by state of charge (20 / 10 / 5 %).
                     ``current_consumed`` / ``energy_consumed`` are **net**: the integral of the
                     battery's discharge current / power since the start, so they *fall* while the
                     pad charges the battery (they may go negative after a net charge; -1, "not
                     measured", is sent as -2)
GPS_RAW_INT          3D fix at the position (ground stations read the fix from it), with what a
                     receiver reports: 10-14 satellites, HDOP 0.8-1.2 and VDOP 1.2-1.6 (eph / epv in
                     cm units), varying slowly with time (:func:`gps_quality`), course over ground
GLOBAL_POSITION_INT  position about ``home`` [1e-7 deg, mm], relative_alt [mm] (coil height less the
                     ground gap: 0 when landed), velocity NED [cm/s]
ATTITUDE             roll 0, pitch = -tilt (nose down in forward flight), yaw = course over ground
                     (held while hovering) [rad], and their rates [rad/s]
VFR_HUD              airspeed = groundspeed [m/s] (no wind in the link model), heading [deg], throttle
                     [%] = propulsion power / the series' peak propulsion power, alt [m AMSL], climb [m/s]
NAMED_VALUE_FLOAT    :data:`NVF_NAMES` (upper case, <= 10 characters, as MAVProxy's graph and
                     MAVExplorer need)
===================  ============================================================================

A ``.tlog`` is written as pymavlink reads it: for each frame an 8-byte big-endian timestamp in
microseconds since the Unix epoch, then the frame bytes (the timestamps are the simulation clock
from the start epoch, so a faster-than-real-time run still records the simulated timeline).

Every network loop here is bounded in both message count and wall time.
"""

from __future__ import annotations

import contextlib
import math
import re
import struct
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..files import rename_into_place, storage_error
from .geodesy import GeoPoint, enu_to_geodetic
from .logs import mavutil

__all__ = ["DEFAULT_HOME", "TlogWriter", "mavlink_table", "encode_tick", "encode_heartbeat", "stream", "StreamStats",
           "check_connect", "check_ids", "CONNECT_FORMAT", "NVF_NAMES", "COPTER_MODES", "schedule", "drawn_totals",
           "gps_quality", "heartbeat_msgs", "landing_rows", "open_link", "link_has_peer", "write_frame",
           "close_link", "SERVER_KINDS"]

#: ArduPilot SITL's default home (CMAC, Canberra), where two of the real logs were flown.
DEFAULT_HOME = GeoPoint(-35.363261, 149.165230, 584.0)
CONNECT_FORMAT = "udpout:HOST:PORT, udpin:HOST:PORT, udp:HOST:PORT, tcp:HOST:PORT or tcpin:HOST:PORT"
#: ArduCopter custom modes sent in HEARTBEAT.custom_mode (ArduCopter's Mode::Number)
COPTER_MODES = {"AUTO": 3, "LOITER": 5, "LAND": 9}
#: MAV_LANDED_STATE of EXTENDED_SYS_STATE by mission phase (anything else: IN_AIR = 2)
_LANDED_STATE = {"ground": 1, "takeoff": 3, "land": 4}
_LAND_PHASES = ("land", "ground")
#: NAMED_VALUE_FLOAT name -> (mavlink_table column, meaning and unit); names match [0-9A-Z_]{1,10}
NVF_NAMES = {
    "I2": ("i2_a", "secondary coil current envelope amplitude [A]"),
    "I1": ("i1_a", "primary (pad) coil current envelope amplitude [A]"),
    "DUTY": ("d_short", "SBAR short-mode duty d [0..1] (0 = rectification mode all the time)"),
    "LM_UH": ("lm_uh", "mutual inductance Lm [uH]"),
    "SBAR_MODE": ("sbar_mode", "0 = RM (rectifying), 1 = switching between RM and SM, 2 = SM (shorted)"),
    "PAD_ON": ("pad_on", "1 = the pad (primary inverter) is energised, 0 = off"),
    "CHG_CMD": ("charge_cmd_a", "charge current command of the CC-CV charger [A]"),
    "I_RECT": ("rect_a", "rectifier output current into the battery side [A]"),
}
_CHARGING_A = 0.05          # net battery current above this [A] reports CHARGING
_INT16 = 32767
_UINT16_MAX = 65535
_MOTION = ("x_m", "y_m", "z_m", "vx", "vy", "vz", "tilt")
_REQUIRED = ("t_s", "x_m", "y_m", "z_m", "lm_h", "i2_amp_a", "d_short", "battery_v", "battery_current_a", "soc")
_OPTIONAL = ("i1_amp_a", "rect_current_a", "charge_cmd_a", "tx_on", "propulsion_w")   # 0 when absent
_HOVER_PHASES = ("charge", "hover")


def check_connect(text: str, name: str = "--connect") -> str:
    """Validate a pymavlink connection string of the supported kinds; ``ValueError`` names the format."""
    kind, _, rest = str(text).partition(":")
    host, _, port = rest.rpartition(":")
    if kind not in ("udpout", "udpin", "udp", "tcp", "tcpin") or not host or re.fullmatch(r"-?[0-9]+", port) is None:
        raise ValueError(f"{name} {text!r} is invalid; valid format: {CONNECT_FORMAT}")
    if not 0 < int(port) < 65536:   # (the format's message named no range: a typo'd port looked like a bad format)
        raise ValueError(f"{name} {text!r} is invalid: port {int(port)}; valid range: 1..65535")
    return text


#: connection kinds on which this end listens: it sends only to a ground station that has sent to it first
SERVER_KINDS = ("udpin", "udp", "tcpin")


def open_link(connect: str, sysid: int = 1, compid: int = 1, name: str = "--connect"):
    """The vehicle's link ``connect`` (see :func:`check_connect`), opened now (before a simulation, so
    that a refused connection or a port that cannot be bound is said at once): an ``OSError`` becomes
    a ``ValueError`` naming the connection."""
    try:   # retries=0: one attempt (tcp: only; the default 3 printed "... sleeping" on stdout and waited 2 s)
        return mavutil().mavlink_connection(check_connect(connect, name), source_system=sysid,
                                            source_component=compid, retries=0)
    except OSError as exc:
        what = exc.strerror or str(exc)
        hint = ("nothing listens there: start the ground station first, or send with udpout:HOST:PORT (QGroundControl "
                "and MAVProxy listen on UDP 14550)" if isinstance(exc, ConnectionRefusedError) else
                "another program holds the port, or the address is not this machine's")
        raise ValueError(f"{name} {connect!r} cannot be opened: {what}; {hint}") from None


def _listening(conn) -> str | None:
    """``"udp"`` or ``"tcp"`` for a link that listens (:data:`SERVER_KINDS`: pymavlink's udp server, tcpin), else
    None (udpout, tcp: it sends out)."""
    if getattr(conn, "udp_server", False):
        return "udp"
    return "tcp" if hasattr(conn, "listen") else None


def _listens(conn) -> bool:
    return _listening(conn) is not None


def link_has_peer(conn) -> bool:
    """Whether ``conn`` has someone to send to: always for a link that sends out (udpout, tcp); for a
    listening link (:data:`SERVER_KINDS`) once a ground station has sent to it (pymavlink drops
    what is written before that)."""
    kind = _listening(conn)
    if kind == "udp":
        return bool(conn.clients)
    return conn.port is not None if kind == "tcp" else True


def poll_link(conn, max_reads: int = 16) -> None:
    """Read what a ground station sent to a listening link, without blocking: pymavlink's udpin
    learns its peers, and tcpin accepts its client, only while reading (the stream never read, so
    ``--connect udpin:`` / ``tcpin:`` sent nothing). Incoming messages are dropped."""
    if conn is None or not _listens(conn):
        return
    for _ in range(max_reads):
        try:
            if conn.recv_msg() is None:
                return
        except OSError:
            return


def check_ids(sysid: int, compid: int) -> tuple[int, int]:
    """MAVLink system and component ids: integers in [1, 255] (0 is the broadcast address)."""
    for name, v in (("--sysid", sysid), ("--compid", compid)):
        if not isinstance(v, (int, np.integer)) or not 1 <= int(v) <= 255:
            raise ValueError(f"{name} {v!r} is invalid; valid range: 1..255 (integer)")
    return int(sysid), int(compid)


class TlogWriter:
    """Append MAVLink frames to a .tlog (8-byte big-endian microsecond timestamp + frame).

    The frames go to a visible ``STEM.partial.tlog`` beside ``path`` (``STEM.partial.2.tlog``, ... when an earlier
    one is there: it is never overwritten) as they are streamed: after an interrupt, an error or a kill the frames
    so far are there, a readable log. :meth:`close` (the stream ended) renames it to ``path``
    (:func:`~mission_sim.files.rename_into_place`); if that fails (``path`` open in a ground station on Windows, a
    folder) the partial file stays and the one-line error names it. :meth:`abort` (an interrupt, an error) leaves
    it where it is and notes its name on the exception. Either way an existing ``path`` is replaced only by a stream
    that ended, and a stream that wrote no frame leaves no file at all (``telemetry --follow`` with no vehicle had
    replaced an existing recording by an empty file). ``kept``: where the frames are after close / abort (None:
    nowhere).
    """

    def __init__(self, path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        for k in range(1, 10_000):
            self.partial_path = self.path.with_name(
                f"{self.path.stem}.partial{'' if k == 1 else f'.{k}'}{self.path.suffix}")
            try:
                self._fh = open(self.partial_path, "xb")   # (an earlier partial file is kept, never overwritten)
                break
            except FileExistsError:
                continue
        else:
            raise ValueError(f"{str(self.path)!r}: 9,999 earlier partial recordings {self.path.stem}.partial*."
                             f"{self.path.suffix} beside it; valid: move them away")
        self.n_frames = 0
        self.kept: Path | None = None
        self.earlier = self.earlier_partials()
        if self.earlier:   # never deleted (they are recordings): named, once, so the user can deal with them
            from wpt_receiver.notices import warn
            names = ", ".join(repr(p.name) for p in self.earlier[:4]) + (" ..." if len(self.earlier) > 4 else "")
            warn(f"{str(self.path)!r}: {len(self.earlier)} earlier partial recording(s) beside it, from streams cut "
                 f"short, kept as they are: {names}; this stream writes {self.partial_path.name!r} (renamed to "
                 f"{self.path.name!r} when it ends); valid: move or delete them once read (dronewpt never does)")

    def earlier_partials(self) -> list[Path]:
        """The partial recordings of ``path`` from earlier streams (``STEM.partial.tlog``, ``STEM.partial.N.tlog``)
        other than this stream's, in order of N."""
        import glob
        stem, suffix = self.path.stem, self.path.suffix
        name = re.compile(re.escape(stem) + r"\.partial(?:\.(\d+))?" + re.escape(suffix))
        found = []
        for p in self.path.parent.glob(f"{glob.escape(stem)}.partial*{glob.escape(suffix)}"):
            m = name.fullmatch(p.name)
            if m and p != self.partial_path:
                found.append((int(m.group(1) or 1), p))
        return [p for _, p in sorted(found)]

    def write(self, frame: bytes, t_epoch_s: float) -> None:
        try:
            self._fh.write(struct.pack(">Q", int(round(t_epoch_s * 1e6))) + frame)
        except OSError as exc:  # a full disk: the file named (the frames written so far stay a valid log; none: removed)
            raise storage_error(exc, self.path, self.partial_path if self.n_frames else None) or exc from None
        self.n_frames += 1

    def _close_file(self) -> bool:
        """Close the partial file (False: it was already); with no frame written, remove it."""
        if self._fh.closed:
            return False
        try:
            self._fh.close()  # flushes the buffer: a full disk may show here
        except OSError as exc:
            raise storage_error(exc, self.path, self.partial_path) or exc from None
        finally:
            if self.n_frames:
                self.kept = self.partial_path
            else:
                with contextlib.suppress(OSError):
                    self.partial_path.unlink(missing_ok=True)
        return True

    def _where(self, before: str = "") -> str:
        return f"the {self.n_frames} frames streamed{before} are in {str(self.partial_path)!r}"

    def close(self) -> None:
        """The stream ended: its frames become ``path`` (none written: no file, an existing one untouched). A
        rename that fails keeps them in :attr:`partial_path`, named in the error."""
        if not self._close_file() or not self.n_frames:
            return
        try:
            rename_into_place(self.partial_path, self.path)
        except OSError as exc:
            raise OSError(f"cannot rename the stream's .tlog to {str(self.path)!r}: {exc.strerror or exc}; "
                          f"{self._where()} ({str(self.path)!r} left as it was)") from None
        except KeyboardInterrupt as exc:   # an interrupt a callback swallowed: not renamed after it
            self._note(exc)
            raise
        self.kept = self.path

    def _note(self, exc: BaseException | None) -> None:
        if exc is not None and self.kept == self.partial_path and hasattr(exc, "add_note") and \
                getattr(exc, "kept", None) is None:
            exc.add_note(f"{self._where(' before it')} ({str(self.path)!r} left as it was)")

    def abort(self, exc: BaseException | None = None) -> None:
        """The stream was cut (``exc``): its frames so far stay in :attr:`partial_path`, ``path`` is left as it
        was; ``exc`` gets a note saying so (the CLI's error and interrupt lines print it)."""
        try:
            self._close_file()
        except OSError:
            pass
        self._note(exc)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc is None:
            self.close()
        else:
            self.abort(exc)


def drawn_totals(ts: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """Net charge [C] and energy [J] drawn from the battery since the series' first sample (fall
    while charging): cumulative sums of -I dt and -V I dt (battery_current_a + = charging)."""
    t = ts["t_s"].to_numpy(float)
    i_a, v = ts["battery_current_a"].to_numpy(float), ts["battery_v"].to_numpy(float)
    dt = np.diff(t, prepend=t[0])
    return np.cumsum(-i_a * dt), np.cumsum(-v * i_a * dt)


def _columns(ts: pd.DataFrame, track) -> dict:
    """Series columns on the series' own time grid: positions, velocities and tilt from ``track``
    (``(t_s, pos_m[, tilt_rad])``) if given, net drawn charge and energy, the hover flag."""
    t = ts["t_s"].to_numpy(float)
    col = {c: ts[c].to_numpy(float) for c in _REQUIRED}
    col.update({c: (ts[c].to_numpy(float) if c in ts else np.zeros(len(t))) for c in _OPTIONAL})
    col["drawn_c"], col["drawn_j"] = drawn_totals(ts)
    phase = ts["phase"].astype(str).to_numpy() if "phase" in ts else None
    col["hover"] = np.isin(phase, _HOVER_PHASES).astype(float) if phase is not None else (col["tx_on"] > 0) * 1.0
    col["landing"] = np.isin(phase, _LAND_PHASES).astype(float) if phase is not None else np.zeros(len(t))
    col["landed_state"] = (np.array([_LANDED_STATE.get(p, 2) for p in phase], dtype=float) if phase is not None
                           else np.full(len(t), 2.0))
    tp, pos = t, np.column_stack([col["x_m"], col["y_m"], col["z_m"]])
    tilt = np.zeros(len(t))
    if track is not None:
        tp, pos = np.asarray(track[0], dtype=float), np.asarray(track[1], dtype=float)
        tilt = np.asarray(track[2], dtype=float) if len(track) > 2 else np.zeros(len(tp))
    vel = [np.gradient(pos[:, i], tp) if len(tp) > 1 else np.zeros(len(tp)) for i in range(3)]
    col["_track"] = (tp, pos, vel, tilt)
    return col


def _at(col: dict, t: np.ndarray, t_out: np.ndarray) -> dict:
    """Columns at ``t_out``: motion interpolated on the track, everything else the latest series
    sample at or before (never a value the simulation did not produce)."""
    tp, pos, vel, tilt = col.pop("_track")
    held = np.clip(np.searchsorted(t, t_out + 1e-9, side="right") - 1, 0, len(t) - 1)
    out = {k: v[held] for k, v in col.items() if k not in _MOTION}
    for i, c in enumerate(("x_m", "y_m", "z_m")):
        out[c] = np.interp(t_out, tp, pos[:, i])
        out["v" + c[0]] = np.interp(t_out, tp, vel[i])
    out["tilt"] = np.interp(t_out, tp, tilt)
    return out


def _attitude(col: dict, t: np.ndarray) -> dict:
    """ATTITUDE / VFR_HUD angles: yaw = course over ground (held below 0.3 m/s), pitch = -tilt, rates."""
    speed = np.hypot(col["vx"], col["vy"])
    course = np.arctan2(col["vx"], col["vy"])                   # from north, clockwise (east = +pi/2)
    moving = speed > 0.3
    idx = np.maximum.accumulate(np.where(moving, np.arange(len(t)), -1)) if len(t) else np.zeros(0, dtype=int)
    yaw = np.where(idx >= 0, course[np.maximum(idx, 0)], 0.0)
    pitch = -np.asarray(col["tilt"], dtype=float)
    rate = (lambda a: np.gradient(a, t)) if len(t) > 1 else (lambda a: np.zeros_like(a))
    yaw_rate = rate(np.unwrap(yaw))
    return {"roll_rad": np.zeros(len(t)), "pitch_rad": pitch, "yaw_rad": yaw, "rollspeed": np.zeros(len(t)),
            "pitchspeed": rate(pitch), "yawspeed": yaw_rate, "heading_deg": np.round(np.degrees(yaw)).astype(int) % 360,
            "groundspeed_m_s": speed}


def _hover_reference_w(col: dict) -> float:
    """Propulsion power shown as 50 % throttle: the median while hovering, else over the series."""
    p = col["propulsion_w"]
    ref = np.median(p[col["hover"] > 0]) if np.any(col["hover"] > 0) else np.median(p) if len(p) else 0.0
    return float(ref) if np.isfinite(ref) and ref > 0 else 1.0


def mavlink_table(ts: pd.DataFrame, home: GeoPoint = DEFAULT_HOME, ground_gap_m: float = 0.0,
                  t_out=None, track=None, drawn0: tuple[float, float] = (0.0, 0.0),
                  hover_w: float | None = None) -> pd.DataFrame:
    """Mission time series -> rows in MAVLink wire units (integers where the spec has them).

    ``ts`` needs the columns t_s, x_m, y_m, z_m (receiver coil in the pad frame, pad = ``home``),
    lm_h, i2_amp_a, d_short, battery_v, battery_current_a (+ = charging), soc; i1_amp_a,
    rect_current_a, charge_cmd_a, tx_on, propulsion_w and phase are used when present. ``t_out``:
    the times to report (default the series' own samples). The drone's altitude is the coil height
    less ``ground_gap_m`` (the coil's height when landed), so a replay of the telemetry (which adds
    the gap back) sees the same coil height. ``track``: ``(t_s, pos_m[, tilt_rad])`` of the
    trajectory the mission flew, for positions, velocities and attitude (the runner's series holds
    them only at its coarse steps in transit). ``drawn0``: net charge [C] and energy [J] drawn
    before this series (follow mode's earlier chunks). ``hover_w``: the propulsion power shown as
    50 % throttle (default :func:`_hover_reference_w`). The one place where the sender converts units.
    """
    missing = [c for c in _REQUIRED if c not in ts]
    if missing:
        raise ValueError(f"time series lacks the columns {missing}; needs {list(_REQUIRED)}")
    t = ts["t_s"].to_numpy(float)
    if len(t) < 1 or not np.all(np.diff(t) > 0):
        raise ValueError("time series t_s must be non-empty and strictly increasing")
    col = _columns(ts, track)
    ref_w = _hover_reference_w(col) if hover_w is None else float(hover_w)
    t_out = t if t_out is None else np.asarray(t_out, dtype=float)
    col = _at(col, t, t_out)
    col.update(_attitude(col, t_out))
    col["drawn_c"] = col["drawn_c"] + drawn0[0]
    col["drawn_j"] = col["drawn_j"] + drawn0[1]
    return _wire(col, t_out, home, ground_gap_m, ref_w)


def _wire(col: dict, t: np.ndarray, home: GeoPoint, ground_gap_m: float, hover_w: float) -> pd.DataFrame:
    """Columns at the report times -> the MAVLink wire table (see :func:`mavlink_table`)."""
    height = np.maximum(col["z_m"] - ground_gap_m, 0.0)
    lat, lon, alt = enu_to_geodetic(col["x_m"], col["y_m"], height, home)
    i_a = col["battery_current_a"]
    cur_ca = np.clip(np.round(-i_a * 100.0), -_INT16, _INT16).astype(int)
    cur_ca[cur_ca == -1] = -2                                 # -1 means "not measured" on the wire
    soc = np.clip(col["soc"], 0.0, 1.0)
    m = mavutil().mavlink
    state = np.select([i_a > _CHARGING_A, soc < 0.05, soc < 0.10, soc < 0.20],
                      [m.MAV_BATTERY_CHARGE_STATE_CHARGING, m.MAV_BATTERY_CHARGE_STATE_EMERGENCY,
                       m.MAV_BATTERY_CHARGE_STATE_CRITICAL, m.MAV_BATTERY_CHARGE_STATE_LOW],
                      m.MAV_BATTERY_CHARGE_STATE_OK)
    consumed = [np.clip(np.round(v), -2**31 + 1, 2**31 - 1).astype(np.int64)
                for v in (col["drawn_c"] / 3.6, col["drawn_j"] / 100.0)]
    for c in consumed:
        c[c == -1] = -2                                       # -1 means "not provided"
    d = col["d_short"]
    return pd.DataFrame({
        "t_s": t, "time_boot_ms": np.round(t * 1e3).astype(np.int64) % 2**32,
        "lat_e7": np.round(lat * 1e7).astype(np.int64), "lon_e7": np.round(lon * 1e7).astype(np.int64),
        "alt_mm": np.round(alt * 1e3).astype(np.int64), "relative_alt_mm": np.round(height * 1e3).astype(np.int64),
        "alt_m": alt, "climb_m_s": col["vz"],
        "vn_cm_s": np.clip(np.round(col["vy"] * 100), -_INT16, _INT16).astype(int),
        "ve_cm_s": np.clip(np.round(col["vx"] * 100), -_INT16, _INT16).astype(int),
        "vd_cm_s": np.clip(np.round(-col["vz"] * 100), -_INT16, _INT16).astype(int),
        "ground_speed_cm_s": np.clip(np.round(col["groundspeed_m_s"] * 100), 0, _UINT16_MAX - 1).astype(int),
        **{k: col[k] for k in ("roll_rad", "pitch_rad", "yaw_rad", "rollspeed", "pitchspeed", "yawspeed",
                               "heading_deg", "groundspeed_m_s")},
        "throttle_pct": np.clip(np.round(50.0 * col["propulsion_w"] / hover_w), 0, 100).astype(int),
        "voltage_mv": np.clip(np.round(col["battery_v"] * 1e3), 1, 10 * (_UINT16_MAX - 1)).astype(int),
        "current_ca": cur_ca, "consumed_mah": consumed[0], "consumed_hj": consumed[1],
        "remaining_pct": np.round(soc * 100).astype(int), "charge_state": state.astype(int),
        "armed": np.ones(len(t), dtype=bool),  # the simulated drone flies the whole mission
        "custom_mode": np.select([col["landing"] > 0, col["hover"] > 0], [COPTER_MODES["LAND"], COPTER_MODES["LOITER"]],
                                 COPTER_MODES["AUTO"]).astype(int),
        "landed_state": col["landed_state"].astype(int),
        **gps_quality(t),
        "i2_a": col["i2_amp_a"], "i1_a": col["i1_amp_a"], "d_short": d, "lm_uh": col["lm_h"] * 1e6,
        "sbar_mode": np.where(d <= 0.0, 0.0, np.where(d >= 1.0, 2.0, 1.0)), "pad_on": (col["tx_on"] > 0) * 1.0,
        "charge_cmd_a": col["charge_cmd_a"], "rect_a": col["rect_current_a"],
    })


def gps_quality(t_s) -> dict:
    """GPS_RAW_INT quality fields at times ``t_s`` [s] as a receiver with a good sky view reports them:
    satellites 10..14, HDOP 0.8..1.2 and VDOP 1.2..1.6 (eph / epv in cm units, i.e. 80..120 and
    120..160), drifting slowly (periods of minutes, as constellations move; deterministic)."""
    t = np.asarray(t_s, dtype=float)
    wave = np.sin(2 * np.pi * t / 300.0)
    return {"sats": np.round(12 + 2 * wave).astype(int),
            "eph_cm": np.round(100 - 20 * np.sin(2 * np.pi * t / 240.0 + 1.0)).astype(int),
            "epv_cm": np.round(140 - 20 * np.sin(2 * np.pi * t / 200.0 + 2.0)).astype(int)}


def _cells_mv(voltage_mv: int) -> list[int]:
    """BATTERY_STATUS voltages[10]: the pack in cell 0 if it fits a uint16, else split over cells."""
    cells, left = [], int(voltage_mv)
    while left > 0 and len(cells) < 10:
        cells.append(min(left, _UINT16_MAX - 1))
        left -= cells[-1]
    return cells + [_UINT16_MAX] * (10 - len(cells))


_STREAM_CLASSES: tuple = ()   # pymavlink's (mavtcp, mavtcpin), resolved once (mavutil() costs ~1 us a frame)


def _stream_classes() -> tuple:
    global _STREAM_CLASSES
    if not _STREAM_CLASSES:
        mu = mavutil()
        _STREAM_CLASSES = (mu.mavtcp, mu.mavtcpin)
    return _STREAM_CLASSES


def _send_stream(conn, sock, frame: bytes) -> bool:
    """``frame`` on the non-blocking TCP socket ``sock`` of ``conn``. A send may take part of a frame: its bytes are
    on the wire, so the rest is kept (``conn.unsent``) and goes first; a frame that finds it still unsent is dropped
    whole (the ground station reads slower than we send). Whether the frame went (or is under way) to the peer."""
    held, rest = getattr(conn, "unsent", (None, b""))
    if held is not sock:                    # a new connection (tcpin: another client): the old rest is void
        rest = b""
    try:
        if rest:
            rest = rest[sock.send(rest):]
        if not rest:
            rest = frame[sock.send(frame):]
            conn.unsent = (sock, rest)
            return True
    except BlockingIOError:
        pass
    conn.unsent = (sock, rest)
    return False


def close_link(conn, timeout_s: float = 1.0) -> None:
    """Close ``conn``, first sending (blocking, up to ``timeout_s``) a TCP frame's rest still unsent
    (:func:`_send_stream`), so that the stream does not end inside a frame."""
    held, rest = getattr(conn, "unsent", (None, b""))
    if rest and held is not None and held is getattr(conn, "port", None):
        try:
            held.settimeout(timeout_s)
            held.sendall(rest)
        except OSError:
            pass
    conn.close()


def write_frame(conn, frame: bytes) -> bool:
    """Write one frame on ``conn``; whether it went to a peer (:func:`link_has_peer`). A TCP ground station
    that has closed the connection is written to no more: pymavlink printed "Connection reset or closed by
    peer on TCP socket" on stdout for every frame after it (4,279 lines in a 30 s stream). On TCP a frame is
    never sent in part (:func:`_send_stream`)."""
    tcp, tcpin = _STREAM_CLASSES or _stream_classes()
    if isinstance(conn, tcp):
        if getattr(conn, "peer_closed", False) or conn.port is None:
            return False
        try:
            return _send_stream(conn, conn.port, frame)
        except OSError:                      # EPIPE, ECONNRESET: it went away
            conn.peer_closed = True
            return False
    if isinstance(conn, tcpin):
        if conn.port is None:                # no ground station connected (yet, or any more)
            return False
        try:
            return _send_stream(conn, conn.port, frame)
        except OSError:                      # it went away: listen for the next (as pymavlink's write does)
            conn.port.close()
            conn.port = None
            conn.fd = conn.listen.fileno()
            return False
    conn.write(frame)
    return link_has_peer(conn)


def send_msgs(mav, msgs, conn, writer, t_log_s: float) -> tuple[int, int]:
    """Pack and send each message on ``conn`` and log it to ``writer`` (either may be None) with
    timestamp ``t_log_s`` [s since the epoch]; returns the number of frames and of those delivered to a
    peer on ``conn`` (:func:`write_frame`). A listening ``conn`` is read first (:func:`poll_link`)."""
    poll_link(conn)
    delivered = 0
    for msg in msgs:
        frame = msg.pack(mav)
        mav.seq = (mav.seq + 1) % 256
        if conn is not None:
            delivered += write_frame(conn, frame)
        if writer is not None:
            writer.write(frame, t_log_s)
    return len(msgs), delivered


def encode_heartbeat(mav, row):
    """HEARTBEAT as ArduCopter sends it (see the module docstring) for one :func:`mavlink_table` row;
    ``row.armed`` False: disarmed (no SAFETY_ARMED flag, system status STANDBY)."""
    m = mavutil().mavlink
    base = m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | m.MAV_MODE_FLAG_STABILIZE_ENABLED \
        | m.MAV_MODE_FLAG_GUIDED_ENABLED | m.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED \
        | (m.MAV_MODE_FLAG_SAFETY_ARMED if row.armed else 0)
    return mav.heartbeat_encode(m.MAV_TYPE_QUADROTOR, m.MAV_AUTOPILOT_ARDUPILOTMEGA, base, int(row.custom_mode),
                                m.MAV_STATE_ACTIVE if row.armed else m.MAV_STATE_STANDBY)


def encode_tick(mav, row) -> list:
    """The messages of one telemetry tick from one :func:`mavlink_table` row (MAVLink 2 objects)."""
    m = mavutil().mavlink
    r = row
    ms = int(r.time_boot_ms)
    sensors = m.MAV_SYS_STATUS_SENSOR_3D_GYRO | m.MAV_SYS_STATUS_SENSOR_3D_ACCEL | m.MAV_SYS_STATUS_SENSOR_GPS \
        | m.MAV_SYS_STATUS_SENSOR_BATTERY | m.MAV_SYS_STATUS_PREARM_CHECK
    health = (sensors if r.remaining_pct >= 5 else sensors & ~m.MAV_SYS_STATUS_SENSOR_BATTERY) \
        | m.MAV_SYS_STATUS_GEOFENCE                          # no fence: healthy (no breach), as ArduPilot
    msgs = [mav.sys_status_encode(sensors, sensors, health, 0, min(int(r.voltage_mv), _UINT16_MAX - 1),
                                  int(r.current_ca), int(r.remaining_pct), 0, 0, 0, 0, 0, 0),
            mav.battery_status_encode(0, m.MAV_BATTERY_FUNCTION_ALL, m.MAV_BATTERY_TYPE_LIPO, _INT16,
                                      _cells_mv(r.voltage_mv), int(r.current_ca), int(r.consumed_mah),
                                      int(r.consumed_hj), int(r.remaining_pct), 0, int(r.charge_state)),
            # the fix first: a reader checks each position against the last fix report
            mav.gps_raw_int_encode(ms * 1000, m.GPS_FIX_TYPE_3D_FIX, int(r.lat_e7), int(r.lon_e7), int(r.alt_mm),
                                   int(r.eph_cm), int(r.epv_cm), int(r.ground_speed_cm_s), int(r.heading_deg) * 100,
                                   int(r.sats)),
            mav.global_position_int_encode(ms, int(r.lat_e7), int(r.lon_e7), int(r.alt_mm), int(r.relative_alt_mm),
                                           int(r.vn_cm_s), int(r.ve_cm_s), int(r.vd_cm_s),
                                           int(r.heading_deg) * 100),
            mav.attitude_encode(ms, float(r.roll_rad), float(r.pitch_rad), float(r.yaw_rad), float(r.rollspeed),
                                float(r.pitchspeed), float(r.yawspeed)),
            mav.vfr_hud_encode(float(r.groundspeed_m_s), float(r.groundspeed_m_s), int(r.heading_deg),
                               int(r.throttle_pct), float(r.alt_m), float(r.climb_m_s))]
    for name, (column, _) in NVF_NAMES.items():
        msgs.append(mav.named_value_float_encode(ms, name.encode(), float(getattr(r, column))))
    return msgs


def heartbeat_msgs(mav, row) -> list:
    """HEARTBEAT and EXTENDED_SYS_STATE (landed state) for one :func:`mavlink_table` row."""
    m = mavutil().mavlink
    return [encode_heartbeat(mav, row),
            mav.extended_sys_state_encode(m.MAV_VTOL_STATE_UNDEFINED, int(getattr(row, "landed_state", 2)))]


def landing_rows(last) -> list[tuple[float, object]]:
    """The end of a stream (module docstring): (seconds after the last tick, row) of the landing
    HEARTBEAT (only if ``last`` was not on the ground) and of the disarm."""
    out = []
    if int(getattr(last, "landed_state", 2)) != _LANDED_STATE["ground"]:
        out.append((0.5, last._replace(custom_mode=COPTER_MODES["LAND"], landed_state=_LANDED_STATE["land"])))
    out.append((1.0, last._replace(custom_mode=COPTER_MODES["LAND"], landed_state=_LANDED_STATE["ground"],
                                   armed=False)))
    return out


def schedule(tick_t: np.ndarray, hb_after: float = -np.inf) -> list[tuple[float, int, bool]]:
    """Send events (time [s], tick index, is_heartbeat) in time order: every tick, and a
    HEARTBEAT at each whole second ``n`` of simulated time with ``hb_after < n <= tick_t[-1]``
    (``hb_after`` -inf: from ``tick_t[0]`` on), carrying the state of the latest tick at or before
    it (or the first tick, for a second just before it)."""
    tick_t = np.asarray(tick_t, dtype=float)
    if not len(tick_t):
        return []
    lo = math.ceil(tick_t[0] - 1e-9) if not math.isfinite(hb_after) else math.floor(hb_after) + 1
    hb = np.arange(lo, math.floor(tick_t[-1] + 1e-9) + 1, dtype=float)
    k = np.clip(np.searchsorted(tick_t, hb + 1e-9, side="right") - 1, 0, len(tick_t) - 1)
    events = [(float(tk), i, False) for i, tk in enumerate(tick_t)] + [(float(n), int(i), True) for n, i in zip(hb, k)]
    return sorted(events, key=lambda e: (e[0], not e[2]))


@dataclass
class StreamStats:
    """What :func:`stream` did: ticks and frames sent, simulated and wall seconds, per-type counts."""

    ticks: int
    frames: int
    sim_s: float
    wall_s: float
    counts: dict
    delivered: int = 0      # frames that went to a peer (:func:`write_frame`)


#: slowest pacing, simulated seconds per wall second (a slower one waits past what time.sleep takes:
#: ``--speed 1e-300`` ended in an OverflowError traceback)
MIN_SPEED = 1e-3


def check_pacing(rate_hz, speed) -> None:
    """``rate_hz`` in (0, 1000] Hz and ``speed`` in [:data:`MIN_SPEED`, inf] (inf: as fast as possible),
    else ``ValueError`` naming the value and its range."""
    if not (math.isfinite(rate_hz) and 0 < rate_hz <= 1000):
        raise ValueError(f"rate={rate_hz!r} is invalid; valid range: (0, 1000] Hz")
    if not (speed >= MIN_SPEED):
        raise ValueError(f"speed={speed!r} is invalid; valid range: [{MIN_SPEED:g}, inf] simulated seconds per wall "
                         "second (inf = as fast as possible)")


def _check_stream(rate_hz, speed, connect, tlog, conn):
    check_pacing(rate_hz, speed)
    if connect is None and tlog is None and conn is None:
        raise ValueError("nothing to do: give a connection (--connect) and/or a --tlog file")


def stream(ts: pd.DataFrame, *, connect: str | None = None, rate_hz: float = 10.0, speed: float = 1.0,
           home: GeoPoint = DEFAULT_HOME, tlog: str | Path | None = None, ground_gap_m: float = 0.0,
           duration_s: float | None = None, start_epoch_s: float | None = None, conn=None,
           track=None, progress: bool = False, sysid: int = 1, compid: int = 1) -> StreamStats:
    """Send the mission time series ``ts`` as MAVLink 2 telemetry (and/or write it to ``tlog``).

    Ticks are at ``t_k = t_0 + k / rate_hz`` of simulation time, HEARTBEATs at every whole second
    of it (:func:`schedule`), each paced at its simulated time / ``speed`` of wall time (``speed =
    inf``: as fast as possible). At most ``duration_s * rate_hz + 1`` ticks (default: the whole
    series). ``conn``: an open pymavlink connection to use instead of opening ``connect``;
    ``track``: ``(t_s, pos_m[, tilt_rad])`` of the flown trajectory (see :func:`mavlink_table`);
    ``sysid`` / ``compid``: the vehicle's MAVLink ids. The stream ends with the vehicle landing and
    disarming (:func:`landing_rows`, up to 1 s of simulated time after the last tick).
    """
    _check_stream(rate_hz, speed, connect, tlog, conn)
    sysid, compid = check_ids(sysid, compid)
    mu = mavutil()
    t = ts["t_s"].to_numpy(float)
    span = float(t[-1] - t[0]) if duration_s is None else min(float(duration_s), float(t[-1] - t[0]))
    n_ticks = int(math.floor(span * rate_hz + 1e-9)) + 1
    sim_t = np.arange(n_ticks) / rate_hz
    table = mavlink_table(ts, home, ground_gap_m, t_out=t[0] + sim_t, track=track)
    rows = list(table.itertuples(index=False))
    events = [(sim_s, rows[k], hb) for sim_s, k, hb in schedule(sim_t)]
    events += [(float(sim_t[-1]) + dt, row, True) for dt, row in landing_rows(rows[-1])]
    own = conn is None and connect is not None
    if own:
        conn = open_link(connect, sysid, compid)
    mav = mu.mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    writer = TlogWriter(tlog) if tlog is not None else None
    epoch0 = time.time() if start_epoch_s is None else float(start_epoch_s)
    counts: dict[str, int] = {}
    frames = delivered = 0
    wall0 = time.monotonic()
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=n_ticks, unit="tick", desc="telemetry")
    ended = False
    try:
        for sim_s, row, hb in events:
            if math.isfinite(speed):
                delay = wall0 + sim_s / speed - time.monotonic()
                if delay > 0:
                    time.sleep(min(delay, 1.0 / speed + 1.0))
            msgs = heartbeat_msgs(mav, row) if hb else encode_tick(mav, row)
            n, n_out = send_msgs(mav, msgs, conn, writer, epoch0 + sim_s)
            frames += n
            delivered += n_out
            for msg in msgs:
                counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
            if bar is not None and not hb:
                bar.update(1)
        ended = True
    except BaseException as exc:
        if writer is not None:
            writer.abort(exc)   # the frames so far as NAME.partial.tlog, an existing NAME left as it was
        raise
    finally:
        if writer is not None and ended:
            writer.close()
        if own:
            close_link(conn)
        if bar is not None:
            bar.close()
    return StreamStats(ticks=n_ticks, frames=frames, sim_s=float(sim_t[-1]), wall_s=time.monotonic() - wall0,
                       counts=counts, delivered=delivered)
