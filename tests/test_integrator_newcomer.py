"""A drone integrator's pass (2026-11-27): what replaying real logs, flying one's own mission files and
streaming telemetry to a ground station found, each case a test that failed before its fix
(docs/robustness.md, "A drone integrator's pass")."""

from __future__ import annotations

import numpy as np
import pytest

from _flightlogs import log_path
from mission_sim.config import load_config


def test_replay_disarmed_draws_avionics_only():
    """A replayed log's disarmed samples ("ground": motors off) draw the avionics alone. The per-sample
    arrays moved into chunks (world/samples.py) had dropped the replay's override, so a disarmed ROV
    sitting on the bench for 247 s drew hover power (98.8 W): 26.0 kJ of 'propulsion' instead of 3.6 kJ."""
    import policies
    from mission_sim.mavlink.replay import replay_log

    cfg = load_config(None)
    res = replay_log(log_path("ardusub_log_tools_small_rov.tlog"), cfg, policies.make("model_based"))
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
    ``[Errno 111] Connection refused`` naming no option; now one line naming --connect, nothing simulated."""
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
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
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
    assert f"--connect udpin:127.0.0.1:{port} listens: no ground station contacted it, so nothing was delivered" in err
    assert "use --connect udpout:HOST:14550" in err
