"""mission_sim.mavlink.logs and the log-only parts of mission_sim.mavlink.replay against pymavlink directly."""

from pathlib import Path

import numpy as np
import pytest

from _flightlogs import LOG_NAMES, log_path, pymavlink_reference
from mission_sim.mavlink.geodesy import GeoPoint, enu_to_geodetic, geodetic_to_enu, parse_geo_point
from mission_sim.mavlink.logs import read_log
from mission_sim.mavlink.replay import NoPositionError, default_pad, logged_energy_j, track_from_log

_cache: dict = {}


def _both(name):
    if name not in _cache:
        p = log_path(name)
        _cache[name] = (read_log(p), pymavlink_reference(p))
    return _cache[name]


def test_a_log_beside_the_repository_is_refused_here():
    """tests/conftest.py runs the flight-log tests under ``_flightlogs.log_guard``: a log in a
    ``shared`` folder beside the repository cannot be opened (it need not exist)."""
    shared = Path(__file__).resolve().parents[2] / "shared" / "flightlogs" / LOG_NAMES[0]
    with pytest.raises(PermissionError, match="outside the repository"):
        open(shared, "rb")


@pytest.mark.parametrize("name", LOG_NAMES)
def test_log_facts_agree_with_pymavlink(name):
    log, ref = _both(name)
    assert log.errors == []
    assert log.duration_s == pytest.approx(ref["duration_s"], abs=1e-6)
    assert log.bad_frames == ref["bad"]
    # armed periods: same count, same edges (to the millisecond)
    assert len(log.armed_periods) == len(ref["armed_periods"]) >= 1
    np.testing.assert_allclose(np.array(log.armed_periods), np.array(ref["armed_periods"]), atol=1e-3)
    # positions with a 3D fix: same extents; duplicate timestamps may be dropped, nothing else
    pos = log.position
    n_rejected = sum(log.gps_rejected.values())
    assert n_rejected == (12 if name.startswith("ardusub") else 0) + ref["origin"]  # the ROV's 12 fixes with HDOP 99.99
    assert log.gps_rejected.get("origin", 0) == ref["origin"]        # the dronekit tlog's estimator without a GPS origin
    assert ref["n_pos"] - 5 <= len(pos) <= ref["n_pos"]       # the reference skips HDOP > 10 fixes too
    assert (pos["lat_deg"].min(), pos["lat_deg"].max()) == pytest.approx(ref["lat"], abs=1e-9)
    assert (pos["lon_deg"].min(), pos["lon_deg"].max()) == pytest.approx(ref["lon"], abs=1e-9)
    assert (pos["alt_m"].min(), pos["alt_m"].max()) == pytest.approx(ref["alt"], abs=1e-6)
    assert np.all(np.diff(pos["t_s"]) > 0), "timeline must be strictly increasing"
    # battery: the same source values in SI units
    if log.battery_source == "BATTERY_STATUS":
        vref, nref = ref["volt_bs"], ref["n_volt_bs"]
    else:
        vref, nref = ref["volt"], ref["n_volt"]
    if vref is None:
        assert len(log.battery) == 0 and log.battery_source is None
    else:
        assert (log.battery["voltage_v"].min(), log.battery["voltage_v"].max()) == pytest.approx(vref, abs=1e-9)
        assert nref - 5 <= len(log.battery) <= nref
        np.testing.assert_allclose(log.battery["power_w"], log.battery["voltage_v"] * log.battery["current_a"])


def test_dronekit_tlog_reboot_and_protocol():
    """Real quad, MAVLink 1, rebooted at ~252 s: the timeline continues, 7 flights, 3S pack."""
    log, _ = _both("dronekit-python_flight.tlog")
    assert log.reboots == 1 and set(log.mavlink_frames) == {1}
    assert log.vehicle == {"sysid": 1, "compid": 1, "mav_type": 2}
    t = log.position["t_s"].to_numpy()
    assert t[0] < 252 < t[-1] and np.max(np.diff(t)) < 30  # no hole where time_boot_ms restarted
    assert 9.0 < log.battery["voltage_v"].median() < 12.6   # 3S: cV->V conversion done right
    assert 50 < log.battery["current_a"].max() < 60          # cA -> A


def test_dataflash_old_curr_units_and_open_armed_period():
    log, _ = _both("dronekit-la-testdata_log171.bin")
    assert log.kind == "dataflash" and log.battery_source == "CURR"
    assert 14.5 < log.battery["voltage_v"].min() and log.battery["voltage_v"].max() < 16.8  # 4S, cV -> V
    (a, b), = log.armed_periods
    assert b == pytest.approx(log.duration_s)  # the log ends armed: period closed at the end of the log


def test_mavlink2_rov_and_unknown_battery_vtol():
    rov, _ = _both("ardusub_log_tools_small_rov.tlog")
    assert set(rov.mavlink_frames) == {2} and rov.battery_source == "BATTERY_STATUS"
    vtol, _ = _both("uavlogviewer_vtol_sitl.tlog")
    assert vtol.battery_source is None and len(vtol.battery) == 0  # voltage 0 / current -1 = unknown


def test_track_geometry_and_energy():
    log, _ = _both("dronekit-python_flight.tlog")
    tr = track_from_log(log, ground_gap_m=0.1)
    assert tr.t_s[0] == 0 and np.all(np.diff(tr.t_s) > 0)
    pad = default_pad(log)
    # the pad is where the vehicle stood at the first arming: the track starts there in plan
    i = np.searchsorted(tr.t_s + tr.t_offset_s, log.armed_periods[0][0])
    assert np.hypot(*tr.pos_m[i, :2]) < 1e-6
    assert np.all(tr.pos_m[:, 2] >= 0.1 - 1e-12)
    # round trip through the local tangent plane
    lat, lon, alt = enu_to_geodetic(tr.pos_m[:, 0], tr.pos_m[:, 1], tr.height_m, pad)
    np.testing.assert_allclose(lat, log.position["lat_deg"], atol=1e-9)
    np.testing.assert_allclose(lon, log.position["lon_deg"], atol=1e-9)
    # metres per degree from the standard WGS84 series (independent of our radii of curvature)
    phi = np.radians(pad.lat_deg)
    m_per_deg_lat = 111132.92 - 559.82 * np.cos(2 * phi) + 1.175 * np.cos(4 * phi)
    m_per_deg_lon = 111412.84 * np.cos(phi) - 93.5 * np.cos(3 * phi) + 0.118 * np.cos(5 * phi)
    e, n, _ = geodetic_to_enu(pad.lat_deg + 1e-3, pad.lon_deg + 1e-3, pad.alt_m, pad)
    assert n == pytest.approx(m_per_deg_lat * 1e-3, rel=2e-4) and e == pytest.approx(m_per_deg_lon * 1e-3, rel=2e-4)
    # logged energy: integral of V*I; a constant-power check of the integrator
    b = log.battery.assign(power_w=100.0)
    assert logged_energy_j(b, 500, 600) == pytest.approx(100.0 * np.ptp(b["t_s"][b["t_s"].between(500, 600)].to_numpy()), rel=1e-9)
    e_armed = logged_energy_j(log.battery, periods=log.armed_periods)
    assert 0 < e_armed < logged_energy_j(log.battery)


def test_window_and_no_position():
    log, _ = _both("uavlogviewer_vtol_sitl.tlog")
    tr = track_from_log(log, window=(50, 60))
    assert tr.t_offset_s >= 50 and tr.t_s[-1] <= 10
    with pytest.raises(NoPositionError, match="window 102..105 s: 0 usable"):   # a 3.4 s gap of fixes at 101.7 s
        track_from_log(log, window=(102, 105))
    with pytest.raises(ValueError, match="the log ends at 207.886 s"):   # (was NoPositionError: past the log's end)
        track_from_log(log, window=(300, 400))


def test_track_from_log_refuses_a_window_past_the_log_as_replay_does():
    """2026-11-27: track_from_log took a window ending past the log's end (cut to the log without a word) while replay,
    calibrate and refly refused it (check_window): it is now the one place the window is checked."""
    from mission_sim.mavlink.replay import WINDOW_END_SLACK_S, log_end_s
    log, _ = _both("uavlogviewer_vtol_sitl.tlog")
    end = log_end_s(log)
    assert track_from_log(log, window=(50, end + WINDOW_END_SLACK_S)).t_offset_s >= 50   # a rounded-up end: taken
    with pytest.raises(ValueError, match=rf"--window 50,{end + 5:g} is invalid: the log ends at {end:.3f} s; valid: "
                                         rf"0 <= T0 < T1 <= {end + WINDOW_END_SLACK_S:.3f} s"):
        track_from_log(log, window=(50, end + 5))


@pytest.mark.parametrize("window, shown", [((50, float("nan")), "50,nan"), ((100, 50), "100,50"), ((-50, 60), "-50,60"),
                                           ((60, 60), "60,60"), ((float("-inf"), 60), "-inf,60")])
def test_track_from_log_refuses_a_window_outside_what_its_message_says_is_valid(window, shown):
    """2026-11-27 review: check_window printed "valid: 0 <= T0 < T1 <= ..." but checked only T1's bound: from Python
    (the CLI's parse_window refuses these first) a NaN end, T0 after T1 and a negative T0 passed (an empty or cut
    track, or "no usable position"). One line naming the window and the log's range."""
    from mission_sim.mavlink.replay import WINDOW_END_SLACK_S, log_end_s
    log, _ = _both("uavlogviewer_vtol_sitl.tlog")
    end = log_end_s(log)
    with pytest.raises(ValueError) as e:
        track_from_log(log, window=window)
    assert str(e.value) == (f"--window {shown} is invalid; valid: 0 <= T0 < T1 <= {end + WINDOW_END_SLACK_S:.3f} s of log "
                            f"time (its time range 0..{end:.3f} s; {WINDOW_END_SLACK_S:g} s allowed for a rounded end)")
    with pytest.raises(ValueError, match=r"^window=\('a', 60\) is invalid; valid: 0 <= T0 < T1 <= "):   # not numbers
        track_from_log(log, window=("a", 60))


@pytest.mark.parametrize("text", ["1,2,3,4", "abc", "91,0", "10,200", "10,20,nan", ""])
def test_bad_pad_names_the_format(text):
    with pytest.raises(ValueError, match="LAT,LON|range"):
        parse_geo_point(text)


def test_pad_parses():
    assert parse_geo_point("-35.36, 149.16") == GeoPoint(-35.36, 149.16, None)
    assert parse_geo_point("-35.36,149.16,584").alt_m == 584


def test_compare_power_arithmetic():
    """Known inputs: logged 200 W, model 100 W -> error -100 W, energy -50 %, best-fit scale 2."""
    from dataclasses import replace

    from mission_sim.mavlink.replay import compare_power
    log, _ = _both("dronekit-python_flight.tlog")
    tr = track_from_log(log, ground_gap_m=0.1)
    log2 = replace(log, battery=log.battery.assign(power_w=200.0))
    table, c = compare_power(log2, tr, tr.t_s, np.full(len(tr.t_s), 100.0))
    assert c["n_samples_airborne"] > 500 and 300 < c["airborne_time_s"] < log.armed_time_s
    assert c["mean_error_w"] == pytest.approx(-100.0) and c["energy_error_rel"] == pytest.approx(-0.5)
    assert c["best_fit_scale"] == pytest.approx(2.0) and c["rms_error_after_scale_w"] == pytest.approx(0.0, abs=1e-9)
    # airborne = armed and more than 1 m above the pad
    assert np.all(table.loc[table["airborne"], "height_m"] > 1.0) and table.loc[table["airborne"], "armed"].all()


def _modern_dataflash() -> bytes:
    """A small synthetic DataFlash log in the newer ArduPilot layout: two GPS receivers (column I),
    float BAT in V and A, ARM messages. Built from the DataFlash format (FMT records first)."""
    import struct
    chars = {"Q": "Q", "B": "B", "L": "i", "e": "i", "f": "f"}

    def fmt(typ, name, form, cols):
        length = 3 + struct.calcsize("<" + "".join(chars[c] for c in form))
        return b"\xa3\x95\x80" + struct.pack("<BB4s16s64s", typ, length, name.encode(), form.encode(), cols.encode())

    def rec(typ, form, *vals):
        return b"\xa3\x95" + bytes([typ]) + struct.pack("<" + "".join(chars[c] for c in form), *vals)

    data = b"\xa3\x95\x80" + struct.pack("<BB4s16s64s", 128, 89, b"FMT", b"BBnNZ", b"Type,Length,Name,Format,Columns")
    data += fmt(130, "GPS", "QBBLLe", "TimeUS,I,Status,Lat,Lng,Alt") + fmt(131, "BAT", "QBff", "TimeUS,Inst,Volt,Curr")
    data += fmt(132, "ARM", "QB", "TimeUS,ArmState")
    for k in range(100):
        t = 1_000_000 + k * 200_000
        data += rec(130, "QBBLLe", t, 0, 3, int(-35.36e7) + k * 10, int(149.16e7), 58400 + k * 10)  # Alt in cm
        data += rec(130, "QBBLLe", t + 1000, 1, 3 if k > 50 else 1, int(-35.30e7), int(149.10e7), 50000)
        data += rec(131, "QBff", t + 2000, 0, 24.5 - 0.01 * k, 12.5)
        if k in (10, 80):
            data += rec(132, "QB", t + 3000, 1 if k == 10 else 0)
    return data


def test_modern_dataflash_layout(tmp_path):
    p = tmp_path / "modern.bin"
    p.write_bytes(_modern_dataflash())
    log = read_log(p)
    assert log.kind == "dataflash" and log.bad_frames == 0 and log.errors == []
    assert len(log.position) == 100                                   # receiver 0 only
    np.testing.assert_allclose(log.position["lat_deg"], -35.36 + np.arange(100) * 1e-6, atol=1e-9)
    np.testing.assert_allclose(log.position["alt_m"], 584.0 + np.arange(100) * 0.1, atol=1e-9)
    np.testing.assert_allclose(np.diff(log.position["t_s"]), 0.2, atol=1e-9)
    assert log.battery_source == "BAT"                                # floats in V and A: no scaling
    np.testing.assert_allclose(log.battery["voltage_v"], 24.5 - 0.01 * np.arange(100), atol=1e-5)
    np.testing.assert_allclose(log.battery["power_w"], log.battery["voltage_v"] * 12.5, rtol=1e-6)
    (a, b), = log.armed_periods
    assert (a, b) == pytest.approx((3.003, 17.003), abs=1e-6)
