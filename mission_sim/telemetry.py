"""Live MAVLink 2 telemetry of a simulated mission, a .tlog writer, and reading a live vehicle.

:func:`stream` sends, for each tick of ``rate_hz`` on the simulation clock, paced at ``speed``
times real time:

===================  ============================================================================
message              content (from the mission time series; units as the MAVLink spec)
===================  ============================================================================
HEARTBEAT            quadrotor, generic autopilot, armed while airborne; 1 Hz of wall time
SYS_STATUS           battery voltage [mV], current [cA, + = discharging], remaining [%]
BATTERY_STATUS       pack voltage in cell 0 [mV], current [cA], consumed [mAh, hJ], remaining [%],
                     charge_state CHARGING (7) while the battery current is a net charge, else
                     OK / LOW / CRITICAL / EMERGENCY by state of charge (20 / 10 / 5 %)
GLOBAL_POSITION_INT  position about ``home`` [1e-7 deg, mm], relative_alt [mm], velocity NED [cm/s]
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

from .geodesy import GeoPoint, enu_to_geodetic, geodetic_to_enu
from .mavlink_io import mavutil

__all__ = ["DEFAULT_HOME", "TlogWriter", "mavlink_table", "encode_tick", "stream", "StreamStats",
           "follow", "FollowStats", "check_connect", "CONNECT_FORMAT"]

#: ArduPilot SITL's default home (CMAC, Canberra), where two of the real logs were flown.
DEFAULT_HOME = GeoPoint(-35.363261, 149.165230, 584.0)
CONNECT_FORMAT = "udpout:HOST:PORT, udpin:HOST:PORT, udp:HOST:PORT, tcp:HOST:PORT or tcpin:HOST:PORT"
_CHARGING_A = 0.05          # net battery current above this [A] reports CHARGING
_AIRBORNE_M = 0.5           # height above the pad coil beyond the ground gap that counts as airborne
_INT16 = 32767
_UINT16_MAX = 65535
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


def mavlink_table(ts: pd.DataFrame, home: GeoPoint = DEFAULT_HOME, ground_gap_m: float = 0.0) -> pd.DataFrame:
    """Mission time series -> one row per sample in MAVLink wire units (integers where the spec has them).

    ``ts`` needs the columns t_s, x_m, y_m, z_m (ENU about the pad = ``home``), lm_h, i2_amp_a,
    d_short, battery_v, battery_current_a (+ = charging), soc. This is the one place where the
    sender converts units.
    """
    missing = [c for c in _REQUIRED if c not in ts]
    if missing:
        raise ValueError(f"time series lacks the columns {missing}; needs {list(_REQUIRED)}")
    t = ts["t_s"].to_numpy(float)
    if len(t) < 1 or not np.all(np.diff(t) > 0):
        raise ValueError("time series t_s must be non-empty and strictly increasing")
    x, y, z = (ts[c].to_numpy(float) for c in ("x_m", "y_m", "z_m"))
    lat, lon, alt = enu_to_geodetic(x, y, z, home)
    vel = [np.gradient(a, t) if len(t) > 1 else np.zeros_like(t) for a in (x, y, z)]
    v_v = ts["battery_v"].to_numpy(float)
    i_a = ts["battery_current_a"].to_numpy(float)          # + = charging
    dt = np.diff(t, prepend=t[0])
    discharged_c = np.cumsum(-i_a * dt)                       # net charge drawn [C]
    drawn_j = np.cumsum(-v_v * i_a * dt)                      # net energy drawn [J]
    cur_ca = np.clip(np.round(-i_a * 100.0), -_INT16, _INT16).astype(int)
    cur_ca[cur_ca == -1] = -2                                 # -1 means "not measured" on the wire
    soc = np.clip(ts["soc"].to_numpy(float), 0.0, 1.0)
    m = mavutil().mavlink
    state = np.select([i_a > _CHARGING_A, soc < 0.05, soc < 0.10, soc < 0.20],
                      [m.MAV_BATTERY_CHARGE_STATE_CHARGING, m.MAV_BATTERY_CHARGE_STATE_EMERGENCY,
                       m.MAV_BATTERY_CHARGE_STATE_CRITICAL, m.MAV_BATTERY_CHARGE_STATE_LOW],
                      m.MAV_BATTERY_CHARGE_STATE_OK)
    return pd.DataFrame({
        "t_s": t,
        "time_boot_ms": np.round(t * 1e3).astype(np.int64) % 2**32,
        "lat_e7": np.round(lat * 1e7).astype(np.int64), "lon_e7": np.round(lon * 1e7).astype(np.int64),
        "alt_mm": np.round(alt * 1e3).astype(np.int64), "relative_alt_mm": np.round(z * 1e3).astype(np.int64),
        "vn_cm_s": np.clip(np.round(vel[1] * 100), -_INT16, _INT16).astype(int),
        "ve_cm_s": np.clip(np.round(vel[0] * 100), -_INT16, _INT16).astype(int),
        "vd_cm_s": np.clip(np.round(-vel[2] * 100), -_INT16, _INT16).astype(int),
        "ground_speed_cm_s": np.clip(np.round(np.hypot(vel[0], vel[1]) * 100), 0, _UINT16_MAX - 1).astype(int),
        "voltage_mv": np.clip(np.round(v_v * 1e3), 1, 10 * (_UINT16_MAX - 1)).astype(int),
        "current_ca": cur_ca,
        "consumed_mah": np.clip(np.round(discharged_c / 3.6), 0, 2**31 - 1).astype(np.int64),
        "consumed_hj": np.clip(np.round(drawn_j / 100.0), 0, 2**31 - 1).astype(np.int64),
        "remaining_pct": np.round(soc * 100).astype(int),
        "charge_state": state.astype(int),
        "armed": (z > ground_gap_m + _AIRBORNE_M),
        "i2_a": ts["i2_amp_a"].to_numpy(float), "d_short": ts["d_short"].to_numpy(float),
        "lm_uh": ts["lm_h"].to_numpy(float) * 1e6,
    })


def _cells_mv(voltage_mv: int) -> list[int]:
    """BATTERY_STATUS voltages[10]: the pack in cell 0 if it fits a uint16, else split over cells."""
    cells, left = [], int(voltage_mv)
    while left > 0 and len(cells) < 10:
        cells.append(min(left, _UINT16_MAX - 1))
        left -= cells[-1]
    return cells + [_UINT16_MAX] * (10 - len(cells))


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
           progress: bool = False) -> StreamStats:
    """Send the mission time series ``ts`` as MAVLink 2 telemetry (and/or write it to ``tlog``).

    Ticks are at ``t_k = t_0 + k / rate_hz`` of simulation time (the sample at or before ``t_k``
    is sent), paced at ``t_k / speed`` of wall time (``speed = inf``: as fast as possible). The
    loop runs at most ``duration_s * rate_hz + 1`` ticks (default: the whole series).
    ``conn``: an open pymavlink connection to use instead of opening ``connect``.
    """
    if not (math.isfinite(rate_hz) and 0 < rate_hz <= 1000):
        raise ValueError(f"rate={rate_hz!r} is invalid; valid range: (0, 1000] Hz")
    if not (speed > 0):
        raise ValueError(f"speed={speed!r} is invalid; valid range: (0, inf] (inf = as fast as possible)")
    if connect is None and tlog is None and conn is None:
        raise ValueError("nothing to do: give a connection (--connect) and/or a --tlog file")
    mu = mavutil()
    table = mavlink_table(ts, home, ground_gap_m)
    t = table["t_s"].to_numpy()
    span = float(t[-1] - t[0]) if duration_s is None else min(float(duration_s), float(t[-1] - t[0]))
    n_ticks = int(math.floor(span * rate_hz + 1e-9)) + 1
    idx = np.searchsorted(t, t[0] + np.arange(n_ticks) / rate_hz + 1e-9, side="right") - 1
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
            row = table.iloc[int(idx[k])]
            for msg in encode_tick(mav, row, hb):
                frame = msg.pack(mav)
                mav.seq = (mav.seq + 1) % 256
                if conn is not None:
                    conn.write(frame)
                if writer is not None:
                    writer.write(frame, epoch0 + sim_k)
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
    return StreamStats(ticks=n_ticks, frames=frames, sim_s=n_ticks / rate_hz, wall_s=time.monotonic() - wall0,
                       counts=counts)


@dataclass
class FollowStats:
    """What :func:`follow` did: positions received, chunks simulated, frames sent, wall seconds."""

    positions: int
    chunks: int
    frames: int
    wall_s: float
    final_soc: float | None
    home: GeoPoint | None


def _chunk_config(cfg, soc):
    """``cfg`` with the battery starting at ``soc`` (the previous chunk's final state of charge)."""
    from .config import apply_overrides, config_from_dict, config_to_dict
    return config_from_dict(apply_overrides(config_to_dict(cfg), {"battery.initial_soc": float(soc)}))


def follow(follow_connect: str, cfg, policy, run_mission, *, connect: str | None = None, rate_hz: float = 10.0,
           home: GeoPoint | None = None, tlog=None, max_wall_s: float = 60.0, chunk_s: float = 1.0,
           max_messages: int = 1_000_000, idle_timeout_s: float = 10.0, out_conn=None) -> FollowStats:
    """Drive the mission world from a live vehicle's GLOBAL_POSITION_INT and stream the result.

    Positions from ``follow_connect`` (e.g. ``udpin:127.0.0.1:14551``; lat = lon = 0, i.e. no fix,
    skipped) are timed by the receiver's clock and converted to the pad frame about ``home``
    (None: the first position received is the pad). Every ``chunk_s`` seconds the new stretch
    of track runs through ``run_mission(cfg, policy, trajectory=...)``, the battery carried
    over from chunk to chunk by its state of charge, and its telemetry is sent at ``rate_hz``,
    scheduled ``chunk_s`` behind the vehicle (the latency of this chunked scheme; the link's
    electrical state restarts each chunk). The loop ends after ``max_wall_s`` seconds,
    ``max_messages`` received messages or ``idle_timeout_s`` without a position.
    """
    from .trajectory import Trajectory

    mu = mavutil()
    vin = mu.mavlink_connection(check_connect(follow_connect, "--follow"), source_system=255, source_component=190)
    own_out = out_conn is None and connect is not None
    out = mu.mavlink_connection(check_connect(connect), source_system=1, source_component=1) if own_out else out_conn
    mav = mu.mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    writer = TlogWriter(tlog) if tlog is not None else None
    gap = float(cfg.mission.hover_gap_m)
    wall0 = time.monotonic()
    epoch0 = time.time()
    deadline = wall0 + float(max_wall_s)
    t_rx, pos = [], []
    chunk_start = 0                         # index of the first sample of the next chunk
    queue: list[tuple[float, object]] = []  # (send at wall offset, mavlink_table row)
    soc = None
    frames = chunks = n_msgs = 0
    last_hb = -math.inf
    last_rx = wall0
    try:
        while n_msgs < max_messages:
            now = time.monotonic()
            if now >= deadline or now - last_rx > idle_timeout_s:
                break
            wait = 0.05 if not queue else max(0.0, min(0.05, wall0 + queue[0][0] - now))
            msg = vin.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=wait)
            n_msgs += 1
            if msg is not None and not (msg.lat == 0 and msg.lon == 0):
                last_rx = time.monotonic()
                if home is None or home.alt_m is None:
                    home = GeoPoint(msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3 if home is None or
                                    home.alt_m is None else home.alt_m)
                e, n, u = geodetic_to_enu(msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3, home)
                t_new = last_rx - wall0
                if not t_rx or t_new > t_rx[-1]:
                    t_rx.append(t_new)
                    pos.append((float(e), float(n), max(float(u), 0.0) + gap))
            # simulate a finished chunk
            if len(t_rx) - chunk_start >= 2 and t_rx[-1] - t_rx[chunk_start] >= chunk_s:
                lo = max(chunk_start - 1, 0)    # overlap one sample: chunks join without a gap
                t_seg = np.array(t_rx[lo:])
                traj = Trajectory.from_samples(t_seg - t_seg[0], np.array(pos[lo:]))
                c = cfg if soc is None else _chunk_config(cfg, soc)
                res = run_mission(c, policy, trajectory=traj)
                soc = float(res.summary["final_soc"])
                ts = res.timeseries.copy()
                ts["t_s"] = ts["t_s"] + t_seg[0]
                tab = mavlink_table(ts, home, gap)
                tick_t = np.arange(math.ceil(t_seg[0] * rate_hz), math.floor(t_seg[-1] * rate_hz) + 1) / rate_hz
                if chunks:
                    tick_t = tick_t[tick_t > t_seg[0]]
                rows = np.clip(np.searchsorted(tab["t_s"].to_numpy(), tick_t + 1e-9, side="right") - 1, 0, len(tab) - 1)
                queue.extend((tk + chunk_s, tab.iloc[int(r)]) for tk, r in zip(tick_t, rows))
                chunk_start = len(t_rx)
                chunks += 1
            # send what is due
            now = time.monotonic()
            while queue and wall0 + queue[0][0] <= now:
                t_send, row = queue.pop(0)
                hb = now - last_hb >= 1.0
                last_hb = now if hb else last_hb
                for m in encode_tick(mav, row, hb):
                    frame = m.pack(mav)
                    mav.seq = (mav.seq + 1) % 256
                    if out is not None:
                        out.write(frame)
                    if writer is not None:
                        writer.write(frame, epoch0 + float(row.t_s))
                    frames += 1
    finally:
        vin.close()
        if own_out:
            out.close()
        if writer is not None:
            writer.close()
    return FollowStats(positions=len(t_rx), chunks=chunks, frames=frames, wall_s=time.monotonic() - wall0,
                       final_soc=soc, home=home)
