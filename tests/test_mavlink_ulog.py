"""PX4 ULog replay (pyulog): the same tables and outputs as for ArduPilot logs, checked against
pyulog read directly (issue 12). The log is a real PX4 flight that starts armed."""

import json

import numpy as np
import pytest

from _flightlogs import ULOG_NAME, log_path
from mission_sim.cli import main
from mission_sim.mavlink.logs import read_log


def _pyulog_reference():
    """Facts from pyulog directly: the start, last sample, vehicle_status arming, GPS, battery 0."""
    from pyulog import ULog
    u = ULog(str(log_path(ULOG_NAME)))
    topic = {(d.name, d.multi_id): d.data for d in u.data_list}
    vs = topic[("vehicle_status", 0)]
    t_vs = np.maximum((vs["timestamp"].astype(np.int64) - u.start_timestamp) / 1e6, 0.0)
    armed = vs["arming_state"] == 2
    first_disarm = t_vs[np.flatnonzero(~armed)[0]]
    g = topic[("vehicle_gps_position", 0)]
    b = topic[("battery_status", 0)]
    # the log's data ends at ~6.5 s; one topic with a single sample (`mission`) claims 1174 s: the
    # reference end is the last sample of the topics with more than one sample
    last = max(int(d["timestamp"].max()) for d in topic.values() if len(d["timestamp"]) > 1)
    stray = max(int(d["timestamp"].max()) for d in topic.values())
    return {"armed_first": bool(armed[0]), "armed_s": float(first_disarm) if armed[0] else None,
            "duration_s": (last - u.start_timestamp) / 1e6, "stray_s": (stray - u.start_timestamp) / 1e6,
            "n_fix": int(np.sum(g["fix_type"] >= 3)),
            "lat": (g["lat"].min() / 1e7, g["lat"].max() / 1e7), "alt": (g["alt"].min() / 1e3, g["alt"].max() / 1e3),
            "volt": (float(b["voltage_v"].min()), float(b["voltage_v"].max())), "n_bat": len(b["voltage_v"])}


def test_ulog_tables_agree_with_pyulog():
    log, ref = read_log(log_path(ULOG_NAME)), _pyulog_reference()
    assert log.kind == "ulog" and log.errors == []
    assert log.duration_s == pytest.approx(ref["duration_s"], abs=1e-6) and 6 < log.duration_s < 7
    assert ref["stray_s"] > 1000 and log.bad_frames == 1            # the stray sample, counted
    # starts armed: armed from the start of the log to vehicle_status's first disarmed report
    assert ref["armed_first"] and log.armed_source == "vehicle_status" and log.starts_armed
    assert log.armed_periods[0][0] == 0.0
    assert log.armed_time_s == pytest.approx(ref["armed_s"], rel=0.02) and ref["armed_s"] > 5
    assert len(log.position) == ref["n_fix"] and sum(log.gps_rejected.values()) == 0
    assert (log.position["lat_deg"].min(), log.position["lat_deg"].max()) == pytest.approx(ref["lat"], abs=1e-9)
    assert (log.position["alt_m"].min(), log.position["alt_m"].max()) == pytest.approx(ref["alt"], abs=1e-6)
    assert log.battery_source == "battery_status" and len(log.battery) == ref["n_bat"]
    assert (log.battery["voltage_v"].min(), log.battery["voltage_v"].max()) == pytest.approx(ref["volt"], abs=1e-5)
    assert 22 < log.battery["voltage_v"].median() < 25.2          # 6S pack, volts (not mV)
    np.testing.assert_allclose(log.battery["power_w"], log.battery["voltage_v"] * log.battery["current_a"])
    # attitude from the quaternion: a multirotor on the ground and in a short hop stays level
    assert len(log.attitude) > 1000 and np.all(np.abs(log.attitude[["roll_rad", "pitch_rad"]].to_numpy()) < 0.5)
    assert 1.6e9 < log.t0_epoch_s < 1.7e9                          # 2021, from the GPS's UTC time


def test_ulog_replay_through_the_cli(capsys, tmp_path):
    assert main(["replay", str(log_path(ULOG_NAME)), "--format", "json", "--no-plot", "--out", str(tmp_path)]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["armed_source"] == "vehicle_status" and s["battery_source"] == "battery_status"
    ref = _pyulog_reference()
    # what the log says, and armed inside the track (which starts at the first GPS fix, 0.16 s in)
    assert s["log_armed_time_s"] == pytest.approx(ref["armed_s"], rel=0.02) and s["starts_armed"]
    assert s["armed_time_s"] == pytest.approx(ref["armed_s"] - s["armed_periods_s"][0][0], abs=0.01)
    assert s["duration_s"] == pytest.approx(ref["duration_s"], abs=1e-6)
    assert s["propulsion_energy_j"] > 0 and 0 <= s["final_soc"] <= 1


def test_broken_ulog_says_pyulog_failed(capsys, tmp_path):
    p = tmp_path / "broken.ulg"
    p.write_bytes(log_path(ULOG_NAME).read_bytes()[:7] + b"garbage")   # magic, then no valid header
    assert main(["replay", str(p), "--no-plot", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "could not be parsed" in err[0] and "pyulog" in err[0]
