"""A demanding newcomer's second pass (2026-11-28 small hours, branch newcomer2): the cases found on the surfaces the
first pass did not cover (telemetry --follow, the stream's .tlog, TOML files saved with a BOM, ...), each fixed.
docs/robustness.md, "A demanding newcomer's second pass (2026-11-28)"."""

from __future__ import annotations

import math
import socket

import numpy as np
import pandas as pd
import pytest

from mission_sim.cli import main
from mission_sim.mavlink.logs import read_log


def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _series(duration_s=3.0, dt=0.05):
    """A short mission-shaped time series (circle at 3 m, battery discharging)."""
    t = np.arange(0.0, duration_s + 1e-9, dt)
    n = len(t)
    return pd.DataFrame({"t_s": t, "x_m": 3.0 * np.cos(t), "y_m": 3.0 * np.sin(t), "z_m": 0.2 + 0.4 * t,
                         "lm_h": np.full(n, 6.25e-6), "i2_amp_a": np.zeros(n), "d_short": np.zeros(n),
                         "battery_v": np.full(n, 29.6), "battery_current_a": np.full(n, -6.0),
                         "soc": 0.9 - 1e-4 * t, "i1_amp_a": np.zeros(n), "rect_current_a": np.zeros(n),
                         "charge_cmd_a": np.zeros(n), "tx_on": np.zeros(n, bool), "propulsion_w": np.full(n, 100.0),
                         "phase": np.full(n, "transit")})


def _hidden(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


# ------------------------------------------------------------------ the stream's .tlog: nothing lost
def test_follow_with_no_vehicle_is_an_error_and_leaves_an_existing_tlog_as_it_was(tmp_path, capsys):
    """`telemetry --follow udpin:...` with nothing sending: was exit 0, "followed 0 live positions", and the
    existing --tlog (a recording of 28,924 bytes) replaced by an empty file. Now one line naming the address,
    exit 2, the old recording byte for byte, no temporary file."""
    tlog = tmp_path / "flight.tlog"
    tlog.write_bytes(b"an earlier recording")
    port = _free_port()
    rc = main(["telemetry", "--follow", f"udpin:127.0.0.1:{port}", "--follow-time", "0.5", "--connect", "none",
               "--tlog", str(tlog)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    assert f"--follow udpin:127.0.0.1:{port}: no position arrived" in err[0] and f"{str(tlog)!r} was not written" in err[0]
    assert tlog.read_bytes() == b"an earlier recording"
    assert _hidden(tmp_path) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["flight.tlog"]


def test_an_interrupted_stream_keeps_its_frames_beside_and_the_old_tlog_as_it_was(tmp_path, monkeypatch):
    """Ctrl-C during `telemetry --tlog X` replaced an existing X by the frames streamed until then. Now X stays as
    it was, the frames so far are a readable X.partial.tlog, and the interrupt carries a note naming it."""
    from mission_sim.mavlink import telemetry

    tlog = tmp_path / "x.tlog"
    tlog.write_bytes(b"an earlier recording")
    real, calls = telemetry.encode_tick, []

    def cut(mav, row):
        calls.append(1)
        if len(calls) == 12:
            raise KeyboardInterrupt
        return real(mav, row)
    monkeypatch.setattr(telemetry, "encode_tick", cut)
    with pytest.raises(KeyboardInterrupt) as info:
        telemetry.stream(_series(), tlog=tlog, rate_hz=5.0, speed=math.inf, start_epoch_s=1.7e9)
    assert tlog.read_bytes() == b"an earlier recording"
    partial = tmp_path / "x.partial.tlog"
    assert any(str(partial) in note for note in info.value.__notes__)
    log = read_log(partial)
    assert log.bad_frames == 0 and 8 <= len(log.position) <= 11   # the 11 ticks sent before the cut
    assert _hidden(tmp_path) == []


def test_a_stream_that_ends_replaces_the_tlog_and_leaves_no_partial(tmp_path):
    from mission_sim.mavlink import telemetry

    tlog = tmp_path / "x.tlog"
    tlog.write_bytes(b"an earlier recording")
    st = telemetry.stream(_series(), tlog=tlog, rate_hz=5.0, speed=math.inf, start_epoch_s=1.7e9)
    log = read_log(tlog)
    assert st.ticks == 16 and len(log.position) == st.ticks and log.bad_frames == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.tlog"]


def test_tlog_writer_with_no_frame_writes_no_file(tmp_path):
    from mission_sim.mavlink.telemetry import TlogWriter

    old = tmp_path / "old.tlog"
    old.write_bytes(b"kept")
    for name in ("old.tlog", "new.tlog"):
        w = TlogWriter(tmp_path / name)
        w.close()
        assert w.kept is None
    assert old.read_bytes() == b"kept" and not (tmp_path / "new.tlog").exists() and _hidden(tmp_path) == []


def test_a_stream_whose_tlog_cannot_be_renamed_keeps_its_frames_and_names_them(tmp_path, monkeypatch):
    """The frames went to a hidden temporary file renamed at the end; a rename that failed (Windows: X.tlog open in a
    ground station; X a folder) deleted it: every frame of a live flight lost. Now they are streamed into a visible
    X.partial.tlog (a kill leaves them there too), which stays when the rename fails, named in the error; X as it
    was. An earlier X.partial.tlog is not overwritten: the next one is X.partial.2.tlog."""
    import os

    from mission_sim.mavlink import telemetry

    tlog = tmp_path / "x.tlog"
    tlog.write_bytes(b"an earlier recording")
    (tmp_path / "x.partial.tlog").write_bytes(b"an earlier partial recording")

    def refused(src, dst):
        raise PermissionError(13, "The process cannot access the file because it is being used by another process")
    monkeypatch.setattr(os, "replace", refused)
    with pytest.raises(OSError) as info:
        telemetry.stream(_series(), tlog=tlog, rate_hz=5.0, speed=math.inf, start_epoch_s=1.7e9)
    kept = tmp_path / "x.partial.2.tlog"
    msg = str(info.value)
    assert f"frames streamed are in {str(kept)!r}" in msg and "being used by another process" in msg, msg
    monkeypatch.undo()
    log = read_log(kept)
    assert log.bad_frames == 0 and len(log.position) == 16          # every tick streamed
    assert tlog.read_bytes() == b"an earlier recording"
    assert (tmp_path / "x.partial.tlog").read_bytes() == b"an earlier partial recording"
    assert _hidden(tmp_path) == []


def test_a_streaming_tlog_is_visible_while_it_is_written(tmp_path):
    """After a SIGKILL the frames sat in a hidden .x.tmpPID.tlog; they are written to x.partial.tlog from the
    first frame on."""
    from mission_sim.mavlink.telemetry import TlogWriter

    w = TlogWriter(tmp_path / "x.tlog")
    w.write(b"\xfd" + bytes(20), 1.7e9)
    w._fh.flush()
    assert _hidden(tmp_path) == [] and (tmp_path / "x.partial.tlog").stat().st_size == 29
    w.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.tlog"]


@pytest.mark.parametrize("error", [OSError, ValueError])
def test_a_stream_cut_by_an_error_names_its_partial_tlog(tmp_path, monkeypatch, capsys, error):
    """An OSError / ValueError during `telemetry --tlog X` kept the frames so far in X.partial.tlog, but only the
    interrupt line printed the note naming it: the error line said nothing of it."""
    from _cli_helpers import one_error_line
    from mission_sim.mavlink import telemetry

    tlog = tmp_path / "x.tlog"
    real, calls = telemetry.encode_tick, []

    def cut(mav, row):
        calls.append(1)
        if len(calls) == 12:
            raise error("the link went away")
        return real(mav, row)
    monkeypatch.setattr(telemetry, "encode_tick", cut)
    err = one_error_line(capsys, ["telemetry", "--connect", "none", "--tlog", str(tlog), "--speed", "inf",
                                  "--duration", "5", "--no-progress"])
    partial = tmp_path / "x.partial.tlog"
    assert err.startswith("dronewpt telemetry: error: the link went away; the ") and \
        f"frames streamed before it are in {str(partial)!r}" in err, err
    assert len(read_log(partial).position) >= 8 and not tlog.exists()


@pytest.mark.parametrize("frames_before", [0, 3])
def test_a_full_disk_names_the_partial_tlog_only_when_it_holds_frames(tmp_path, frames_before):
    """A full disk while streaming: the error names X.partial.tlog where the frames so far are kept; with none
    written the partial file is removed and the error says nothing partial was left."""
    import errno

    from mission_sim.files import OutputError
    from mission_sim.mavlink.telemetry import TlogWriter

    class FullDisk:
        closed = False

        def write(self, data):
            raise OSError(errno.ENOSPC, "No space left on device")

        def close(self):
            self.closed = True
    w = TlogWriter(tmp_path / "t.tlog")
    for k in range(frames_before):
        w.write(b"\xfd" + bytes(20), 1.7e9 + k)
    w._fh.flush()
    real, w._fh = w._fh, FullDisk()
    with pytest.raises(OutputError, match="no space left on the device") as info:
        w.write(b"\xfd" + bytes(20), 1.8e9)
    real.close()
    w.abort(info.value)
    partial = tmp_path / "t.partial.tlog"
    if frames_before:
        assert f"what was written before it is in {str(partial)!r}" in str(info.value)
        assert partial.stat().st_size == 29 * frames_before
    else:
        assert "nothing partial was left" in str(info.value) and not partial.exists()
    assert not (tmp_path / "t.tlog").exists()


# ------------------------------------------------------------------ TOML files saved with a byte-order mark
BOM = b"\xef\xbb\xbf"


@pytest.mark.parametrize("crlf", [False, True])
def test_toml_files_with_a_byte_order_mark_are_read(tmp_path, crlf):
    """A mission, study or --drone TOML saved as "UTF-8 with BOM" (Windows Notepad, PowerShell) was refused as
    "not valid TOML: Invalid statement (at line 1, column 1)"; it is read as the same file without the mark (with
    Windows line endings too): the values in it, not the defaults."""
    from mission_sim.config import load_config
    from mission_sim.mavlink.calibrate import read_drone_toml
    from mission_sim.studies.study import case_space, load_study

    def write(name, text):
        if crlf:
            text = text.replace("\n", "\r\n")
        (tmp_path / name).write_bytes(BOM + text.encode())
        (tmp_path / f"plain_{name}").write_bytes(text.encode())
        return tmp_path / name, tmp_path / f"plain_{name}"

    mission, plain = write("m.toml", "[battery]\ncapacity_ah = 5.5\n[drone]\nmass_kg = 1.7\n")
    cfg = load_config(mission)
    assert cfg.battery.capacity_ah == 5.5 and cfg.drone.mass_kg == 1.7 and cfg == load_config(plain)
    drone, plain = write("d.toml", "[drone]\nmass_kg = 1.7\nflat_plate_area_m2 = 0.05\n")
    assert read_drone_toml(drone) == {"drone.mass_kg": 1.7, "drone.flat_plate_area_m2": 0.05} == read_drone_toml(plain)
    study, plain = write("s.toml", '[study]\nname = "s"\n[grid]\n"wind.speed_m_s" = [1.0, 2.0, 3.0]\n')
    a, b = load_study(study), load_study(plain)
    assert [c.params for c in case_space(a)] == [c.params for c in case_space(b)]
    assert [c.params["wind.speed_m_s"] for c in case_space(a)] == [1.0, 2.0, 3.0]


def test_a_toml_file_with_a_bad_byte_after_the_mark_is_still_refused(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_bytes(BOM + b"[battery]\ncapacity_ah = \xff\n")
    assert main(["mission", str(bad), "--dry-run"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is not a UTF-8 text (TOML) file: byte 0xff" in err[0], err


# ------------------------------------------------------------------ a .tlog whose receive stamps do not advance
def _restamp(src, dst, stamp):
    """``src`` with every frame's 8-byte receive stamp replaced by ``stamp(k, t)`` (k: record number)."""
    import struct

    from mission_sim.mavlink.logs import mavutil
    reader = mavutil().mavlink_connection(str(src))
    with open(dst, "wb") as out:
        k = 0
        while (msg := reader.recv_msg()) is not None:
            out.write(struct.pack(">Q", int(round(stamp(k, msg._timestamp) * 1e6))) + msg.get_msgbuf())
            k += 1
    reader.close()


@pytest.mark.parametrize("stamp", ["first", "zero", "ms", "s"])
def test_a_tlog_with_one_receive_stamp_on_every_frame_is_put_on_the_vehicle_clock(tmp_path, stamp):
    """A .tlog whose 8-byte receive stamps are all the same (or 0: a writer without a clock) read as "0.0 s logged",
    every battery and heartbeat record at one instant, never armed, no airborne power to compare (and scipy's
    "invalid value encountered in sqrt" on stderr). The positions carry time_boot_ms: the records without it are
    now placed by record order between them, and the log reads as the original within a frame interval."""
    from mission_sim.mavlink import telemetry

    good = tmp_path / "good.tlog"
    telemetry.stream(_series(duration_s=12.0), tlog=good, rate_hz=5.0, speed=math.inf, start_epoch_s=1.7e9)
    bad = tmp_path / "bad.tlog"
    _restamp(good, bad, {"first": lambda k, t: 1.7e9, "zero": lambda k, t: 0.0, "ms": lambda k, t: t * 1e-3,
                         "s": lambda k, t: t * 1e-6}[stamp])   # (ms, s: the value written in the us field)
    a, b = read_log(good), read_log(bad)
    assert "do not advance" in b.clock.source and "do not advance" not in a.clock.source
    assert len(b.position) == len(a.position) == 61
    np.testing.assert_allclose(b.position["t_s"], a.position["t_s"], atol=1e-6)   # by time_boot_ms, as before
    assert len(b.battery) == len(a.battery) >= 12                                 # was 1 (all at one instant)
    np.testing.assert_allclose(b.battery["t_s"], a.battery["t_s"], atol=0.21)     # one tick of 5 Hz
    # armed from the start; the landing heartbeats after the last position (up to 1 s) have no boot-stamped record
    # after them and stay at the last one's time
    assert a.armed_time_s - 1.05 <= b.armed_time_s <= a.armed_time_s and b.armed_time_s > 11.0
    assert b.duration_s == pytest.approx(a.duration_s, abs=1.1)                   # the landing rows after the last tick


def test_one_corrupt_time_boot_ms_does_not_freeze_the_receive_clock(tmp_path):
    """The frozen-receive-stamps test compared raw spans: one GLOBAL_POSITION_INT of the dronekit log repacked with
    time_boot_ms = 4e9 made the boot span ~4e6 s and the log 'receive timestamps do not advance' (records placed by
    record order). It is read as the original now (5-95 % percentile spans)."""
    import struct

    from _flightlogs import log_path
    from mission_sim.mavlink.logs import mavutil
    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    src, dst = log_path("dronekit-python_flight.tlog"), tmp_path / "one_bad_boot.tlog"
    reader, n = mavutil().mavlink_connection(str(src)), 0
    with open(dst, "wb") as out:
        while (msg := reader.recv_msg()) is not None:
            buf = msg.get_msgbuf()
            if msg.get_type() == "GLOBAL_POSITION_INT":
                n += 1
                if n == 500:
                    mav = mavlink2.MAVLink(None, srcSystem=msg.get_srcSystem(), srcComponent=msg.get_srcComponent())
                    mav.seq, msg.time_boot_ms = msg.get_seq(), 4_000_000_000
                    buf = bytes(msg.pack(mav))
            out.write(struct.pack(">Q", int(round(msg._timestamp * 1e6))) + buf)
    reader.close()
    a, b = read_log(src), read_log(dst)
    assert n > 500 and b.bad_frames == a.bad_frames
    assert not any(s.by_record for s in b.clock.segments), b.clock.source
    assert b.duration_s == pytest.approx(a.duration_s, abs=0.5)
    assert b.clock.source == a.clock.source


# ------------------------------------------------------------------ a pads file with a row pasted twice
@pytest.mark.parametrize("suffix", ["csv", "geojson"])
def test_a_pad_listed_twice_is_refused_by_a_re_flight_only(tmp_path, capsys, suffix):
    """`replay LOG --pads FILE` with a row pasted twice flew a detour to each copy and charged twice (120 s instead
    of 60 s, +18.1 s of flight time gained instead of +9.0 s, no word): refused there, one line naming both pads.
    `mission --pads` is not: its built-in pattern visits the pads in file order, so A, B, A is a route (f911edc:
    211.6 s simulated; the check in read_pads refused it). Pads 0.1 m apart or more are two pads."""
    from _cli_helpers import one_error_line
    from _flightlogs import log_path
    from mission_sim.plans.pads import check_distinct, read_pads

    def write(points):
        f = tmp_path / f"p.{suffix}"
        if suffix == "csv":
            f.write_text("lat,lon\n" + "".join(f"{lat},{lon}\n" for lat, lon in points))
        else:
            import json
            f.write_text(json.dumps({"type": "FeatureCollection", "features": [
                {"type": "Feature", "properties": {}, "geometry": {"type": "Point", "coordinates": [lon, lat]}}
                for lat, lon in points]}))
        return f
    aba = write([(-35.36208, 149.1658531), (-35.3622242, 149.1656661), (-35.3620805, 149.1658531)])
    assert len(read_pads(aba)) == 3                                 # read_pads is neutral
    assert main(["mission", "--pads", str(aba), "--dry-run"]) == 0   # a route A, B, A
    capsys.readouterr()
    err = one_error_line(capsys, ["replay", str(log_path("dronekit-python_flight.tlog")), "--pads", str(aba),
                                  "--window", "440,620", "--out", str(tmp_path / "r")])
    assert err.startswith(f"dronewpt replay: error: {aba.name}: pads 1 and 3 are 0.0") and \
        "m apart: one pad listed twice" in err, err
    assert not (tmp_path / "r").exists()
    check_distinct(read_pads(write([(-35.36208, 149.1658531), (-35.362082, 149.1658531)])), "p")  # 0.22 m: two pads


def test_a_tlog_stamped_in_nanoseconds_is_said_as_such(tmp_path, capsys):
    """Every frame good, every 8-byte stamp in nanoseconds (beyond 2100): was "no readable record in its 7 kB,
    N corrupt frame(s): cut short before its first record, or not a flight log"; now the stamps are named."""
    from mission_sim.mavlink import telemetry

    good = tmp_path / "good.tlog"
    telemetry.stream(_series(duration_s=4.0), tlog=good, rate_hz=5.0, speed=math.inf, start_epoch_s=1.7e9)
    bad = tmp_path / "ns.tlog"
    _restamp(good, bad, lambda k, t: t * 1e3)   # microseconds * 1000
    assert main(["replay", str(bad), "--no-plot", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "records has an implausible timestamp (the first 1.7e+12 s since 1970" in err[0], err
    assert "corrupt frame" not in err[0] and not (tmp_path / "o").exists()


# ------------------------------------------------------------------ calibrate: a current sensor the wrong way round
def test_calibrate_refuses_a_log_whose_airborne_battery_power_is_negative(tmp_path, capsys):
    """The log171 .bin with its current's sign inverted (a sensor wired or configured backwards) was fitted to mass
    0.1 kg, f 1e-4 m^2, avionics 0 W (three bounds), held-out error nan, and the [drone] TOML written with a warning on
    stdout. Now refused, one line naming the median power; the same log the right way round still calibrates."""
    from mission_sim.mavlink.calibrate import NoBatteryError, calibrate_log
    from mission_sim.world.power import DroneParams
    from _flightlogs import DATA_DIR

    path = DATA_DIR / "dronekit-la-testdata_log171.bin"
    log = read_log(path)
    good = calibrate_log(log, DroneParams())
    assert abs(good.report["calibrated_heldout_energy_error_rel"]) < 0.02
    log.battery = log.battery.assign(current_a=-log.battery["current_a"], power_w=-log.battery["power_w"])
    with pytest.raises(NoBatteryError, match=r"battery power while airborne is not positive \(median -\d+ W over \d+ "
                                             r"samples\): the logged current's sign is inverted"):
        calibrate_log(log, DroneParams())
    # a current of 0 throughout (no sensor) is no inverted sign: said as such
    log.battery = log.battery.assign(current_a=0.0, power_w=0.0)
    with pytest.raises(NoBatteryError, match=r"battery power while airborne is 0 W \(median over \d+ samples\): the "
                                             r"logged current is 0 \(no current sensor\?\)") as info:
        calibrate_log(log, DroneParams())
    assert "inverted" not in str(info.value)


# ------------------------------------------------------------------ --follow: one implausible position from the vehicle
class _FakeVehicle:
    """A --follow input: GLOBAL_POSITION_INT-like messages at 10 Hz of wall time (lat / lon in 1e-7 deg, alt mm)."""

    def __init__(self, positions):
        import time
        self.queue, self.next, self.time = list(positions), None, time

    def recv_match(self, type=None, blocking=True, timeout=None):
        if not self.queue:
            self.time.sleep(timeout or 0.0)
            return None
        self.time.sleep(0.1)
        k, lat, lon, alt = self.queue.pop(0)
        return type and __import__("types").SimpleNamespace(time_boot_ms=100 * k, lat=lat, lon=lon, alt=alt)

    def close(self):
        pass


def _track(n, bad=(), lat0=-35.363261, lon0=149.165230, alt_bad=()):
    out = []
    for k in range(n):
        lat, lon = lat0 + 2e-6 * k, lon0
        if k in bad:
            lat, lon = lon, lat          # a sender with latitude and longitude swapped in one frame
        out.append((k, int(round(lat * 1e7)), int(round(lon * 1e7)), 589_000 * (10 if k in alt_bad else 1)))
    return out


def test_follow_skips_an_impossible_jump(monkeypatch, tmp_path, capsys):
    """At Zurich (47.4 N, 8.5 E) latitude and longitude swapped in one frame are both in range: the frame was taken,
    the drone flew ~5,200 km in 0.1 s and the session ended with 'battery cannot supply ... 5.58e19 W'. An altitude in
    cm (5,890 m for 589 m) passed too. Both are now skipped as jumps no vehicle makes (gpsclean's bounds, the time
    between the frames) and counted; the session goes on."""
    from mission_sim.mavlink import follow

    tlog = tmp_path / "z.tlog"
    monkeypatch.setattr(follow, "open_follow",
                        lambda connect: _FakeVehicle(_track(20, bad={6}, lat0=47.4, lon0=8.5, alt_bad={12})))
    rc = main(["telemetry", "--follow", "udpin:127.0.0.1:14999", "--follow-time", "120", "--follow-idle", "0.3",
               "--connect", "none", "--tlog", str(tlog)])
    out, err = capsys.readouterr()
    assert rc == 0 and "followed 18 live positions" in out, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "2 implausible position(s) skipped (the first: a jump of" in lines[0], lines
    pos = read_log(tlog).position
    assert len(pos) >= 10 and pos["lat_deg"].between(47.39, 47.41).all() and pos["lon_deg"].between(8.49, 8.51).all()


def test_follow_skips_an_implausible_position_and_says_so(monkeypatch, tmp_path, capsys):
    """One frame with latitude 149 deg (swapped, corrupt, INT32_MAX) ended the whole --follow session: `error:
    latitude 149.16522999999998 is invalid` (not even saying it came from the vehicle). Now it is skipped and counted,
    one warning names it; the rest is followed. All of them implausible: exit 2 naming the first."""
    from mission_sim.mavlink import follow

    tlog = tmp_path / "f.tlog"
    monkeypatch.setattr(follow, "open_follow", lambda connect: _FakeVehicle(_track(20, bad={3})))
    rc = main(["telemetry", "--follow", "udpin:127.0.0.1:14999", "--follow-time", "120", "--follow-idle", "0.3",
               "--connect", "none", "--tlog", str(tlog)])
    out, err = capsys.readouterr()
    assert rc == 0 and "followed 19 live positions" in out, (out, err)
    assert err.strip().splitlines() == ["dronewpt telemetry: warning: --follow udpin:127.0.0.1:14999: 1 implausible "
                                        "position(s) skipped (the first: latitude 149.16523 is invalid; valid range: "
                                        "(-90, 90) degrees)"]
    assert len(read_log(tlog).position) >= 10
    monkeypatch.setattr(follow, "open_follow", lambda connect: _FakeVehicle(_track(3, bad={0, 1, 2})))
    rc = main(["telemetry", "--follow", "udpin:127.0.0.1:14999", "--follow-time", "2", "--connect", "none",
               "--tlog", str(tmp_path / "g.tlog")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "no usable position in" in err[0] and "3 implausible position(s)" in err[0]
    assert not (tmp_path / "g.tlog").exists()
