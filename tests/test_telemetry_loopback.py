"""Telemetry sender: loopback to a separate receiving process, and the .tlog writer read back."""

import contextlib
import json
import math
import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mission_sim.mavlink.geodesy import GeoPoint, geodetic_to_enu
from mission_sim.mavlink.logs import mavutil, read_log
from mission_sim.mavlink.telemetry import (COPTER_MODES, DEFAULT_HOME, NVF_NAMES, check_connect, check_ids,
                                          mavlink_table, stream)

RECEIVER = Path(__file__).with_name("_mavlink_receiver.py")


def _series(duration_s=2.5, dt=0.01):
    """A mission-shaped time series: circle at 3 m, then hover over the pad charging, then climb."""
    t = np.arange(0.0, duration_s + 1e-9, dt)
    x = 3.0 * np.cos(t)
    y = 3.0 * np.sin(t)
    z = 0.2 + 0.4 * t
    charging = (t > 0.8) & (t < 1.6)
    i_batt = np.where(charging, 4.0, -6.0)                  # + = charging
    soc = 0.5 + np.cumsum(i_batt * dt) / (5.0 * 3600)
    return pd.DataFrame({"t_s": t, "x_m": x, "y_m": y, "z_m": z, "lm_h": 6.25e-6 * np.exp(-t),
                         "i2_amp_a": np.where(charging, 11.0, 0.0) + t, "d_short": np.clip(t / 2.5, 0, 1),
                         "battery_v": 29.6 + 0.1 * np.sin(t), "battery_current_a": i_batt, "soc": soc,
                         "i1_amp_a": np.where(charging, 20.0, 0.0), "rect_current_a": np.where(charging, 4.5, 0.0),
                         "charge_cmd_a": np.where(charging, 5.0, 0.0), "tx_on": charging,
                         "propulsion_w": np.full(len(t), 100.0),
                         "phase": np.where(charging, "charge", "transit")})


def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _loopback(ts, duration_s, **kw):
    """Stream ``ts`` to a separate receiving process over loopback UDP; (stats, messages by type)."""
    port = _free_port()
    rx = subprocess.Popen([sys.executable, str(RECEIVER), str(port), "8"], stdout=subprocess.PIPE, text=True,
                          env={**os.environ, "PYTHONPATH": ""})
    try:
        assert rx.stdout.readline().strip() == "READY"
        st = stream(ts, connect=f"udpout:127.0.0.1:{port}", duration_s=duration_s, **kw)
        out, _ = rx.communicate(timeout=15)
    finally:
        if rx.poll() is None:
            rx.kill()
    by = {}
    for m in json.loads(out.strip().splitlines()[-1]):
        by.setdefault(m["msg"], []).append(m)
    return st, by


def test_loopback_contents_and_rates():
    ts = _series()
    st, by = _loopback(ts, 2.0, rate_hz=10.0, speed=1.0, sysid=42, compid=7)
    # real-time pacing at speed 1: 2 s of mission cannot be sent faster than in 2 s of wall time (a
    # loaded machine can only make it slower, so no upper bound on wall time is asserted)
    assert st.ticks == 21 and st.wall_s >= 1.9
    assert {"HEARTBEAT", "SYS_STATUS", "BATTERY_STATUS", "GLOBAL_POSITION_INT", "NAMED_VALUE_FLOAT",
            "GPS_RAW_INT", "ATTITUDE", "VFR_HUD"} <= set(by)
    assert all(m["version"] == 2 and (m["sys"], m["comp"]) == (42, 7) for ms in by.values() for m in ms)
    # every tick arrived (loopback), and at the requested rate: ATTITUDE and VFR_HUD too
    gp = by["GLOBAL_POSITION_INT"]
    assert len(gp) == len(by["ATTITUDE"]) == len(by["VFR_HUD"]) == st.ticks
    assert len(by["NAMED_VALUE_FLOAT"]) == len(NVF_NAMES) * st.ticks
    arrival = np.array([m["t"] for m in gp])
    rate = (len(arrival) - 1) / (arrival[-1] - arrival[0])
    assert rate <= 10.0 * 1.1                       # never faster than the requested 10 Hz
    assert np.all(np.diff([m["time_boot_ms"] for m in gp]) == 100)
    assert np.all(np.diff([m["time_boot_ms"] for m in by["ATTITUDE"]]) == 100)
    # HEARTBEAT at 0, 1 and 2 s of simulated time (= wall time at speed 1), an ArduCopter quad; then
    # the landing (the series ends in the air: LAND, armed) and the disarm
    hb_all = by["HEARTBEAT"]
    assert all(m["type"] == 2 and m["autopilot"] == 3 for m in hb_all)
    hb, land = hb_all[:-2], hb_all[-2:]
    assert len(hb) == 3 and [m["custom_mode"] for m in land] == [COPTER_MODES["LAND"]] * 2
    assert land[0]["base_mode"] & 128 and land[0]["system_status"] == 4      # armed, ACTIVE, landing
    assert not land[1]["base_mode"] & 128 and land[1]["system_status"] == 3  # disarmed, STANDBY
    assert [m["landed_state"] for m in by["EXTENDED_SYS_STATE"]] == [2, 2, 2, 4, 1]  # in air .. landing, on ground
    _check_gps_quality(by["GPS_RAW_INT"])
    assert np.all(np.abs(np.diff([m["t"] for m in hb]) - 1.0) < 0.3)
    # contents: the sample at each tick, in wire units
    tick_t = np.array([m["time_boot_ms"] for m in gp]) / 1e3
    k = np.searchsorted(ts["t_s"], tick_t + 1e-9, side="right") - 1
    ref = ts.iloc[k].reset_index(drop=True)
    e, n, u = geodetic_to_enu(np.array([m["lat"] for m in gp]) / 1e7, np.array([m["lon"] for m in gp]) / 1e7,
                              np.array([m["alt"] for m in gp]) / 1e3, DEFAULT_HOME)
    np.testing.assert_allclose(e, ref["x_m"], atol=0.02)
    np.testing.assert_allclose(n, ref["y_m"], atol=0.02)
    np.testing.assert_allclose(u, ref["z_m"], atol=2e-3)
    np.testing.assert_allclose([m["relative_alt"] / 1e3 for m in gp], ref["z_m"], atol=1e-3)
    # velocity on the circle: 3 rad/s * ... = 3 m/s tangential; NED north = d(y)/dt
    np.testing.assert_allclose([m["vx"] / 100 for m in gp[1:-1]], 3.0 * np.cos(ref["t_s"][1:-1]), atol=0.02)
    # ATTITUDE yaw = course over ground: on the circle x = 3 cos t, y = 3 sin t the velocity points
    # along (-sin t, cos t) (east, north), i.e. yaw = atan2(-sin t, cos t) = -t (wrapped)
    yaw = np.array([m["yaw"] for m in by["ATTITUDE"]])[1:-1]
    np.testing.assert_allclose(np.angle(np.exp(1j * (yaw + ref["t_s"][1:-1]))), 0.0, atol=0.02)
    hud = by["VFR_HUD"]
    np.testing.assert_allclose([m["groundspeed"] for m in hud[1:-1]], 3.0, atol=0.05)
    np.testing.assert_allclose([m["climb"] for m in hud[1:-1]], 0.4, atol=0.01)
    np.testing.assert_allclose([m["alt"] for m in hud], DEFAULT_HOME.alt_m + ref["z_m"], atol=2e-3)
    assert {m["throttle"] for m in hud} == {50}        # constant power = the hover reference: 50 %
    _check_named_values(by["NAMED_VALUE_FLOAT"], ref)
    # battery: charging state while the battery current is a net charge, current sign per MAVLink
    bs = by["BATTERY_STATUS"]
    charging = ref["battery_current_a"].to_numpy() > 0
    assert [m["charge_state"] for m in bs] == [7 if c else 1 for c in charging]
    assert [m["current_battery"] for m in bs] == list(np.round(-ref["battery_current_a"] * 100).astype(int))
    assert [m["voltages"][0] for m in bs] == list(np.round(ref["battery_v"] * 1000).astype(int))
    assert all(v == 65535 for m in bs for v in m["voltages"][1:])
    assert [m["battery_remaining"] for m in bs] == list(np.round(ref["soc"] * 100).astype(int))
    ss = by["SYS_STATUS"]
    assert [m["voltage_battery"] for m in ss] == [m["voltages"][0] for m in bs]
    _check_sys_status_and_mode(ss, hb, ts)


def _check_gps_quality(gps):
    """What a pre-flight checker reads: a 3D fix, 10..14 satellites (>= 6), HDOP 0.8..1.2 (eph in cm)."""
    assert all(m["fix_type"] == 3 for m in gps)
    assert all(10 <= m["satellites_visible"] <= 14 for m in gps)
    assert all(80 <= m["eph"] <= 120 and 120 <= m["epv"] <= 160 for m in gps)


def _check_named_values(nvf_msgs, ref):
    """Names a ground station can graph, values the series' own at each tick."""
    assert all(re.fullmatch(r"[0-9A-Z_]{1,10}", m["name"]) for m in nvf_msgs)
    nvf = {name: np.array([m["value"] for m in nvf_msgs if m["name"] == name]) for name in NVF_NAMES}
    np.testing.assert_allclose(nvf["I2"], ref["i2_amp_a"], rtol=1e-6)
    np.testing.assert_allclose(nvf["I1"], ref["i1_amp_a"], rtol=1e-6)
    np.testing.assert_allclose(nvf["DUTY"], ref["d_short"], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(nvf["LM_UH"], ref["lm_h"] * 1e6, rtol=1e-6)
    np.testing.assert_allclose(nvf["PAD_ON"], ref["tx_on"].astype(float))
    np.testing.assert_allclose(nvf["CHG_CMD"], ref["charge_cmd_a"], rtol=1e-6)
    np.testing.assert_allclose(nvf["I_RECT"], ref["rect_current_a"], rtol=1e-6)
    d = ref["d_short"].to_numpy()
    np.testing.assert_allclose(nvf["SBAR_MODE"], np.where(d <= 0, 0, np.where(d >= 1, 2, 1)))


def _check_sys_status_and_mode(ss, hb, ts):
    """SYS_STATUS bits consistent (what is present is enabled and healthy, the geofence healthy so no
    breach), and the ArduCopter mode: LOITER (5) while hover-charging, AUTO (3) in transit."""
    m = mavutil().mavlink
    for s in ss:
        assert s["onboard_control_sensors_present"] == s["onboard_control_sensors_enabled"]
        assert s["onboard_control_sensors_health"] & s["onboard_control_sensors_present"] \
            == s["onboard_control_sensors_present"]
        assert s["onboard_control_sensors_health"] & m.MAV_SYS_STATUS_GEOFENCE
        assert not s["onboard_control_sensors_present"] & m.MAV_SYS_STATUS_GEOFENCE
    base = m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | m.MAV_MODE_FLAG_SAFETY_ARMED | m.MAV_MODE_FLAG_STABILIZE_ENABLED
    assert all(h["base_mode"] & base == base for h in hb)
    t_hb = np.arange(len(hb), dtype=float)
    k = np.searchsorted(ts["t_s"], t_hb + 1e-9, side="right") - 1
    want = np.where(ts["phase"].to_numpy()[k] == "charge", COPTER_MODES["LOITER"], COPTER_MODES["AUTO"])
    assert [h["custom_mode"] for h in hb] == list(want) and COPTER_MODES["LOITER"] in want


@pytest.mark.parametrize("rate_hz", [10.0, 4.0, 3.0, 2.5, 0.7])
def test_heartbeat_every_second_of_simulated_time(tmp_path, rate_hz):
    """Whatever the stream rate, HEARTBEATs are 1.0 s apart on the simulated clock (.tlog stamps)."""
    path = tmp_path / "hb.tlog"
    stream(_series(duration_s=12.0, dt=0.05), tlog=path, rate_hz=rate_hz, speed=math.inf, start_epoch_s=1.7e9)
    with contextlib.closing(mavutil().mavlink_connection(str(path))) as conn:
        hb, att = [], []
        while (msg := conn.recv_match(blocking=False)) is not None:
            if msg.get_type() == "HEARTBEAT" and msg.custom_mode != COPTER_MODES["LAND"]:  # not the landing at the end
                hb.append(msg._timestamp - 1.7e9)
            elif msg.get_type() == "ATTITUDE":
                att.append(msg._timestamp - 1.7e9)
    n_ticks = math.floor(12.0 * rate_hz + 1e-9) + 1
    last_tick = (n_ticks - 1) / rate_hz                  # the stream ends at its last tick
    np.testing.assert_allclose(hb, np.arange(math.floor(last_tick + 1e-9) + 1.0), atol=1e-6)
    assert len(att) == n_ticks
    np.testing.assert_allclose(np.diff(att), 1.0 / rate_hz, atol=1e-6)


def test_consumed_is_net_and_accumulates():
    """current_consumed / energy_consumed: the net integral of the discharge (falls while charging)."""
    ts = _series(duration_s=20.0, dt=0.05)
    tab = mavlink_table(ts)
    t = ts["t_s"].to_numpy()
    i = ts["battery_current_a"].to_numpy()
    net_c = np.cumsum(-i * np.diff(t, prepend=t[0]))
    np.testing.assert_array_equal(tab["consumed_mah"], np.round(net_c / 3.6).astype(int))
    charging = ts["battery_current_a"].to_numpy() > 0
    dc = np.diff(net_c)
    assert np.all(dc[charging[1:]] < 0) and np.all(dc[~charging[1:]] > 0)


def test_tlog_written_reads_back_with_pymavlink(tmp_path):
    ts = _series(duration_s=20.0, dt=0.05)
    path = tmp_path / "sim.tlog"
    epoch = 1.7e9
    st = stream(ts, tlog=path, rate_hz=5.0, speed=math.inf, start_epoch_s=epoch)
    assert st.ticks == 101
    # pymavlink directly: every frame MAVLink 2, timestamps on the simulated clock, no bad data
    with contextlib.closing(mavutil().mavlink_connection(str(path))) as m:
        n, types, stamps = 0, set(), []
        while (msg := m.recv_match(blocking=False)) is not None:
            assert msg.get_type() != "BAD_DATA" and msg.get_msgbuf()[:1] == b"\xfd"
            n += 1
            types.add(msg.get_type())
            if msg.get_type() == "GLOBAL_POSITION_INT":
                stamps.append(msg._timestamp - epoch)
    assert n == st.frames and {"BATTERY_STATUS", "NAMED_VALUE_FLOAT", "HEARTBEAT"} <= types
    np.testing.assert_allclose(stamps, np.arange(101) / 5.0, atol=1e-6)
    # and through our own reader: the flight comes back about the same home
    log = read_log(path)
    assert log.bad_frames == 0 and set(log.mavlink_frames) == {2} and log.battery_source == "BATTERY_STATUS"
    assert len(log.position) == 101 and log.duration_s == pytest.approx(21.0, abs=1e-6)  # + 1 s: land, disarm
    assert log.armed_periods == [pytest.approx((0.0, 21.0), abs=1e-6)]       # the disarm ends the armed period
    e, n_, u = geodetic_to_enu(log.position["lat_deg"], log.position["lon_deg"], log.position["alt_m"], DEFAULT_HOME)
    k = np.searchsorted(ts["t_s"], log.position["t_s"].to_numpy() + 1e-4, side="right") - 1  # float epoch: ~0.2 us
    np.testing.assert_allclose(e, ts["x_m"].to_numpy()[k], atol=0.02)
    np.testing.assert_allclose(u, ts["z_m"].to_numpy()[k], atol=2e-3)
    np.testing.assert_allclose(log.battery["voltage_v"], ts["battery_v"].to_numpy()[k], atol=1e-3)
    np.testing.assert_allclose(log.battery["current_a"], -ts["battery_current_a"].to_numpy()[k], atol=1e-2)


def test_bad_inputs():
    with pytest.raises(ValueError, match="udpout:HOST:PORT"):
        check_connect("udpout:127.0.0.1")
    with pytest.raises(ValueError, match="udpout:HOST:PORT"):
        check_connect("serial:/dev/ttyS0:57600")
    assert check_connect("udpout:127.0.0.1:14550") == "udpout:127.0.0.1:14550"
    with pytest.raises(ValueError, match="rate"):
        stream(_series(), tlog="x.tlog", rate_hz=0)
    with pytest.raises(ValueError, match="columns"):
        mavlink_table(_series().drop(columns=["soc"]))
    with pytest.raises(ValueError, match="nothing to do"):
        stream(_series())
    assert GeoPoint(0, 0, 0).alt_m == 0
    for bad in [(0, 1), (1, 256), (-1, 1), (1.5, 1)]:
        with pytest.raises(ValueError, match="valid range: 1..255"):
            check_ids(*bad)
        with pytest.raises(ValueError, match="1..255"):
            stream(_series(), tlog="x.tlog", sysid=bad[0], compid=bad[1])


def test_mixed_mavlink1_and_2_tlog(tmp_path):
    """A MAVLink 1 log continued by MAVLink 2 frames (as after a firmware update) reads as one log."""
    from _flightlogs import log_path
    data = log_path("uavlogviewer_vtol_sitl.tlog").read_bytes()
    cut = 0
    while cut < 60_000:  # whole records: 8-byte time + MAVLink 1 frame (6 + payload + 2 bytes)
        assert data[cut + 8] == 0xFE
        cut += 16 + data[cut + 9]
    v1 = data[:cut]
    head = tmp_path / "v1.tlog"
    head.write_bytes(v1)
    first = read_log(head)
    assert set(first.mavlink_frames) == {1} and len(first.position) > 10
    tail = tmp_path / "v2.tlog"
    stream(_series(duration_s=5.0, dt=0.05), tlog=tail, rate_hz=5.0, speed=math.inf,
           start_epoch_s=first.t0_epoch_s + first.duration_s + 10.0)
    mixed = tmp_path / "mixed.tlog"
    mixed.write_bytes(v1 + tail.read_bytes())
    log = read_log(mixed)
    assert log.bad_frames == first.bad_frames == 0
    assert log.mavlink_frames[1] == first.mavlink_frames[1] and log.mavlink_frames[2] == stream_frames(tail)
    assert len(log.position) == len(first.position) + 26
    assert log.duration_s == pytest.approx(first.duration_s + 16.0, abs=1e-3)  # + 1 s: landing and disarm


def stream_frames(path):
    with contextlib.closing(mavutil().mavlink_connection(str(path))) as m:
        n = 0
        while m.recv_match(blocking=False) is not None:
            n += 1
    return n
