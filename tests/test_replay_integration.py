"""Replay of the real logs through the mission runner, telemetry round trips, --follow with a live vehicle.

These need the mission world of issue 4 (mission_sim.world.runner.run_mission); windows keep each
replay short.
"""

import contextlib
import json
import math
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from _flightlogs import log_path, pymavlink_reference
from mission_sim.cli import main
from mission_sim.mavlink.logs import read_log

WINDOWS = {  # log seconds: arming on the pad, take-off, some flying
    "dronekit-python_flight.tlog": (455.0, 505.0),
    "dronekit-la-testdata_log171.bin": (55.0, 105.0),
    "uavlogviewer_vtol_sitl.tlog": (0.0, 50.0),
}
_ref: dict = {}
_runs: dict = {}


def _reference(name):
    if name not in _ref:
        _ref[name] = pymavlink_reference(log_path(name))
    return _ref[name]


def _replay(capsys, name, tmp_path, *extra):
    """Summary of `dronewpt replay` on the log's window (cached per arguments; the output folder
    of the first run is kept in the summary as "_out")."""
    key = (name, *extra)
    if key not in _runs:
        w = WINDOWS[name]
        out = tmp_path / "out"
        argv = ["replay", str(log_path(name)), "--window", f"{w[0]},{w[1]}", "--format", "json",
                "--out", str(out), "--no-plot", *extra]
        assert main(argv) == 0
        _runs[key] = {**json.loads(capsys.readouterr().out), "_out": str(out)}
    return _runs[key]


def _series_m_per_deg(lat_deg):
    phi = np.radians(lat_deg)
    return (111132.92 - 559.82 * np.cos(2 * phi) + 1.175 * np.cos(4 * phi),
            111412.84 * np.cos(phi) - 93.5 * np.cos(3 * phi) + 0.118 * np.cos(5 * phi))


@pytest.mark.parametrize("name", list(WINDOWS))
def test_replay_real_log(capsys, tmp_path, name):
    s = _replay(capsys, name, tmp_path)
    ref = _reference(name)
    for key in ("duration_s", "distance_m", "max_alt_m", "armed_time_s", "n_position_samples", "bad_frames",
                "rectifier_output_j", "battery_charge_in_j", "propulsion_energy_j"):
        assert isinstance(s[key], (int, float)) and math.isfinite(s[key]), key
    assert s["duration_s"] == pytest.approx(ref["duration_s"], abs=1e-6)
    assert s["bad_frames"] == ref["bad"]
    w0, w1 = WINDOWS[name]
    # armed time inside the window, from pymavlink's armed periods
    armed_ref = sum(max(0.0, min(b, w1) - max(a, w0)) for a, b in ref["armed_periods"])
    assert s["armed_time_s"] == pytest.approx(armed_ref, abs=1.0)  # the track starts/ends at a fix sample
    # distance: the same positions through the standard metres-per-degree series
    log = read_log(log_path(name))
    pos = log.position[(log.position["t_s"] >= w0) & (log.position["t_s"] <= w1)]
    assert s["n_position_samples"] <= len(pos) and s["n_position_samples"] >= 0.9 * len(pos)
    mlat, mlon = _series_m_per_deg(s["pad"]["lat_deg"])
    n = (pos["lat_deg"].to_numpy() - s["pad"]["lat_deg"]) * mlat
    e = (pos["lon_deg"].to_numpy() - s["pad"]["lon_deg"]) * mlon
    horiz = np.sum(np.hypot(np.diff(e), np.diff(n)))
    assert s["horizontal_distance_m"] == pytest.approx(horiz, rel=0.03)
    assert s["distance_m"] >= s["horizontal_distance_m"]
    # energy: nothing from nowhere
    assert 0 <= s["rectifier_output_j"] <= s["energy_from_source_j"] + 1e-9
    assert s["propulsion_energy_j"] > 0
    # the timeseries written closes the propulsion energy
    ts = __import__("pandas").read_parquet(Path(s["_out"]) / "mission" / "timeseries.parquet")
    e_prop = float(np.sum(0.5 * (ts["propulsion_w"].to_numpy()[1:] + ts["propulsion_w"].to_numpy()[:-1])
                          * np.diff(ts["t_s"].to_numpy())))
    assert s["propulsion_energy_j"] == pytest.approx(e_prop, rel=0.05)
    if ref["power"]:
        # logged energy = integral of V I from pymavlink's own samples over the same span
        t, p = np.array(ref["power"]).T
        t0, t1 = s["window_s"]
        lo = max(t0, log.position["t_s"][log.position["t_s"] >= t0].iloc[0])
        m = (t >= lo) & (t <= lo + s["position_span_s"])
        assert s["logged_energy_j"] == pytest.approx(np.trapezoid(p[m], t[m]), rel=0.02)
        c = s["power_comparison"]
        assert c["n_samples_airborne"] > 20
        # a 3S / 4S quad of ~1.5 kg hovers on far more than the 1 kg default drone's ~99 W
        assert c["logged_mean_w"] > c["model_mean_w"] and 1.0 < c["equivalent_mass_kg"] < 4.0
    else:
        assert "logged_energy_j" not in s and s["battery_source"] is None


def test_equivalent_mass_closes_the_energy(capsys, tmp_path):
    """Re-running with the fitted mass makes the model's airborne energy match the log's."""
    name = "dronekit-python_flight.tlog"
    s1 = _replay(capsys, name, tmp_path)
    m = s1["power_comparison"]["equivalent_mass_kg"]
    s2 = _replay(capsys, name, tmp_path, "--mass", f"{m:.6f}")
    c2 = s2["power_comparison"]
    assert abs(c2["energy_error_rel"]) < 0.01
    assert abs(s1["power_comparison"]["energy_error_rel"]) > 0.1   # the default drone was off


def test_pad_far_away_gets_no_power(capsys, tmp_path):
    """Pad at the take-off spot: the armed drone sits on it and charges; 300 m away: nothing."""
    name = "dronekit-python_flight.tlog"
    near = _replay(capsys, name, tmp_path)
    lat, lon = near["pad"]["lat_deg"], near["pad"]["lon_deg"]
    far = _replay(capsys, name, tmp_path, f"--pad={lat},{lon + 300 / _series_m_per_deg(lat)[1]}")
    assert near["rectifier_output_j"] > 0
    assert far["rectifier_output_j"] == 0 and far["energy_from_source_j"] == 0
    assert far["propulsion_energy_j"] == pytest.approx(near["propulsion_energy_j"], rel=1e-6)


def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


SHORT_MISSION = ["--set", "pads.0.hover_time_s=8", "--set", "pads.1.hover_time_s=8"]


def test_telemetry_cli_shows_charging_and_replays(capsys, tmp_path):
    """A mission streamed to a separate receiver and to a .tlog: the drone shows CHARGING over the
    pads only, and `dronewpt replay` of that .tlog gives back the flown distance."""
    port = _free_port()
    # generous bounds: on a loaded machine the CLI can take seconds to start streaming
    rx = subprocess.Popen([sys.executable, str(Path(__file__).with_name("_mavlink_receiver.py")), str(port), "60", "3"],
                          stdout=subprocess.PIPE, text=True)
    tlog = tmp_path / "mission.tlog"
    try:
        assert rx.stdout.readline().strip() == "READY"
        assert main(["telemetry", "--connect", f"udpout:127.0.0.1:{port}", "--rate", "4", "--speed", "100",
                     "--tlog", str(tlog), *SHORT_MISSION]) == 0
        out, _ = rx.communicate(timeout=70)
    finally:
        if rx.poll() is None:
            rx.kill()
    capsys.readouterr()
    msgs = json.loads(out.strip().splitlines()[-1])
    bs = [m for m in msgs if m["msg"] == "BATTERY_STATUS"]
    gp = [m for m in msgs if m["msg"] == "GLOBAL_POSITION_INT"]
    assert len(bs) == len(gp) > 50
    charging = np.array([m["charge_state"] == 7 for m in bs])
    rel_alt = np.array([m["relative_alt"] for m in gp]) / 1e3
    assert charging.any() and (~charging).any()
    assert np.all(rel_alt[charging] < 1.0)            # charging happens hovering low over a pad
    lm = np.array([m["value"] for m in msgs if m["msg"] == "NAMED_VALUE_FLOAT" and m["name"] == "LM_UH"])
    # Lm is held from the runner's last sample (coarse steps up to sim.flight_dt_s = 1 s): check at cruise
    assert np.all(lm >= 0) and lm.max() > 1.0 and np.all(lm[rel_alt > 4.5] < 0.5)  # uH
    # the .tlog: pymavlink reads it back, and the replay sees the mission's path
    assert main(["replay", str(tlog), "--format", "json", "--out", str(tmp_path / "rp"), "--no-plot",
                 "--pad=-35.363261,149.165230,584"]) == 0   # the mission's first pad is at the home
    s = json.loads(capsys.readouterr().out)
    log = read_log(tlog)
    assert log.bad_frames == 0 and s["battery_source"] == "BATTERY_STATUS"
    assert s["n_position_samples"] == len(log.position) > 50
    assert s["rectifier_output_j"] > 0
    # closed loop: the "logged" power is the simulator's own (V I of its battery, no charging while
    # airborne), so the comparison must find the model and the default 1 kg drone again
    c = s["power_comparison"]
    assert c["n_samples_airborne"] > 20 and abs(c["energy_error_rel"]) < 0.05
    assert c["equivalent_mass_kg"] == pytest.approx(1.0, rel=0.05) and c["correlation"] > 0.5


def test_follow_live_vehicle(tmp_path):
    """--follow: a separate process plays the vehicle; the simulation follows its positions."""
    import argparse

    from mission_sim.cli import mavlink as cli
    from mission_sim.mavlink import follow
    from mission_sim.world.runner import run_mission
    port = _free_port()
    tlog = tmp_path / "follow.tlog"
    vin = follow.open_follow(f"udpin:127.0.0.1:{port}")  # bound before the vehicle starts
    cfg = cli._mav_config(argparse.Namespace(config=None, set=[]))
    veh = subprocess.Popen([sys.executable, str(Path(__file__).with_name("_fake_vehicle.py")), str(port), "3.5"],
                           stdout=subprocess.PIPE, text=True)
    try:
        assert veh.stdout.readline().strip() == "ready"   # its connection is open: it sends from now on
        st = follow.follow(f"udpin:127.0.0.1:{port}", cfg, cli._mav_policy(cfg, "model_based"), run_mission,
                              rate_hz=5.0, tlog=tlog, max_wall_s=30.0, idle_timeout_s=1.0, in_conn=vin)
        sent = int(veh.communicate(timeout=10)[0].split()[-1])
    finally:
        if veh.poll() is None:
            veh.kill()
    rc = 0 if st.positions == sent else 1
    assert rc == 0 and sent == 36 and st.chunks >= 3, (st, sent)   # every position arrived, ~1 s chunks
    log = read_log(tlog)
    assert len(log.position) >= 8 and log.battery_source == "BATTERY_STATUS"
    # the simulated drone is where the vehicle was: standing on the home point (the pad, charging),
    # then 3 m up flying east at 2 m/s
    p = log.position
    assert p["lat_deg"].iloc[0] == pytest.approx(-35.363261, abs=2e-7)
    assert p["lon_deg"].iloc[0] == pytest.approx(149.165230, abs=2e-7)
    east = (p["lon_deg"].to_numpy() - 149.165230) * 90882.98
    up = p["alt_m"].to_numpy() - 584.0
    assert east.max() > 1.0 and np.all(np.diff(east) > -0.05)
    flying = up > 2.9
    assert flying.any() and (~flying).any()
    speed = np.diff(east[flying]) / np.diff(p["t_s"].to_numpy()[flying])
    np.testing.assert_allclose(speed, 2.0, atol=0.3)  # the vehicle's clock spaces the samples
    current = log.battery["current_a"].to_numpy()   # MAVLink sign: < 0 = charging
    n = min(len(current), len(flying))
    assert np.any(current[:n][~flying[:n]] < 0)      # charging while standing on the pad
    assert np.all(current[:n][flying[:n]] > 0)       # never 3 m up
    hb = _heartbeats(tlog)                           # the stream ends as `telemetry`'s: LAND, then disarmed
    assert [h.custom_mode for h in hb[-2:]] == [9, 9] and hb[-2].base_mode & 128 and not hb[-1].base_mode & 128


def _heartbeats(tlog):
    from mission_sim.mavlink.logs import mavutil
    with contextlib.closing(mavutil().mavlink_connection(str(tlog))) as conn:
        out = []
        while (m := conn.recv_match(type="HEARTBEAT")) is not None:
            out.append(m)
    return out


def test_follow_through_the_cli(capsys, tmp_path):
    """`dronewpt telemetry --follow`: end to end through the CLI (the vehicle may start before the
    CLI listens, so only the flying part is asserted)."""
    port = _free_port()
    tlog = tmp_path / "cli_follow.tlog"
    veh = subprocess.Popen([sys.executable, str(Path(__file__).with_name("_fake_vehicle.py")), str(port), "4.0"],
                           stdout=subprocess.PIPE, text=True)
    try:
        rc = main(["telemetry", "--follow", f"udpin:127.0.0.1:{port}", "--follow-time", "30", "--follow-idle", "1",
                   "--connect", "none", "--tlog", str(tlog), "--rate", "5"])
        veh.communicate(timeout=10)
    finally:
        if veh.poll() is None:
            veh.kill()
    assert rc == 0 and "followed" in capsys.readouterr().out
    p = read_log(tlog).position
    east = (p["lon_deg"].to_numpy() - 149.165230) * 90882.98
    assert len(p) >= 5 and east.max() > 1.0


def test_follow_chunks_join_as_one_continuous_mission():
    """ChunkedMission fed a track second by second reports what one continuous run gives: the
    link's electrical state carries across chunks (I2 at every tick), the battery's charge and the
    net consumed charge / energy accumulate over the whole run, ticks every 1 / rate and HEARTBEATs
    every second with no gap at the end."""
    import argparse

    from mission_sim.cli import mavlink as cli
    from mission_sim.mavlink.follow import ChunkedMission
    from mission_sim.mavlink.telemetry import DEFAULT_HOME, drawn_totals
    from mission_sim.world.runner import run_mission
    from mission_sim.world.trajectory import Trajectory
    cfg = cli._mav_config(argparse.Namespace(config=None, set=[]))
    policy = cli._mav_policy(cfg, "model_based")
    t = np.arange(0.0, 8.05, 0.1)   # 3.55 s on the pad (charging), then east at 2 m/s, 3 m up
    up = np.clip((t - 3.55) * 2.0, 0.0, 3.0)
    pos = np.column_stack([np.maximum(t - 3.55, 0.0) * 2.0, np.zeros_like(t), up + cfg.mission.hover_gap_m])
    sim = ChunkedMission(cfg, policy, run_mission, DEFAULT_HOME, 10.0)
    events = []
    for ti, p in zip(t, pos):
        sim.add(ti, p)
        if sim.pending_s() >= 1.0:
            events += sim.simulate()
    if sim.pending_s() > 0:
        events += sim.simulate()                                # the last, partial chunk
    assert 7 <= sim.chunks <= 9
    ticks = [(te, row) for te, row, hb in events if not hb]
    tt = np.array([te for te, _ in ticks])
    np.testing.assert_allclose(tt, np.arange(81) / 10.0, atol=1e-9)         # no gap, to the last sample
    np.testing.assert_allclose([te for te, _, hb in events if hb], np.arange(9.0))
    full = run_mission(cfg, policy, trajectory=Trajectory.from_samples(t, pos))
    ts = full.timeseries
    k = np.clip(np.searchsorted(ts["t_s"], tt + 1e-9, side="right") - 1, 0, len(ts) - 1)
    i2_chunked = np.array([row.i2_a for _, row in ticks])
    # (a chunk ends at the newest sample, whose speed it knows from the past only: a take-off right
    # at a chunk's last sample would keep the pad on there for one more sample than a run that
    # knows the next sample; this track takes off between chunk ends)
    np.testing.assert_allclose(i2_chunked, ts["i2_amp_a"].to_numpy()[k], rtol=1e-3, atol=1e-3)
    assert i2_chunked[1:30].min() > 10.0                # charging on the pad: no restart at 1 s, 2 s
    c, j = drawn_totals(ts)
    # measured: SoC 0.98245 vs 0.98254 (0.44 C of the 4680 C pack), drawn 11.57 vs 11.49 C: the
    # runner's coarse 1 s steps in flight fall on other instants in the chunks, and the battery's
    # RC polarisation (tau 15 s) restarts at each chunk's warm-up (no initial-state hook in the runner)
    assert sim.final_soc == pytest.approx(full.summary["final_soc"], abs=2e-4)
    assert sim.drawn[0] == pytest.approx(c[-1], rel=0.02) and sim.drawn[1] == pytest.approx(j[-1], rel=0.02)
    mah = np.array([row.consumed_mah for _, row in ticks])
    assert mah[30] < mah[1] <= 0 < mah[-1]              # net: falls while charging, then rises in flight
    assert mah[-1] == pytest.approx(c[-1] / 3.6, abs=1.0)
