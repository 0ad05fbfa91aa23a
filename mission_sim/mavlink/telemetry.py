"""Live MAVLink 2 telemetry of a simulated mission and a .tlog writer (``--follow``: follow.py).

:func:`stream` sends, for each tick of ``rate_hz`` on the simulation clock, paced at ``speed``
times real time:

===================  ============================================================================
message              content (from the mission time series; units as the MAVLink spec)
===================  ============================================================================
HEARTBEAT            quadrotor, generic autopilot, armed (the mission is flown throughout); 1 Hz of
                     wall time
SYS_STATUS           battery voltage [mV], current [cA, + = discharging], remaining [%]
BATTERY_STATUS       pack voltage in cell 0 [mV], current [cA], consumed [mAh, hJ], remaining [%],
                     charge_state CHARGING (7) while the battery current is a net charge, else
                     OK / LOW / CRITICAL / EMERGENCY by state of charge (20 / 10 / 5 %)
GLOBAL_POSITION_INT  position about ``home`` [1e-7 deg, mm], relative_alt [mm] (coil height less the
                     ground gap: 0 when landed), velocity NED [cm/s]
GPS_RAW_INT          3D fix at the same position (ground stations read the fix from it)
NAMED_VALUE_FLOAT    I2 (secondary current envelope amplitude, A), d_short (short duty, 0..1),
                     Lm (mutual inductance, uH)
===================  ============================================================================

A ``.tlog`` is written as pymavlink reads it: for each frame an 8-byte big-endian timestamp in
microseconds since the Unix epoch, then the frame bytes (the timestamps are the simulation clock
from the start epoch, so a faster-than-real-time run still records the simulated timeline).

Every network loop here is bounded in both message count and wall time.
"""

from __future__ import annotations

import math
import struct
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .geodesy import GeoPoint, enu_to_geodetic
from .logs import mavutil

__all__ = ["DEFAULT_HOME", "TlogWriter", "mavlink_table", "encode_tick", "stream", "StreamStats",
           "check_connect", "CONNECT_FORMAT"]

#: ArduPilot SITL's default home (CMAC, Canberra), where two of the real logs were flown.
DEFAULT_HOME = GeoPoint(-35.363261, 149.165230, 584.0)
CONNECT_FORMAT = "udpout:HOST:PORT, udpin:HOST:PORT, udp:HOST:PORT, tcp:HOST:PORT or tcpin:HOST:PORT"
_CHARGING_A = 0.05          # net battery current above this [A] reports CHARGING
_INT16 = 32767
_UINT16_MAX = 65535
_MOTION = ("x_m", "y_m", "z_m", "vx", "vy", "vz")
_REQUIRED = ("t_s", "x_m", "y_m", "z_m", "lm_h", "i2_amp_a", "d_short", "battery_v", "battery_current_a", "soc")


def check_connect(text: str, name: str = "--connect") -> str:
    """Validate a pymavlink connection string of the supported kinds; ``ValueError`` names the format."""
    kind, _, rest = str(text).partition(":")
    host, _, port = rest.rpartition(":")
    if kind not in ("udpout", "udpin", "udp", "tcp", "tcpin") or not host or not port.isdigit() \
            or not 0 < int(port) < 65536:
        raise ValueError(f"{name} {text!r} is invalid; valid format: {CONNECT_FORMAT}")
    return text


class TlogWriter:
    """Append MAVLink frames to a .tlog (8-byte big-endian microsecond timestamp + frame)."""

    def __init__(self, path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = open(self.path, "wb")
        self.n_frames = 0

    def write(self, frame: bytes, t_epoch_s: float) -> None:
        self._fh.write(struct.pack(">Q", int(round(t_epoch_s * 1e6))) + frame)
        self.n_frames += 1

    def close(self) -> None:
        self._fh.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def mavlink_table(ts: pd.DataFrame, home: GeoPoint = DEFAULT_HOME, ground_gap_m: float = 0.0,
                  t_out=None, track=None) -> pd.DataFrame:
    """Mission time series -> rows in MAVLink wire units (integers where the spec has them).

    ``ts`` needs the columns t_s, x_m, y_m, z_m (receiver coil in the pad frame, pad = ``home``),
    lm_h, i2_amp_a, d_short, battery_v, battery_current_a (+ = charging), soc. ``t_out``: the
    times to report (default the series' own samples): positions and velocities are interpolated,
    the electrical state is the latest sample at or before (never a value the simulation did not
    produce). The drone's
    altitude is the coil height less ``ground_gap_m`` (the coil's height when landed), so a
    replay of the telemetry (which adds the gap back) sees the same coil height. ``track``:
    ``(t_s, pos_m)`` of the trajectory the mission flew, for positions and velocities (the
    runner's time series holds them only at its coarse steps in transit). This is the one place
    where the sender converts units.
    """
    missing = [c for c in _REQUIRED if c not in ts]
    if missing:
        raise ValueError(f"time series lacks the columns {missing}; needs {list(_REQUIRED)}")
    t = ts["t_s"].to_numpy(float)
    if len(t) < 1 or not np.all(np.diff(t) > 0):
        raise ValueError("time series t_s must be non-empty and strictly increasing")
    col = {c: ts[c].to_numpy(float) for c in _REQUIRED}
    tp = t
    if track is not None:
        tp, pos = np.asarray(track[0], dtype=float), np.asarray(track[1], dtype=float)
        for i, c in enumerate(("x_m", "y_m", "z_m")):
            col[c] = np.interp(t, tp, pos[:, i])
    for i, c in enumerate(("x_m", "y_m", "z_m")):
        src = col[c] if track is None else pos[:, i]
        v = np.gradient(src, tp) if len(tp) > 1 else np.zeros_like(tp)
        col["v" + c[0]] = v if track is None else np.interp(t, tp, v)
    if track is not None and t_out is not None:   # positions straight from the track at the ticks
        t_out = np.asarray(t_out, dtype=float)
        exact = {c: np.interp(t_out, tp, pos[:, i]) for i, c in enumerate(("x_m", "y_m", "z_m"))}
        exact.update({"v" + c[0]: np.interp(t_out, tp, np.gradient(pos[:, i], tp)) for i, c in enumerate("xyz")})
    else:
        exact = {}
    dt = np.diff(t, prepend=t[0])
    col["drawn_c"] = np.cumsum(-col["battery_current_a"] * dt)                       # net charge drawn [C]
    col["drawn_j"] = np.cumsum(-col["battery_v"] * col["battery_current_a"] * dt)    # net energy drawn [J]
    if t_out is not None:
        t_out = np.asarray(t_out, dtype=float)
        held = np.clip(np.searchsorted(t, t_out + 1e-9, side="right") - 1, 0, len(t) - 1)
        col = {k: (np.interp(t_out, t, v) if k in _MOTION else v[held]) for k, v in col.items()}
        col.update(exact)
        t = t_out
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
    return pd.DataFrame({
        "t_s": t,
        "time_boot_ms": np.round(t * 1e3).astype(np.int64) % 2**32,
        "lat_e7": np.round(lat * 1e7).astype(np.int64), "lon_e7": np.round(lon * 1e7).astype(np.int64),
        "alt_mm": np.round(alt * 1e3).astype(np.int64), "relative_alt_mm": np.round(height * 1e3).astype(np.int64),
        "vn_cm_s": np.clip(np.round(col["vy"] * 100), -_INT16, _INT16).astype(int),
        "ve_cm_s": np.clip(np.round(col["vx"] * 100), -_INT16, _INT16).astype(int),
        "vd_cm_s": np.clip(np.round(-col["vz"] * 100), -_INT16, _INT16).astype(int),
        "ground_speed_cm_s": np.clip(np.round(np.hypot(col["vx"], col["vy"]) * 100), 0, _UINT16_MAX - 1).astype(int),
        "voltage_mv": np.clip(np.round(col["battery_v"] * 1e3), 1, 10 * (_UINT16_MAX - 1)).astype(int),
        "current_ca": cur_ca,
        "consumed_mah": np.clip(np.round(col["drawn_c"] / 3.6), 0, 2**31 - 1).astype(np.int64),
        "consumed_hj": np.clip(np.round(col["drawn_j"] / 100.0), 0, 2**31 - 1).astype(np.int64),
        "remaining_pct": np.round(soc * 100).astype(int),
        "charge_state": state.astype(int),
        "armed": np.ones(len(t), dtype=bool),  # the simulated drone flies the whole mission
        "i2_a": col["i2_amp_a"], "d_short": col["d_short"], "lm_uh": col["lm_h"] * 1e6,
    })


def _cells_mv(voltage_mv: int) -> list[int]:
    """BATTERY_STATUS voltages[10]: the pack in cell 0 if it fits a uint16, else split over cells."""
    cells, left = [], int(voltage_mv)
    while left > 0 and len(cells) < 10:
        cells.append(min(left, _UINT16_MAX - 1))
        left -= cells[-1]
    return cells + [_UINT16_MAX] * (10 - len(cells))


def send_tick(mav, row, heartbeat: bool, conn, writer, t_log_s: float) -> list:
    """Encode one tick (:func:`encode_tick`), send each frame on ``conn`` and log it to ``writer``
    (either may be None) with timestamp ``t_log_s`` [s since the epoch]; returns the messages."""
    msgs = encode_tick(mav, row, heartbeat)
    for msg in msgs:
        frame = msg.pack(mav)
        mav.seq = (mav.seq + 1) % 256
        if conn is not None:
            conn.write(frame)
        if writer is not None:
            writer.write(frame, t_log_s)
    return msgs


def encode_tick(mav, row, heartbeat: bool) -> list:
    """The messages of one telemetry tick from one :func:`mavlink_table` row (MAVLink 2 objects)."""
    m = mavutil().mavlink
    r = row
    msgs = []
    if heartbeat:
        base = m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (m.MAV_MODE_FLAG_SAFETY_ARMED if r.armed else 0)
        msgs.append(mav.heartbeat_encode(m.MAV_TYPE_QUADROTOR, m.MAV_AUTOPILOT_GENERIC, base, 0,
                                         m.MAV_STATE_ACTIVE if r.armed else m.MAV_STATE_STANDBY))
    sensors = m.MAV_SYS_STATUS_SENSOR_BATTERY | m.MAV_SYS_STATUS_SENSOR_GPS
    msgs.append(mav.sys_status_encode(sensors, sensors, sensors, 0, min(int(r.voltage_mv), _UINT16_MAX - 1),
                                      int(r.current_ca), int(r.remaining_pct), 0, 0, 0, 0, 0, 0))
    msgs.append(mav.battery_status_encode(0, m.MAV_BATTERY_FUNCTION_ALL, m.MAV_BATTERY_TYPE_LIPO, _INT16,
                                          _cells_mv(r.voltage_mv), int(r.current_ca), int(r.consumed_mah),
                                          int(r.consumed_hj), int(r.remaining_pct), 0, int(r.charge_state)))
    # the fix first: a reader checks each position against the last fix report
    msgs.append(mav.gps_raw_int_encode(int(r.time_boot_ms) * 1000, m.GPS_FIX_TYPE_3D_FIX, int(r.lat_e7),
                                       int(r.lon_e7), int(r.alt_mm), _UINT16_MAX, _UINT16_MAX,
                                       int(r.ground_speed_cm_s), _UINT16_MAX, 255))
    msgs.append(mav.global_position_int_encode(int(r.time_boot_ms), int(r.lat_e7), int(r.lon_e7), int(r.alt_mm),
                                               int(r.relative_alt_mm), int(r.vn_cm_s), int(r.ve_cm_s),
                                               int(r.vd_cm_s), _UINT16_MAX))
    for name, value in ((b"I2", r.i2_a), (b"d_short", r.d_short), (b"Lm", r.lm_uh)):
        msgs.append(mav.named_value_float_encode(int(r.time_boot_ms), name, float(value)))
    return msgs


@dataclass
class StreamStats:
    """What :func:`stream` did: ticks and frames sent, simulated and wall seconds, per-type counts."""

    ticks: int
    frames: int
    sim_s: float
    wall_s: float
    counts: dict


def stream(ts: pd.DataFrame, *, connect: str | None = None, rate_hz: float = 10.0, speed: float = 1.0,
           home: GeoPoint = DEFAULT_HOME, tlog: str | Path | None = None, ground_gap_m: float = 0.0,
           duration_s: float | None = None, start_epoch_s: float | None = None, conn=None,
           track=None, progress: bool = False) -> StreamStats:
    """Send the mission time series ``ts`` as MAVLink 2 telemetry (and/or write it to ``tlog``).

    Ticks are at ``t_k = t_0 + k / rate_hz`` of simulation time (the series interpolated there),
    paced at ``t_k / speed`` of wall time (``speed = inf``: as fast as possible). The
    loop runs at most ``duration_s * rate_hz + 1`` ticks (default: the whole series).
    ``conn``: an open pymavlink connection to use instead of opening ``connect``; ``track``:
    ``(t_s, pos_m)`` of the flown trajectory for the positions (see :func:`mavlink_table`).
    """
    if not (math.isfinite(rate_hz) and 0 < rate_hz <= 1000):
        raise ValueError(f"rate={rate_hz!r} is invalid; valid range: (0, 1000] Hz")
    if not (speed > 0):
        raise ValueError(f"speed={speed!r} is invalid; valid range: (0, inf] (inf = as fast as possible)")
    if connect is None and tlog is None and conn is None:
        raise ValueError("nothing to do: give a connection (--connect) and/or a --tlog file")
    mu = mavutil()
    t = ts["t_s"].to_numpy(float)
    span = float(t[-1] - t[0]) if duration_s is None else min(float(duration_s), float(t[-1] - t[0]))
    n_ticks = int(math.floor(span * rate_hz + 1e-9)) + 1
    table = mavlink_table(ts, home, ground_gap_m, t_out=t[0] + np.arange(n_ticks) / rate_hz, track=track)
    own = conn is None and connect is not None
    if own:
        conn = mu.mavlink_connection(check_connect(connect), source_system=1, source_component=1)
    mav = mu.mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    writer = TlogWriter(tlog) if tlog is not None else None
    epoch0 = time.time() if start_epoch_s is None else float(start_epoch_s)
    counts: dict[str, int] = {}
    frames, last_hb = 0, -math.inf
    wall0 = time.monotonic()
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=n_ticks, unit="tick", desc="telemetry")
    try:
        for k in range(n_ticks):
            sim_k = k / rate_hz
            if math.isfinite(speed):
                delay = wall0 + sim_k / speed - time.monotonic()
                if delay > 0:
                    time.sleep(min(delay, 1.0 / rate_hz / speed + 1.0))
            now = time.monotonic()
            hb = now - last_hb >= 1.0 or (not math.isfinite(speed) and k % max(int(round(rate_hz)), 1) == 0)
            if hb:
                last_hb = now
            row = table.iloc[k]
            for msg in send_tick(mav, row, hb, conn, writer, epoch0 + sim_k):
                name = msg.get_type()
                counts[name] = counts.get(name, 0) + 1
                frames += 1
            if bar is not None:
                bar.update(1)
    finally:
        if writer is not None:
            writer.close()
        if own:
            conn.close()
        if bar is not None:
            bar.close()
    return StreamStats(ticks=n_ticks, frames=frames, sim_s=(n_ticks - 1) / rate_hz, wall_s=time.monotonic() - wall0,
                       counts=counts)
