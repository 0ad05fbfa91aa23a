"""``dronewpt telemetry --follow``: drive the mission world from a live vehicle's positions.

A vehicle (e.g. an autopilot in software-in-the-loop) sends GLOBAL_POSITION_INT to a UDP port;
:func:`follow` turns its positions into the pad frame, runs the mission world on them chunk by
chunk (:class:`ChunkedMission`) and streams the simulated telemetry
(:mod:`mission_sim.mavlink.telemetry`) one chunk behind. Every loop is bounded in message count
and wall time.

Continuity across chunks: each chunk is simulated from :data:`WARM_S` seconds *before* its start
(the battery at that time's state of charge from the previous chunk), and only its own stretch is
reported, so the link's electrical state (coil currents, SBAR duty, the policy's memory) at the
chunk boundary is the one a continuous run reaches (the link settles in ~0.2 s, far inside the
warm-up). Not carried exactly: the battery's RC polarisation (tau 15 s) restarts at the warm-up
(the runner has no initial-state hook); over an 8 s test track the state of charge differs from a
continuous run by 1e-4 and the consumed charge by 0.7 %. Net charge and energy drawn accumulate over the whole run; HEARTBEATs come at every
whole second of the vehicle's clock (with EXTENDED_SYS_STATE, the landed state); the last, partial chunk
is simulated and sent at the end, then the vehicle lands and disarms as in ``dronewpt telemetry``
(:func:`mission_sim.mavlink.telemetry.landing_rows`).
"""

from __future__ import annotations

import bisect
import math
import time
from dataclasses import dataclass

import numpy as np

from .geodesy import GeoPoint, geodetic_to_enu
from .gpsclean import MAX_SPEED_M_S, MAX_VSPEED_M_S, SLACK_M
from .logs import mavutil
from .telemetry import (TlogWriter, check_connect, close_link, check_ids, drawn_totals, encode_tick, heartbeat_msgs,
                        landing_rows, mavlink_table, open_link, schedule, send_msgs)

__all__ = ["FollowStats", "open_follow", "follow", "ChunkedMission", "WARM_S"]

_REANCHOR_S = 5.0           # vehicle clock this far off ours -> re-anchor (reboot, stall)
WARM_S = 2.0                # each chunk is simulated from this long before its start


@dataclass
class FollowStats:
    """What :func:`follow` did: positions received, chunks simulated, frames sent, wall seconds."""

    positions: int
    chunks: int
    frames: int
    wall_s: float
    final_soc: float | None
    home: GeoPoint | None
    delivered: int = 0      # frames that went to a peer on the out link (telemetry.write_frame)
    rejected: int = 0       # positions outside the Earth's ranges skipped (a corrupt frame, INT32_MAX = unknown)
    first_rejected: str = ""   # why the first of them was (GeoPoint's one-line error)


def _chunk_config(cfg, soc):
    """``cfg`` with the battery starting at ``soc`` (the state of charge where the chunk starts)."""
    from ..config import apply_overrides, config_from_dict, config_to_dict
    return config_from_dict(apply_overrides(config_to_dict(cfg), {"battery.initial_soc": float(soc)}))


class ChunkedMission:
    """The mission world run along a growing track, chunk by chunk, as one continuous mission.

    :meth:`add` appends a position (time [s], ENU [m] coil position); :meth:`simulate` runs the
    new stretch and returns the send events ``(t [s], mavlink_table row, is_heartbeat)``.
    """

    def __init__(self, cfg, policy, run_mission, home: GeoPoint, rate_hz: float, warm_s: float = WARM_S):
        from ..world.trajectory import Trajectory
        self.cfg, self.policy, self.run_mission, self.home, self.rate_hz = cfg, policy, run_mission, home, rate_hz
        self.warm_s, self.gap = float(warm_s), float(cfg.mission.hover_gap_m)
        self.t: list[float] = []
        self.pos: list[tuple[float, float, float]] = []
        self.start = 0                                   # first sample not yet reported
        self.soc_t, self.soc = [], []                    # state of charge along the reported stretches
        self.drawn = (0.0, 0.0)                          # net charge [C] and energy [J] reported so far
        self.last_tick = self.last_hb = -math.inf
        self.chunks = 0
        self.final_soc = None
        still = Trajectory.from_samples([0.0, 1.0], [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
        self.hover_w = float(still.propulsion_w(cfg.drone)[0])   # 50 % throttle

    def add(self, t_s: float, pos_m) -> None:
        if not self.t or t_s > self.t[-1] + 1e-3:
            self.t.append(float(t_s))
            self.pos.append(tuple(float(v) for v in pos_m))

    def pending_s(self) -> float:
        """Seconds of track received after the last reported sample (0 if nothing new)."""
        if len(self.t) <= self.start or len(self.t) < 2:
            return 0.0
        return self.t[-1] - self.t[max(self.start - 1, 0)]

    def _soc_at(self, t: float) -> float:
        if not self.soc_t:
            return float(self.cfg.battery.initial_soc)
        return float(np.interp(t, self.soc_t, self.soc))

    def simulate(self) -> list:
        """Simulate from the last reported sample to the newest one; the send events of the stretch."""
        from ..world.trajectory import Trajectory
        t_from = self.t[max(self.start - 1, 0)]              # the stretch joins the previous one
        lo = bisect.bisect_left(self.t, t_from - self.warm_s - 1e-9)
        t_seg, pos = np.array(self.t[lo:]), np.array(self.pos[lo:])
        res = self.run_mission(_chunk_config(self.cfg, self._soc_at(t_seg[0])), self.policy,
                               trajectory=Trajectory.from_samples(t_seg - t_seg[0], pos))
        ts = res.timeseries.copy()
        ts["t_s"] = ts["t_s"] + t_seg[0]
        c, j = drawn_totals(ts)
        # drawn up to t_from (reported by the previous chunk): the totals are linear within a step
        # (a row closes its step at t_s), so interpolate; the first chunk reports from its start
        rows_t = ts["t_s"].to_numpy()
        c0, j0 = (0.0, 0.0) if self.start == 0 else (np.interp(t_from, rows_t, c), np.interp(t_from, rows_t, j))
        mine = ts["t_s"].to_numpy() > t_from + 1e-9
        if self.start == 0:
            self.soc_t, self.soc = [float(t_seg[0])], [float(self.cfg.battery.initial_soc)]
        self.soc_t += list(ts["t_s"].to_numpy()[mine])
        self.soc += list(ts["soc"].to_numpy()[mine])
        first = self.last_tick + 1e-9 if self.chunks else t_seg[0] - 1e-9
        tick_t = np.arange(math.ceil(first * self.rate_hz), math.floor(t_seg[-1] * self.rate_hz + 1e-9) + 1) / self.rate_hz
        tick_t = tick_t[tick_t > first]
        events = []
        if len(tick_t):
            tab = mavlink_table(ts, self.home, self.gap, t_out=tick_t, track=(t_seg, pos),
                                drawn0=(self.drawn[0] - c0, self.drawn[1] - j0), hover_w=self.hover_w)
            rows = list(tab.itertuples(index=False))         # namedtuples, as `telemetry` sends
            events = [(t, rows[k], hb) for t, k, hb in schedule(tick_t, self.last_hb)]
            self.last_tick = float(tick_t[-1])
            self.last_hb = max([t for t, _, hb in events if hb], default=self.last_hb)
        self.drawn = (self.drawn[0] + c[-1] - c0, self.drawn[1] + j[-1] - j0)
        self.final_soc = float(res.summary["final_soc"])
        self.start = len(self.t)
        self.chunks += 1
        return events


def open_follow(follow_connect: str):
    """The connection a live vehicle sends to (e.g. ``udpin:127.0.0.1:14551``), as a ground station."""
    return mavutil().mavlink_connection(check_connect(follow_connect, "--follow"), source_system=255,
                                        source_component=190)


class _Clock:
    """The vehicle's ``time_boot_ms`` anchored to our clock at the first frame and again after a
    reboot or a jump (frames may arrive in bursts; the vehicle's clock spaces the samples)."""

    def __init__(self):
        self.offset = None

    def __call__(self, time_boot_ms: int, arrival_s: float) -> float:
        tb = time_boot_ms * 1e-3
        if self.offset is None or abs(tb + self.offset - arrival_s) > _REANCHOR_S:
            self.offset = arrival_s - tb
        return tb + self.offset


def _jump(last, now) -> str:
    """'' if a vehicle could have moved from ``last`` to ``now`` (each (boot s, arrival s, e, n, u), metres in one
    frame), else why not: farther than gpsclean's bounds (:data:`~mission_sim.mavlink.gpsclean.SLACK_M` +
    :data:`~mission_sim.mavlink.gpsclean.MAX_SPEED_M_S` dt horizontally, ``MAX_VSPEED_M_S`` dt vertically) with dt the
    longer of the vehicle's and the arrival clock's time between them (a reboot sets the vehicle's back)."""
    dt = max(now[0] - last[0], now[1] - last[1], 0.0)
    d_h, d_v = math.hypot(now[2] - last[2], now[3] - last[3]), abs(now[4] - last[4])
    if d_h <= SLACK_M + MAX_SPEED_M_S * dt and d_v <= SLACK_M + MAX_VSPEED_M_S * dt:
        return ""
    return (f"a jump of {d_h:.4g} m horizontally, {d_v:.4g} m vertically in {dt:.3g} s from the last position; valid: "
            f"at most {SLACK_M:g} m + {MAX_SPEED_M_S:g} m/s x dt horizontally, "
            f"{SLACK_M:g} m + {MAX_VSPEED_M_S:g} m/s x dt vertically")


#: consecutive positions that must agree (each a plausible move from the one before) before the first is taken as the
#: reference later jumps are judged against: one implausible but in-range first fix (latitude and longitude swapped
#: at Zurich) had become the reference, and every good position after it was skipped as a jump
CONFIRM = 3


class _Positions:
    """The vehicle's positions as :func:`follow` takes them: :meth:`take` gives the GLOBAL_POSITION_INTs newly taken,
    each as (time_boot_ms, arrival s, (e, n, u) in metres about ``home``) (``home`` None: the first position taken; no
    altitude: the first one's). A frame without a fix (lat = lon = 0) is skipped; an implausible one is skipped and
    counted (``rejected``; ``first_rejected`` says why): one outside :class:`GeoPoint`'s ranges, or an impossible jump
    from the last position taken (:func:`_jump`: latitude and longitude swapped at Zurich, 47.4 / 8.5, are both in
    range). One such frame ended the session.

    The first reference is confirmed: positions are held until :data:`CONFIRM` consecutive ones agree (each a
    plausible move from the one before), then all of them are taken at once; a position that does not agree with the
    one held before it drops those held (counted as skipped) and starts anew from it. So a bad first fix followed by
    good ones costs that fix, not the session. :meth:`flush` takes the longest agreeing run when the stream ends before
    :data:`CONFIRM` positions came: those held, or a run dropped earlier when it is longer (or as long: the later run
    contradicted it), so that good, good, swapped, end takes the two good ones and skips the swapped one."""

    def __init__(self, home: GeoPoint | None):
        self.home, self.rejected, self.first_rejected = home, 0, ""
        self.last: tuple | None = None   # (boot s, arrival s, e, n, u) of the last position taken
        self.held: list = []             # before the first reference: (msg time_boot_ms, arrival s, lat, lon, alt, enu0)
        self.dropped: list = []          # the longest run dropped so far (the earliest of equal ones), for flush

    def _skip(self, why: str, n: int = 1) -> None:
        self.rejected += n
        self.first_rejected = self.first_rejected or why

    def take(self, msg, arrival_s: float) -> list:
        if msg.lat == 0 and msg.lon == 0:
            return []
        lat, lon, alt = msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3
        try:
            GeoPoint(msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1e3)   # (/: the message's digits in the error)
        except ValueError as exc:
            self._skip(str(exc))
            return []
        if self.last is None:     # no reference yet: held until CONFIRM in a row agree
            origin = GeoPoint(*self.held[0][2:5]) if self.held else GeoPoint(lat, lon, alt)
            e, n, u = (float(v) for v in geodetic_to_enu(lat, lon, alt, origin))
            now = (msg.time_boot_ms, arrival_s, lat, lon, alt, (e, n, u))
            if self.held:
                prev = self.held[-1]
                why = _jump((prev[0] * 1e-3, prev[1], *prev[5]), (msg.time_boot_ms * 1e-3, arrival_s, e, n, u))
                if why:   # one of the two is wrong: those held so far are dropped, the new one starts anew
                    self._skip(why.replace("from the last position", "between the first positions"), len(self.held))
                    if len(self.held) > len(self.dropped):
                        self.dropped = self.held
                    self.held = []
                    return self.take(msg, arrival_s)
            self.held.append(now)
            return self.flush() if len(self.held) >= CONFIRM else []
        e, n, u = geodetic_to_enu(lat, lon, alt, self.home)
        why = _jump(self.last, (msg.time_boot_ms * 1e-3, arrival_s, float(e), float(n), float(u)))
        if why:
            self._skip(why)
            return []
        return [self._accept(msg.time_boot_ms, arrival_s, lat, lon, alt)]

    def flush(self) -> list:
        """The positions held (not yet confirmed by :data:`CONFIRM` in a row), taken; [] if none. Without a reference
        yet, the longest agreeing run: a run dropped earlier at least as long as those held is taken instead (it was
        counted as skipped; those held are counted instead): a position that contradicted earlier ones is not made
        the reference."""
        held, self.held = self.held, []
        if self.last is None and self.dropped and len(self.dropped) >= len(held):
            self.rejected += len(held) - len(self.dropped)
            held = self.dropped
        self.dropped = []
        return [self._accept(tb, arrival, lat, lon, alt) for tb, arrival, lat, lon, alt, _ in held]

    def _accept(self, time_boot_ms, arrival_s, lat, lon, alt):
        if self.home is None:
            self.home = GeoPoint(lat, lon, alt)
        elif self.home.alt_m is None:
            self.home = GeoPoint(self.home.lat_deg, self.home.lon_deg, alt)
        e, n, u = (float(v) for v in geodetic_to_enu(lat, lon, alt, self.home))
        self.last = (time_boot_ms * 1e-3, arrival_s, e, n, u)
        return time_boot_ms, arrival_s, (e, n, u)


def _poll(vin, positions, wait, simulating, last_rx, idle_timeout_s):
    """One receive of at most ``wait`` s: ``(taken, last_rx, idle)``. Idle only when nothing came (a slow chunk must
    not drop the positions queued meanwhile) and positions have come (those held for the first reference count: a
    vehicle that stops after 2 is idle too); ``last_rx`` moves only when a position was taken or held (not on a
    no-fix frame, nor a skipped one)."""
    msg = vin.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=wait)
    idle = msg is None and (simulating or bool(positions.held)) and time.monotonic() - last_rx > idle_timeout_s
    before = positions.held[-1] if positions.held else None
    taken = [] if msg is None else positions.take(msg, time.monotonic())
    if taken or (positions.held and positions.held[-1] is not before):
        last_rx = time.monotonic()
    return taken, last_rx, idle


def follow(follow_connect: str, cfg, policy, run_mission, *, connect: str | None = None, rate_hz: float = 10.0,
           home: GeoPoint | None = None, tlog=None, max_wall_s: float = 60.0, chunk_s: float = 1.0,
           max_messages: int = 1_000_000, idle_timeout_s: float = 10.0, out_conn=None, in_conn=None,
           sysid: int = 1, compid: int = 1) -> FollowStats:
    """Drive the mission world from a live vehicle's GLOBAL_POSITION_INT and stream the result.

    Positions from ``follow_connect`` (e.g. ``udpin:127.0.0.1:14551``; no fix or implausible: skipped,
    :class:`_Positions`) are timed by the vehicle's clock (:class:`_Clock`) and converted to the pad frame about
    ``home`` (None: the first position taken is the pad, :class:`_Positions`). Every ``chunk_s`` seconds the
    new stretch runs through :class:`ChunkedMission` and its telemetry is sent at ``rate_hz``,
    ``chunk_s`` behind the vehicle. The loop ends after ``max_wall_s`` seconds, ``max_messages`` received messages
    or ``idle_timeout_s`` without a position once positions have come (before the first one it waits up to
    ``max_wall_s``: a vehicle may boot after the follower); then the last chunk runs and the queue is sent at once. ``in_conn``: a connection from
    :func:`open_follow` opened earlier (bind before slow set-up work, or the vehicle's first
    messages are lost). ``sysid`` / ``compid``: the simulated vehicle's MAVLink ids.
    """
    sysid, compid = check_ids(sysid, compid)
    vin = in_conn if in_conn is not None else open_follow(follow_connect)
    own_out = out_conn is None and connect is not None
    out = open_link(connect, sysid, compid) if own_out else out_conn
    mav = mavutil().mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    writer = TlogWriter(tlog) if tlog is not None else None
    wall0, epoch0 = time.monotonic(), time.time()
    clock, sim, queue, positions = _Clock(), None, [], _Positions(home)   # queue: (send at, row, is heartbeat)
    frames = n_msgs = delivered = 0
    last_rx, idle = wall0, False
    last_tick = []                              # (time, row) of the latest tick queued

    def enqueue(events):
        for t, row, hb in events:
            queue.append((t + chunk_s, row, hb))
            if not hb:
                last_tick[:] = [(t + chunk_s, row)]

    def add(taken):
        nonlocal sim
        for time_boot_ms, arrival_s, enu in taken:
            if sim is None:
                sim = ChunkedMission(cfg, policy, run_mission, positions.home, rate_hz)
            sim.add(clock(time_boot_ms, arrival_s - wall0), (enu[0], enu[1], max(enu[2], 0.0) + sim.gap))

    def send_due(now):
        nonlocal frames, delivered
        while queue and wall0 + queue[0][0] <= now:
            t_send, row, hb = queue.pop(0)
            msgs = heartbeat_msgs(mav, row) if hb else encode_tick(mav, row)
            n, n_out = send_msgs(mav, msgs, out, writer, epoch0 + t_send - chunk_s)
            frames += n
            delivered += n_out

    ended = False
    try:
        while n_msgs < max_messages and time.monotonic() < wall0 + max_wall_s and not idle:
            wait = 0.05 if not queue else max(0.0, min(0.05, wall0 + queue[0][0] - time.monotonic()))
            taken, last_rx, idle = _poll(vin, positions, wait, sim is not None, last_rx, idle_timeout_s)
            n_msgs += 1
            add(taken)
            if sim is not None and sim.pending_s() >= chunk_s:
                enqueue(sim.simulate())
            send_due(time.monotonic())
        add(positions.flush())                  # positions held for want of CONFIRM in a row: nothing contradicted them
        if sim is not None and sim.pending_s() > 0:
            enqueue(sim.simulate())             # the last, partial chunk
        if last_tick:                           # then the vehicle lands and disarms, as in `telemetry`
            queue.extend((last_tick[0][0] + dt, row, True) for dt, row in landing_rows(last_tick[0][1]))
        send_due(math.inf)                      # and everything still queued, without waiting
        ended = True
    except BaseException as exc:
        if writer is not None:
            writer.abort(exc)   # the frames so far as NAME.partial.tlog, an existing NAME left as it was
        raise
    finally:
        vin.close()
        if own_out:
            close_link(out)
        if writer is not None and ended:
            writer.close()      # no position came, no frame: no file (an existing one untouched)
    return FollowStats(positions=len(sim.t) if sim else 0, chunks=sim.chunks if sim else 0, frames=frames,
                       delivered=delivered, wall_s=time.monotonic() - wall0, final_soc=sim.final_soc if sim else None,
                       home=positions.home, rejected=positions.rejected, first_rejected=positions.first_rejected)
