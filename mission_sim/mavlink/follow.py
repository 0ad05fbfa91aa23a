"""``dronewpt telemetry --follow``: drive the mission world from a live vehicle's positions.

A vehicle (e.g. an autopilot in software-in-the-loop) sends GLOBAL_POSITION_INT to a UDP port;
:func:`follow` turns its positions into the pad frame, runs the mission world on them chunk by
chunk and streams the simulated telemetry (:mod:`mission_sim.mavlink.telemetry`) about one chunk behind.
Every loop is bounded in message count and wall time.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .geodesy import GeoPoint, geodetic_to_enu
from .logs import mavutil
from .telemetry import TlogWriter, check_connect, mavlink_table, send_tick

__all__ = ["FollowStats", "open_follow", "follow"]

_REANCHOR_S = 5.0           # vehicle clock this far off ours -> re-anchor (reboot, stall)


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
    from ..config import apply_overrides, config_from_dict, config_to_dict
    return config_from_dict(apply_overrides(config_to_dict(cfg), {"battery.initial_soc": float(soc)}))


def open_follow(follow_connect: str):
    """The connection a live vehicle sends to (e.g. ``udpin:127.0.0.1:14551``), as a ground station."""
    return mavutil().mavlink_connection(check_connect(follow_connect, "--follow"), source_system=255,
                                        source_component=190)


def follow(follow_connect: str, cfg, policy, run_mission, *, connect: str | None = None, rate_hz: float = 10.0,
           home: GeoPoint | None = None, tlog=None, max_wall_s: float = 60.0, chunk_s: float = 1.0,
           max_messages: int = 1_000_000, idle_timeout_s: float = 10.0, out_conn=None, in_conn=None) -> FollowStats:
    """Drive the mission world from a live vehicle's GLOBAL_POSITION_INT and stream the result.

    Positions from ``follow_connect`` (e.g. ``udpin:127.0.0.1:14551``; lat = lon = 0, i.e. no fix,
    skipped) are timed by the vehicle's ``time_boot_ms`` anchored to the receiver's clock, and converted to the pad frame about ``home``
    (None: the first position received is the pad). Every ``chunk_s`` seconds the new stretch
    of track runs through ``run_mission(cfg, policy, trajectory=...)``, the battery carried
    over from chunk to chunk by its state of charge, and its telemetry is sent at ``rate_hz``,
    scheduled ``chunk_s`` behind the vehicle (the latency of this chunked scheme; the link's
    electrical state restarts each chunk). The loop ends after ``max_wall_s`` seconds,
    ``max_messages`` received messages or ``idle_timeout_s`` without a position; then the last
    partial chunk is simulated and everything still queued is sent at once. ``in_conn``: a
    connection from :func:`open_follow` opened earlier (bind before slow set-up work, or the
    vehicle's first messages are lost).
    """
    from ..world.trajectory import Trajectory

    mu = mavutil()
    vin = in_conn if in_conn is not None else open_follow(follow_connect)
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
    tb_offset = None
    frames = chunks = n_msgs = 0
    last_hb = -math.inf
    last_rx = wall0
    def simulate_chunk():
        nonlocal chunk_start, chunks, soc
        lo = max(chunk_start - 1, 0)            # overlap one sample: chunks join without a gap
        t_seg = np.array(t_rx[lo:])
        traj = Trajectory.from_samples(t_seg - t_seg[0], np.array(pos[lo:]))
        res = run_mission(cfg if soc is None else _chunk_config(cfg, soc), policy, trajectory=traj)
        soc = float(res.summary["final_soc"])
        ts = res.timeseries.copy()
        ts["t_s"] = ts["t_s"] + t_seg[0]
        tick_t = np.arange(math.ceil(t_seg[0] * rate_hz), math.floor(t_seg[-1] * rate_hz) + 1) / rate_hz
        if chunks:
            tick_t = tick_t[tick_t > t_seg[0]]
        if len(tick_t):
            tab = mavlink_table(ts, home, gap, t_out=tick_t, track=(t_seg, np.array(pos[lo:])))
            queue.extend((tk + chunk_s, tab.iloc[i]) for i, tk in enumerate(tick_t))
        chunk_start = len(t_rx)
        chunks += 1

    def send_due(now):
        nonlocal last_hb, frames
        while queue and wall0 + queue[0][0] <= now:
            _, row = queue.pop(0)
            t_wall = time.monotonic()
            hb = t_wall - last_hb >= 1.0
            last_hb = t_wall if hb else last_hb
            frames += len(send_tick(mav, row, hb, out, writer, epoch0 + float(row.t_s)))

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
                # the vehicle's clock spaces the samples (frames may arrive in bursts); anchored to
                # our clock at the first frame and again after a reboot or a jump
                tb = msg.time_boot_ms * 1e-3
                arrival = last_rx - wall0
                if tb_offset is None or abs(tb + tb_offset - arrival) > _REANCHOR_S:
                    tb_offset = arrival - tb
                t_new = tb + tb_offset
                if not t_rx or t_new > t_rx[-1] + 1e-3:
                    t_rx.append(t_new)
                    pos.append((float(e), float(n), max(float(u), 0.0) + gap))
            if len(t_rx) - chunk_start >= 2 and t_rx[-1] - t_rx[chunk_start] >= chunk_s:
                simulate_chunk()
            send_due(time.monotonic())
        if len(t_rx) - max(chunk_start - 1, 0) >= 2 and len(t_rx) > chunk_start:
            simulate_chunk()                    # the last, partial chunk
        send_due(math.inf)                      # and everything still queued, without waiting
    finally:
        vin.close()
        if own_out:
            out.close()
        if writer is not None:
            writer.close()
    return FollowStats(positions=len(t_rx), chunks=chunks, frames=frames, wall_s=time.monotonic() - wall0,
                       final_soc=soc, home=home)
