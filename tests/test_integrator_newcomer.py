"""A drone integrator's pass (2026-11-27): what replaying real logs, flying one's own mission files and
streaming telemetry to a ground station found, each case a test that failed before its fix
(docs/robustness.md, "A drone integrator's pass")."""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np
import pytest

from _cli_helpers import fake_follow
from _flightlogs import log_path, tlog_records, write_tlog
from mission_sim.config import load_config


def test_replay_disarmed_draws_avionics_only():
    """A replayed log's disarmed samples ("ground": motors off) draw the avionics alone. The per-sample
    arrays moved into chunks (world/samples.py) had dropped the replay's override, so a disarmed ROV
    sitting on the bench for 247 s drew hover power (98.8 W): 26.0 kJ of 'propulsion' instead of 3.6 kJ."""
    import policies
    from mission_sim.mavlink.replay import replay_log

    cfg = load_config(None)
    res = replay_log(log_path("ardusub_log_tools_small_rov.tlog"), cfg, policies.make("model_based"),
                     warn=False)   # the ROV's 4S pack against the config's 8S: in the summary's warnings
    ts = res.mission.timeseries
    ground = (ts["phase"] == "ground").to_numpy()
    assert ground.sum() > 100 and (~ground).sum() > 100
    np.testing.assert_allclose(ts.loc[ground, "propulsion_w"].to_numpy(), cfg.drone.avionics_w, rtol=1e-12)
    assert ts.loc[~ground, "propulsion_w"].median() > 10 * cfg.drone.avionics_w    # armed: momentum theory
    # the summary's propulsion energy is the rows' (the step-mean power times dt, to rounding)
    e = float(np.sum(ts["propulsion_w"].to_numpy() * ts["dt_s"].to_numpy()))
    assert res.summary["propulsion_energy_j"] == pytest.approx(e, rel=1e-6)
    assert res.summary["propulsion_energy_j"] < 5000.0           # 26,024 J before the fix


def _series(duration_s=2.0, dt=0.05):
    """A small mission-shaped time series (hover at 2 m, charging in the middle)."""
    import pandas as pd
    t = np.arange(0.0, duration_s + 1e-9, dt)
    charging = (t > 0.5) & (t < 1.5)
    return pd.DataFrame({"t_s": t, "x_m": 0.5 * t, "y_m": 0 * t, "z_m": 2.0 + 0 * t, "lm_h": 6.25e-6 + 0 * t,
                         "i2_amp_a": np.where(charging, 11.0, 0.0), "d_short": 0 * t, "battery_v": 29.6 + 0 * t,
                         "battery_current_a": np.where(charging, 2.0, -3.0), "soc": 0.8 + 0 * t,
                         "propulsion_w": np.full(len(t), 100.0), "phase": np.where(charging, "charge", "transit")})


def _ground_station(kind, port, stop, got):
    """A ground station that contacts the vehicle first (as MAVProxy --master=udpout: / tcp: does):
    UDP: a HEARTBEAT every 20 ms to ``port``; TCP: connects. Parses what comes back into ``got``."""
    import socket
    import time

    from mission_sim.mavlink.logs import mavutil
    m = mavutil().mavlink
    mav = m.MAVLink(None, srcSystem=255, srcComponent=190)
    hb = mav.heartbeat_encode(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(mav)
    parser = m.MAVLink(None)
    parser.robust_parsing = True
    if kind == "udp":
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    else:
        s = None
        while s is None and not stop.is_set():
            try:
                s = socket.create_connection(("127.0.0.1", port), timeout=0.02)
            except OSError:
                s = None
                time.sleep(0.01)
        if s is None:
            return
    s.settimeout(0.02)
    with s:
        while not stop.is_set():
            if kind == "udp":
                s.sendto(hb, ("127.0.0.1", port))
            try:
                data = s.recv(1 << 16)
            except OSError:
                continue
            got.extend(parser.parse_buffer(data) or [])


@pytest.mark.parametrize("kind", ["udp", "tcp"])
def test_listening_connect_delivers_to_a_ground_station(kind):
    """``--connect udpin:`` / ``tcpin:`` (advertised in --connect's format) never delivered a frame: pymavlink's
    listening links learn their peer (udpin) or accept their client (tcpin) only while reading, and the stream
    never read. Now a ground station that contacts the vehicle gets the stream from then on, and the count of
    frames delivered says how much it got."""
    import socket
    import threading

    from mission_sim.mavlink.telemetry import stream
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM if kind == "tcp" else socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    stop, got = threading.Event(), []
    th = threading.Thread(target=_ground_station, args=(kind, port, stop, got), daemon=True)
    th.start()
    try:
        st = stream(_series(), connect=f"{kind}in:127.0.0.1:{port}", rate_hz=10, speed=4.0, sysid=9)
    finally:
        import time
        time.sleep(0.3)
        stop.set()
        th.join(5)
    types = [g.get_type() for g in got]
    assert {"HEARTBEAT", "SYS_STATUS", "BATTERY_STATUS", "GLOBAL_POSITION_INT"} <= set(types)   # nothing before
    assert st.delivered > 0.6 * st.frames                  # the first frames go out before the first contact
    assert len(got) == st.delivered                       # loopback: every delivered frame arrives
    assert {(g.get_srcSystem(), g.get_srcComponent()) for g in got} == {(9, 1)}
    seq = [g.get_seq() for g in got]
    assert all((b - a) % 256 == 1 for a, b in zip(seq, seq[1:]))   # consecutive: nothing lost or repeated


def test_connect_refused_is_said_before_the_simulation(monkeypatch, capsys):
    """``--connect tcp:`` to a port where nothing listens simulated the whole mission first, then ended with
    ``[Errno 111] Connection refused`` naming no option; now one line naming --connect, nothing simulated, and one
    attempt (pymavlink's default retries=3 printed "... sleeping" on stdout twice and waited 2 s)."""
    import socket

    import mission_sim.world.runner as runner
    from mission_sim.cli import main

    def boom(*a, **k):
        raise AssertionError("simulated before the link was opened")
    monkeypatch.setattr(runner, "run_mission", boom)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]                          # closed again: nothing listens there
    rc = main(["telemetry", "--connect", f"tcp:127.0.0.1:{port}", "--speed", "inf", "--no-progress"])
    out, err = capsys.readouterr()
    err = err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert out == ""         # pymavlink's default 3 retries printed "[Errno 111] Connection refused sleeping" twice
    assert f"--connect 'tcp:127.0.0.1:{port}' cannot be opened: Connection refused" in err[0]


def test_listening_connect_nobody_contacted_warns(capsys):
    """A listening --connect that no ground station contacted said "sent N MAVLink 2 frames ... to udpin:..."
    and exit 0 while nothing left the machine; now a warning says nothing was delivered and what to use."""
    import socket

    from mission_sim.cli import main
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    rc = main(["telemetry", "--connect", f"udpin:127.0.0.1:{port}", "--speed", "inf", "--duration", "2",
               "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 0
    assert f"--connect udpin:127.0.0.1:{port}: it listens and no ground station contacted it, so nothing was delivered" in err
    assert "use --connect udpout:HOST:14550" in err


@pytest.fixture(scope="module")
def dronekit_read():
    """The shipped dronekit tlog as read (its facts agree with pymavlink's: test_mavlink_io) and its records."""
    from mission_sim.mavlink.logs import read_log
    path = log_path("dronekit-python_flight.tlog")
    return read_log(path), tlog_records(path)


@pytest.mark.parametrize("step_s", [-3600.0, -10.0, 3600.0])
def test_ground_station_clock_set_mid_log(tmp_path, dronekit_read, step_s):
    """The ground station's clock set back or forward (NTP, a laptop's clock changed) 800 s into the dronekit
    log, the vehicle's boot clock running on. Set back 1 h, the log ended at 800.6 s (the rest of the flight, 3
    of its 7 armed periods, gone) with 661 s "armed from the start"; 10 s back gave 10 armed periods and 1380.6 s;
    1 h forward fitted a 0.996x vehicle clock. Now the step is found (receive minus boot time moving by more
    than clock.RECV_STEP_S) and taken out: the log reads as the original within 0.2 s."""
    from mission_sim.mavlink.logs import read_log
    ref, rec = dronekit_read
    t0 = rec[0][0]
    path = write_tlog(tmp_path / "stepped.tlog", [(t + step_s if t - t0 > 800.0 else t, f) for t, f in rec])
    log = read_log(path)
    assert log.duration_s == pytest.approx(ref.duration_s, abs=0.2)
    assert len(log.armed_periods) == len(ref.armed_periods) == 7
    np.testing.assert_allclose(np.array(log.armed_periods), np.array(ref.armed_periods), atol=0.2)
    assert not log.starts_armed
    assert [round(s.rate, 6) for s in log.clock.segments] == [1.0, 1.0]
    assert len(log.position) == len(ref.position)
    np.testing.assert_allclose(log.position["t_s"].to_numpy(), ref.position["t_s"].to_numpy(), atol=0.2)
    # battery samples (no boot time of their own) in their place: the logged energy over the log is the same
    e = lambda b: float(np.trapezoid(b["voltage_v"] * b["current_a"], b["t_s"]))  # noqa: E731
    assert e(log.battery) == pytest.approx(e(ref.battery), rel=2e-3)


def test_two_logs_joined_read_and_replay(tmp_path):
    """Two vehicles' tlogs joined in one file (the SITL VTOL's of 2018, then the dronekit quad's of 2015:
    the receive clock goes back 3 years at the join). pymavlink's indexing reader failed on it ("the log could
    not be parsed: AttributeError ... '_instance_field'"); read with the streaming reader, the receive clock
    going back across the reboot placed the second log 97.7 million s before the first, and the replay tried
    to allocate 3.6 GiB (the OOM killer ended it without a word). Now each boot follows the last, and a track
    too long for memory is refused before anything is allocated."""
    from mission_sim.mavlink.logs import read_log
    from mission_sim.mavlink.replay import MAX_REPLAY_SAMPLES, FlightTrack, resample_track
    from mission_sim.mavlink.geodesy import GeoPoint
    a, b = log_path("uavlogviewer_vtol_sitl.tlog"), log_path("dronekit-python_flight.tlog")
    joined = tmp_path / "joined.tlog"
    joined.write_bytes(a.read_bytes() + b.read_bytes())
    la, lb, lj = read_log(a), read_log(b), read_log(joined)
    assert not lj.errors
    assert lj.duration_s == pytest.approx(la.duration_s + lb.duration_s, abs=5.0)
    armed = lambda lg: sum(e - s for s, e in lg.armed_periods)  # noqa: E731
    assert armed(lj) == pytest.approx(armed(la) + armed(lb), abs=0.5)
    assert lj.position["t_s"].min() == pytest.approx(la.position["t_s"].min(), abs=1e-6)   # nothing moved before
    # the guard itself: a track of 10 years on the 0.2 s grid is refused, naming --window
    t = np.array([0.0, 10 * 365.25 * 86400])
    track = FlightTrack(t_s=t, pos_m=np.zeros((2, 3)), tilt_rad=np.zeros(2), height_m=np.zeros(2), t_offset_s=0.0,
                        pad=GeoPoint(0.0, 0.0, 0.0), ground_gap_m=0.0, armed=np.ones(2, bool), n_tilt_clipped=0)
    with pytest.raises(ValueError, match=r"more than the 21\.9 h that fit in memory .* --window T0,T1"):
        resample_track(track, 0.2)
    assert MAX_REPLAY_SAMPLES * 0.2 > 20 * 3600            # a long real log still replays


def test_replay_sample_limit_follows_the_memory_budget():
    """replay.MAX_REPLAY_SAMPLES was written as 395,000 while its comment derived it from world.budget: the most
    samples, each a sample and a held row, that fit in MAX_MEMORY_BYTES beside FIXED_BYTES (394,763). Now computed
    from them; a track of 394,900 samples is refused (it was resampled)."""
    from mission_sim.mavlink.geodesy import GeoPoint
    from mission_sim.mavlink.replay import MAX_REPLAY_SAMPLES, FlightTrack, resample_track
    from mission_sim.world import budget as b
    per = b.SAMPLE_BYTES + b.ROW_MEMORY_BYTES
    assert b.FIXED_BYTES + per * MAX_REPLAY_SAMPLES <= b.MAX_MEMORY_BYTES < b.FIXED_BYTES + per * (MAX_REPLAY_SAMPLES + 1)
    t = np.array([0.0, 394_900 * 0.2])
    track = FlightTrack(t_s=t, pos_m=np.zeros((2, 3)), tilt_rad=np.zeros(2), height_m=np.zeros(2), t_offset_s=0.0,
                        pad=GeoPoint(0.0, 0.0, 0.0), ground_gap_m=0.0, armed=np.ones(2, bool), n_tilt_clipped=0)
    with pytest.raises(ValueError, match=r"that fit in memory at sim\.traj_dt_s=0\.2"):
        resample_track(track, 0.2)


def _wpl(path, rows, home=(-35.363262, 149.165237, 584.09), bom=False):
    """A QGC WPL 110 file: home, then rows of (frame, command, p1, p2, p3, p4, lat, lon, alt)."""
    lines = ["QGC WPL 110", f"0\t1\t0\t16\t0\t0\t0\t0\t{home[0]:.7f}\t{home[1]:.7f}\t{home[2]:.3f}\t1"]
    lines += ["\t".join([str(i), "0", *map(str, r[:6]), f"{r[6]:.7f}", f"{r[7]:.7f}", f"{r[8]:.3f}", "1"])
              for i, r in enumerate(rows, 1)]
    path.write_bytes(("\ufeff" if bom else "").encode() + ("\r\n".join(lines) + "\r\n").encode())
    return path


def test_far_waypoint_names_the_row_not_an_internal_key(tmp_path, capsys):
    """A waypoint 225 km from home (Canberra to Sydney) said ``mission.land_x_m=166763.8 is invalid; valid range:
    [-100000, 100000] m``: a key the user never wrote. Now the file, the row and the distance (as pads already did)."""
    from mission_sim.cli import main
    f = _wpl(tmp_path / "far.waypoints", [(3, 22, 0, 0, 0, 0, 0, 0, 30), (3, 16, 0, 0, 0, 0, -34.0, 151.0, 30),
                                           (3, 21, 0, 0, 0, 0, -34.0, 151.0, 0)])
    rc = main(["mission", "--plan", str(f), "--dry-run"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert "far.waypoints: row 2: (-34, 151) is 225 km from home; valid: within 100 km of home" in err[0]


def test_mission_file_with_a_byte_order_mark(tmp_path):
    """A .waypoints or .plan saved by a Windows editor starts with a UTF-8 byte order mark: it was "not a mission
    file" (the .plan: "malformed JSON"). Now it reads as the same file without it."""
    import json

    from mission_sim.plans.items import read_mission
    rows = [(3, 22, 0, 0, 0, 0, 0, 0, 20), (3, 16, 0, 0, 0, 0, -35.3625, 149.1655, 20), (3, 21, 0, 0, 0, 0, 0, 0, 0)]
    plain = read_mission(_wpl(tmp_path / "a.waypoints", rows))
    with_bom = read_mission(_wpl(tmp_path / "b.waypoints", rows, bom=True))
    assert with_bom.items == plain.items and with_bom.home == plain.home and len(plain.items) == 3
    plan = {"fileType": "Plan", "mission": {"items": [
        {"type": "SimpleItem", "command": 22, "frame": 3, "params": [0, 0, 0, None, 0, 0, 20]},
        {"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 0, None, -35.3625, 149.1655, 20]}],
        "plannedHomePosition": [-35.363262, 149.165237, 584.09]}, "version": 1}
    (tmp_path / "a.plan").write_text(json.dumps(plan))
    (tmp_path / "b.plan").write_bytes(b"\xef\xbb\xbf" + json.dumps(plan).encode())
    assert repr(read_mission(tmp_path / "b.plan").items) == repr(read_mission(tmp_path / "a.plan").items)   # nan params


def test_telemetry_streams_your_own_mission_file(tmp_path, capsys):
    """``telemetry`` had no --plan / --pads (``mission`` has): an integrator streaming their own QGC plan needed a
    TOML with a [mission] file (and ``--set mission.file=...`` was laid over the config after its route was read,
    so the default route was streamed about the file's home). Now the stream flies the plan about its home."""
    import os

    from mission_sim.cli import main
    plan = Path(__file__).resolve().parent / "data" / "missions" / "qgc_simple_square.plan"
    tlog = tmp_path / "square.tlog"
    rc = main(["telemetry", "--plan", str(plan), "--connect", "none", "--tlog", str(tlog), "--speed", "inf",
               "--no-progress"])
    assert rc == 0, capsys.readouterr().err
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil
    with contextlib.closing(mavutil.mavlogfile(str(tlog))) as m:
        pos = []
        while (g := m.recv_match(type="GLOBAL_POSITION_INT", blocking=False)) is not None:
            pos.append((g.lat * 1e-7, g.lon * 1e-7, g.relative_alt * 1e-3))
    pos = np.array(pos)
    assert np.abs(pos[0, :2] - [47.397742, 8.545594]).max() < 1e-4          # starts at the plan's home (Zurich)
    assert pos[:, 2].max() == pytest.approx(20.0, abs=0.5)                   # the plan's 20 m above home
    north_m = (pos[:, 0] - pos[0, 0]) * 111_200
    assert north_m.max() - north_m.min() > 50                                # it flies the square


def test_tcp_ground_station_going_away(capsys):
    """A TCP ground station (``--connect tcp:`` to it) that closes the connection mid-stream: pymavlink printed
    "Connection reset or closed by peer on TCP socket" on stdout for every later frame (4,279 lines in a 30 s
    stream) and the command said "sent 4280 frames". Now nothing is printed per frame, the stream goes on to its
    end (and its .tlog), and the count of delivered frames says where it stopped."""
    import socket
    import threading
    import time

    from mission_sim.mavlink.telemetry import stream
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    port = srv.getsockname()[1]
    got = []

    def ground_station():
        conn, _ = srv.accept()
        conn.settimeout(0.02)
        t_end = time.monotonic() + 0.4
        while time.monotonic() < t_end:
            try:
                got.append(conn.recv(1 << 16))
            except OSError:
                pass
        conn.close()                                       # the ground station goes away
    th = threading.Thread(target=ground_station, daemon=True)
    th.start()
    try:
        st = stream(_series(4.0), connect=f"tcp:127.0.0.1:{port}", rate_hz=10, speed=4.0)
    finally:
        th.join(5)
        srv.close()
    out = capsys.readouterr().out
    assert "Connection reset" not in out and "closed by peer" not in out
    assert st.ticks == 41 and 0 < st.delivered < 0.5 * st.frames
    assert len(b"".join(got)) > 0


def test_position_gap_while_armed_is_warned(tmp_path, dronekit_read):
    """100 s of the dronekit flight cut out of its tlog (a radio out of range): the replay flew a straight line
    across the gap without a word. Now a warning names the gap; the shipped logs (gaps <= 5.3 s) give none."""
    from mission_sim.mavlink.logs import read_log
    from mission_sim.mavlink.replay import replay_span, replay_warnings, track_from_log

    def gap_warnings(log):
        window, _ = replay_span(log, None, None)
        return [w for w in replay_warnings(log, track_from_log(log, window=window)) if "no position" in w]
    ref, rec = dronekit_read
    t0 = rec[0][0]
    log = read_log(write_tlog(tmp_path / "gap.tlog", [(t, f) for t, f in rec if not 600 < t - t0 < 700]))
    w = gap_warnings(log)
    assert len(w) == 1 and "gap.tlog: no position for 101.2 s while armed (log 599.1..700.3 s)" in w[0]
    # what to do, as a sentence (it ended "...; --window can leave it out", in a study "[replay] window = can leave
    # it out"), with the windows that do it, in the study file's words in a study
    assert w[0].endswith("): the replay flies a straight line across it; to leave it out, replay the part before or "
                         "after it: --window T0,599.1 or --window 700.3,T1")
    from mission_sim.studies.replay_cases import _study_words
    assert _study_words(w[0]).endswith("to leave it out, replay the part before or after it: [replay] window = "
                                       "[T0, 599.1] or [replay] window = [700.3, T1]")
    assert gap_warnings(ref) == []


def test_follow_places_the_pads_of_a_pads_file(tmp_path, monkeypatch):
    """``telemetry --follow`` with a pads file (``--pads``, or a config's [mission] pads_file) took the live
    vehicle's first position as the pad frame's origin, while the pads were placed about the file's first pad: a
    vehicle taking off 50 m from the pad was simulated as if the pad were where it took off. Now the frame is the
    file's, as in a streamed mission."""
    from mission_sim.cli import main
    pads = tmp_path / "pads.csv"
    pads.write_text("lat,lon,hover_time_s\n-35.3620800,149.1658531,60\n")
    seen = fake_follow(monkeypatch)
    assert main(["telemetry", "--follow", "udpin:127.0.0.1:14999", "--pads", str(pads), "--connect", "none",
                 "--tlog", str(tmp_path / "f.tlog")]) == 0
    assert seen["home"] is not None
    assert (seen["home"].lat_deg, seen["home"].lon_deg) == pytest.approx((-35.36208, 149.1658531))


def test_replay_pads_far_from_the_log_names_the_file(tmp_path, capsys):
    """``replay LOG --pads pads.csv`` with the pads of another site (Canberra pads, a Norwegian PX4 log) said
    ``pads.0.x_m=6930816.3 is invalid; valid range: [-100000, 100000] m``; now the file, the pad and the distance,
    as for a mission's pads file (one check, ``plans.route.pads_to_local``)."""
    from mission_sim.cli import main
    pads = tmp_path / "pads.csv"
    pads.write_text("lat,lon,hover_time_s\n-35.3620800,149.1658531,60\n")
    rc = main(["replay", str(log_path("pyulog_sample_log_small.ulg")), "--pads", str(pads), "--out",
               str(tmp_path / "out"), "--no-progress", "--no-plot"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert "pads.csv: pad 0 is 13011 km from the replay's pad frame origin" in err[0] and "within 100 km" in err[0]


def test_a_stalled_sender_is_no_clock_step(dronekit_read):
    """The step detection keeps only steps that persist: 10 s of frames held back and delivered in one burst (a radio
    fade, a stalled ground-station process) are no step of the receive clock; the log reads as before. At the log's
    end the burst is its last level, which persistence alone does not tell from a step: the level after a step must
    run on the receive clock."""
    from mission_sim.mavlink.clock import fit_clock
    rng = np.random.default_rng(1)
    boot = np.arange(0.0, 600.0, 0.25)
    recv = boot + 3.0 + 0.05 * rng.random(len(boot))
    stalled = (boot >= 300) & (boot < 310)
    recv[stalled] = 310.0 + 3.0                            # held back, then all at once
    cm = fit_clock(np.arange(len(boot)), recv, boot)
    assert cm.segments[0].steps == ()
    stepped = recv + np.where(boot >= 400, -3600.0, 0.0)   # the same with the clock set back 1 h at 400 s
    cm = fit_clock(np.arange(len(boot)), stepped, boot)
    assert len(cm.segments[0].steps) == 1 and cm.segments[0].steps[0][4] == pytest.approx(-3600.0, abs=0.1)
    t = cm.map(np.arange(len(boot)), stepped)
    assert np.abs(t - recv)[~stalled].max() < 0.01           # receive times with the step taken out (to its median)
    at_end = boot + 3.0 + 0.05 * rng.random(len(boot))
    at_end[boot >= 590] = 600.0 + 3.0                      # held back at the log's end: the burst is its last level
    assert fit_clock(np.arange(len(boot)), at_end, boot).segments[0].steps == ()



@pytest.mark.parametrize("stall_s", [(1030.0, 1060.0), (1000.0, 1060.0)])
def test_a_stall_at_the_end_of_a_log_is_no_clock_step(tmp_path, dronekit_read, stall_s):
    """A stall near the end of the log: the dronekit tlog's frames between 1030 (or 1000) and 1060 s held back and
    delivered in one burst at 1060 s make the burst the log's last level, and the persistence test alone took it
    for a step (+18.2 s; 32.7 s): duration 1358.8 s (1344.4 s) instead of 1377.0 s. A step is kept only if the level
    after it runs on the receive clock (a burst's receive span is ~0); the log reads as the original."""
    from mission_sim.mavlink.logs import read_log
    ref, rec = dronekit_read
    t0 = rec[0][0]
    a, b = stall_s
    path = write_tlog(tmp_path / "stalled.tlog", [(t0 + b if t0 + a < t <= t0 + b else t, f) for t, f in rec])
    log = read_log(path)
    assert log.duration_s == pytest.approx(ref.duration_s, abs=1e-6)
    assert len(log.armed_periods) == len(ref.armed_periods)


class _SlowSocket:
    """A non-blocking TCP socket whose send takes at most the next of ``caps`` bytes (0: EAGAIN), then all."""

    def __init__(self, caps):
        self.caps, self.got = list(caps), bytearray()

    def send(self, buf):
        cap = self.caps.pop(0) if self.caps else len(buf)
        if cap == 0:
            raise BlockingIOError(11, "Resource temporarily unavailable")
        self.got += bytes(buf[:cap])
        return min(cap, len(buf))

    def sendall(self, buf):
        self.got += bytes(buf)

    def settimeout(self, t):
        pass

    def close(self):
        self.closed = True


@pytest.mark.parametrize("kind", ["mavtcp", "mavtcpin"])
def test_tcp_partial_send_keeps_the_stream_whole(kind):
    """A TCP send that takes part of a frame (the ground station's receive window full) put those bytes on the wire
    while the frame counted as undelivered (tcp:) or delivered whole (tcpin:), and the next frame followed them: the
    stream was corrupt. Now the unsent rest goes first; frames that find it still unsent are dropped whole. What the
    ground station gets is exactly the frames counted as delivered, each intact."""
    from mission_sim.mavlink.logs import mavutil
    from mission_sim.mavlink.telemetry import write_frame
    mu = mavutil()
    mav = mu.mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = []
    for k in range(8):
        frames.append(mav.heartbeat_encode(2, 3, 0, k, 4).pack(mav))
        mav.seq = (mav.seq + 1) % 256
    sock = _SlowSocket([len(frames[0]), 5, 0, 3, 0, 0])   # frame 1 in part, its rest blocked, then in part again
    conn = object.__new__(getattr(mu, kind))
    conn.port = sock
    sent = [write_frame(conn, f) for f in frames]
    assert sent.count(False) >= 2                            # frames that met a backlog are lost, whole
    assert bytes(sock.got) == b"".join(f for f, ok in zip(frames, sent) if ok)
    parser = mu.mavlink.MAVLink(None)
    msgs = parser.parse_buffer(bytes(sock.got))
    assert [m.custom_mode for m in msgs] == [k for k, ok in enumerate(sent) if ok]
    # a rest still unsent when the stream ends goes before the link is closed (close_link): no frame cut short
    from mission_sim.mavlink.telemetry import close_link
    conn.port = sock = _SlowSocket([4, 0])
    conn.listen = _SlowSocket([])                           # tcpin's listening socket, closed with it
    assert write_frame(conn, frames[0]) and not write_frame(conn, frames[1])
    close_link(conn)
    assert bytes(sock.got) == frames[0] and sock.closed


def test_write_frame_resolves_pymavlink_once(monkeypatch):
    """write_frame called mavutil() (setting MAVLINK20 and importing) for every frame, ~1 us each: ~33 ms of a
    32,000-frame --speed inf stream. The TCP classes are resolved once per process."""
    import mission_sim.mavlink.telemetry as tel
    from mission_sim.mavlink.logs import mavutil
    calls = []
    monkeypatch.setattr(tel, "mavutil", lambda: calls.append(1) or mavutil())
    monkeypatch.setattr(tel, "_STREAM_CLASSES", (), raising=False)
    conn = object.__new__(mavutil().mavtcp)
    conn.port = _SlowSocket([])
    for _ in range(100):
        assert tel.write_frame(conn, b"\xfd\x00")
    assert len(calls) <= 1 and bytes(conn.port.got) == 100 * b"\xfd\x00"


def test_reading_a_log_or_its_mission_leaves_no_file_open():
    """open_log's readers were never closed: each read of a .tlog / .bin left its file (and map) to the collector,
    a ResourceWarning in the suite's summary. Reading every shipped log and the mission in a .tlog now closes them."""
    import gc
    import warnings

    from mission_sim.mavlink.logs import read_log
    from mission_sim.plans.items import uploaded_mission
    logs = Path(__file__).parent / "data" / "flightlogs"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ResourceWarning)
        for name in ("dronekit-python_flight.tlog", "dronekit-la-testdata_log171.bin", "uavlogviewer_vtol_sitl.tlog"):
            read_log(logs / name)
        uploaded_mission(logs / "uavlogviewer_vtol_sitl.tlog")
        gc.collect()
    assert not [w for w in caught if issubclass(w.category, ResourceWarning)], [str(w.message) for w in caught]


def test_a_log_whose_reader_fails_to_build_leaves_no_file_open(tmp_path):
    """2026-11-27: a DataFlash log with a format pymavlink refuses (its reader's constructor raises): open_log left the
    half-built reader's file to the collector, a ResourceWarning in whichever later test collected it (under -n 2,
    test_reading_a_log_or_its_mission_leaves_no_file_open failed by it). read_log and uploaded_mission close it; a
    broken PX4 ULog's file (pyulog's, given the name) as well."""
    import gc
    import warnings

    from mission_sim.mavlink.logs import read_log
    from mission_sim.plans.items import uploaded_mission
    data = (Path(__file__).parent / "data" / "flightlogs" / "dronekit-la-testdata_log171.bin").read_bytes()
    i = data.index(b"BIHBcLLeeEefI")                   # the GPS format, with a format char pymavlink does not know
    bad = tmp_path / "badfmt.bin"
    bad.write_bytes(data[:i] + b"BIHBcLLeeEefX" + data[i + 13:])
    ulg = tmp_path / "broken.ulg"                      # a PX4 ULog's magic, then no valid header: pyulog's file too
    ulg.write_bytes((Path(__file__).parent / "data" / "flightlogs" / "pyulog_sample_log_small.ulg").read_bytes()[:7] + b"garbage")
    gc.collect()                                       # (what earlier tests left is not this test's)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ResourceWarning)
        assert "Unsupported format char" in read_log(bad).errors[0]
        assert read_log(ulg).errors[0].startswith("pyulog: ")
        with pytest.raises(ValueError, match="could not be parsed"):
            uploaded_mission(bad)
        gc.collect()
    assert not [w for w in caught if issubclass(w.category, ResourceWarning)], [str(w.message) for w in caught]


def test_replay_prints_the_peak_current_against_its_rating(tmp_path, capsys):
    """A replay printed energies and SoC but not the secondary current: the dronekit tlog's 19.6 A against the 15 A
    rating (the drone armed on the pad before take-off) was in the JSON only (2026-11-28, three newcomers). Since the
    pad switch-off protection (2026-11-28) that replay peaks at 14.2 A, within the rating; with the protection off
    (``sim.rectify_after_pad_off=false``, the shorted secondary of before) it is above it again, so both wordings of
    the line are checked on the same real log."""
    import json

    from mission_sim.cli import main

    def run(name, *extra):
        rc = main(["replay", str(log_path("dronekit-python_flight.tlog")), "--out", str(tmp_path / name), "--no-plot",
                   "--no-progress", *extra])
        assert rc == 0
        out = capsys.readouterr().out
        s = json.loads((tmp_path / name / "replay_summary.json").read_text())
        m = json.loads((tmp_path / name / "mission" / "summary.json").read_text())
        return out, s, m

    out, s, m = run("old", "--set", "sim.rectify_after_pad_off=false")
    assert s["peak_i2_a"] > m["rated_i2_a"] == 15.0 and m["time_above_rated_s"] > 0
    assert (f"peak I2 {s['peak_i2_a']:.2f} A instantaneous (envelope {m['peak_i2_envelope_a']:.2f} A; rated 15 A; "
            f"ABOVE it {1e3 * m['time_above_rated_s']:.2f} ms)") in out
    out, s, m = run("new")
    assert s["peak_i2_a"] < m["rated_i2_a"] == 15.0 and m["time_above_rated_s"] == 0
    assert (f"peak I2 {s['peak_i2_a']:.2f} A instantaneous (envelope {m['peak_i2_envelope_a']:.2f} A; rated 15 A; "
            f"above it 0.00 ms)") in out


def test_peak_line_says_above_by_the_time_above_the_rating():
    """The time above the rating is the fundamental's (envelope's): ABOVE went by the instantaneous peak (ripple
    included), so a peak over the rating with no time above it read "ABOVE it for 0.00 ms" and 2 ms above with the
    instantaneous peak under it read as within (reviewer, 2026-11-28)."""
    from mission_sim.cli.common import peak_i2_line
    assert peak_i2_line(15.2, 14.1, 15.0, 0.0) == ("peak I2 15.20 A instantaneous (envelope 14.10 A; rated 15 A; "
                                                   "above it 0.00 ms)")
    assert peak_i2_line(14.9, 15.3, 15.0, 0.002) == ("peak I2 14.90 A instantaneous (envelope 15.30 A; rated 15 A; "
                                                     "ABOVE it 2.00 ms)")
    assert peak_i2_line(14.9, None, None, None) == "peak I2 14.90 A instantaneous"
