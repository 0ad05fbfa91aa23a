"""Armed periods of real logs that start armed or have no armed-state record, sparse last records,
and parser failures reported as such (issue 12)."""

import contextlib
import struct

import numpy as np
import pytest

from _flightlogs import LOG_NAMES, dataflash_records, log_path, pymavlink_reference
from mission_sim.cli import main
from mission_sim.mavlink.armed import armed_periods, transitions
from mission_sim.mavlink.logs import mavutil, read_log

_ref: dict = {}


def _armed_ref(name):
    """The log's own armed time: pymavlink directly (HEARTBEAT bit 7 / EV 10-11), independent of us."""
    if name not in _ref:
        _ref[name] = sum(b - a for a, b in pymavlink_reference(log_path(name))["armed_periods"])
    return _ref[name]


def _df_without(name, drop):
    """A DataFlash log's bytes without the records for which ``drop(name, payload)`` is true."""
    data = log_path(name).read_bytes()
    return b"".join(data[o:o + n] for o, typ, n in dataflash_records(data) if not drop(typ, data[o + 3:o + n]))


def _tlog_without(path, drop):
    """A .tlog's records (timestamp + frame bytes as pymavlink returns them) without those ``drop(msg)``."""
    with contextlib.closing(mavutil().mavlink_connection(str(path))) as m:
        out = []
        while (msg := m.recv_match(blocking=False)) is not None:
            if not drop(msg):
                out.append(struct.pack(">Q", int(round(msg._timestamp * 1e6))) + bytes(msg.get_msgbuf()))
    return b"".join(out)


@pytest.mark.parametrize("name", LOG_NAMES)
def test_armed_time_matches_the_log(name):
    log = read_log(log_path(name))
    ref = _armed_ref(name)
    assert ref > 10 and log.armed_time_s == pytest.approx(ref, rel=0.02)
    assert log.armed_source in ("HEARTBEAT", "EV / ARM events")


def test_dataflash_with_the_arming_event_cut_out(tmp_path):
    """log171 without its EV 10 (ARMED): no armed-state record left; the RCOU motor outputs give
    the same armed time (within 2 %) and say so."""
    name = "dronekit-la-testdata_log171.bin"
    p = tmp_path / "no_arm.bin"
    p.write_bytes(_df_without(name, lambda typ, payload: typ == "EV" and payload[:1] == b"\x0a"))
    log = read_log(p)
    assert len(log.armed) and log.armed_source == "RCOU motor outputs (inferred)"
    assert log.armed_time_s == pytest.approx(_armed_ref(name), rel=0.02)
    (a, b), = log.armed_periods
    assert 61.0 < a < 64.0 and b == pytest.approx(log.duration_s)   # EV 10 was at 61.1 s


def test_tlog_with_the_vehicle_heartbeats_cut_out(tmp_path):
    """dronekit flight without the vehicle's HEARTBEATs: SERVO_OUTPUT_RAW gives the 7 flights."""
    name = "dronekit-python_flight.tlog"
    p = tmp_path / "no_hb.tlog"
    p.write_bytes(_tlog_without(log_path(name), lambda m: m.get_type() == "HEARTBEAT" and m.autopilot != 8))
    log = read_log(p)
    assert log.armed_source == "SERVO_OUTPUT_RAW motor outputs (inferred)"
    assert len(log.armed_periods) == 7
    assert log.armed_time_s == pytest.approx(_armed_ref(name), rel=0.02)


def test_dataflash_that_starts_armed(tmp_path):
    """An ArduCopter 4.x style log: logging starts armed (no arm record) and the only armed-state
    record is the disarm at the end. Made from log171: the records up to its last event (EV 10 at 61.1 s, ... 71.4 s) cut,
    an EV 11 (DISARMED) appended. The whole log is one armed period, as its records say."""
    name = "dronekit-la-testdata_log171.bin"
    data = log_path(name).read_bytes()
    recs = list(dataflash_records(data))
    cut_at = max(o + n for o, typ, n in recs if typ == "EV")   # after its last event (71.4 s, in flight)
    kept = b"".join(data[o:o + n] for o, typ, n in recs if typ == "FMT" or o >= cut_at)
    ev_type = next(data[o + 3] for o, typ, n in recs if typ == "FMT" and data[o + 5:o + 9].rstrip(b"\0") == b"EV")
    p = tmp_path / "starts_armed.bin"
    p.write_bytes(kept + b"\xa3\x95" + bytes([ev_type, 11]))
    log = read_log(p)
    assert log.starts_armed and log.armed_source == "EV / ARM events"
    assert log.armed_periods == [(0.0, pytest.approx(log.duration_s, abs=0.05))]
    assert log.armed_time_s == pytest.approx(log.duration_s, rel=0.02) and log.duration_s > 150


def test_armed_periods_rules():
    import pandas as pd
    ev = pd.DataFrame({"t_s": [50.0], "armed": [False]})
    assert armed_periods(ev, 80.0) == [] and armed_periods(ev, 80.0, starts_armed=True) == [(0.0, 50.0)]
    # a 1 s motor stop in flight is bridged, a 5 s one is not
    t = np.arange(0, 30, 0.5)
    on = (t >= 2) & ~((t > 10) & (t < 11)) & ~((t > 20) & (t < 25.5))
    tr = transitions(t, on)
    assert armed_periods(tr, 30.0) == [(2.0, 20.5), (25.5, 30.0)]  # off from the first off sample


def test_sparse_last_records_are_kept(tmp_path):
    """Parameter writes 30 and 31 s apart at the end of a log are legitimate records, not time spikes."""
    src = log_path("uavlogviewer_vtol_sitl.tlog")
    base = read_log(src)
    mav = mavutil().mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    t_end = base.t0_epoch_s + base.duration_s
    tail = b""
    for dt in (30.0, 60.0, 91.0):
        frame = mav.param_value_encode(b"BATT_CAPACITY", 3300.0, 4, 900, 1).pack(mav)
        tail += struct.pack(">Q", int(round((t_end + dt) * 1e6))) + frame
    p = tmp_path / "sparse.tlog"
    p.write_bytes(src.read_bytes() + tail)
    log = read_log(p)
    assert log.duration_s == pytest.approx(base.duration_s + 91.0, abs=1e-3) and log.bad_frames == 0
    # a real spike (a flipped timestamp byte: +2^40 us = 12.7 days) in the middle is still dropped
    data = bytearray(src.read_bytes())
    off = 0
    while off < len(data) // 2:                        # whole MAVLink 1 records: 8 + 6 + payload + 2 bytes
        assert data[off + 8] == 0xFE
        off += 16 + data[off + 9]
    data[off + 2] ^= 0x01
    p.write_bytes(bytes(data))
    spiked = read_log(p)
    assert spiked.duration_s == pytest.approx(base.duration_s, abs=1e-6) and spiked.bad_frames == 1


def test_parser_failure_is_reported_as_such(capsys, tmp_path):
    """A format char pymavlink does not know: the error names pymavlink's message, not "no position"."""
    name = "dronekit-la-testdata_log171.bin"
    data = log_path(name).read_bytes()
    i = data.index(b"BIHBcLLeeEefI")                   # the GPS format
    p = tmp_path / "badfmt.bin"
    p.write_bytes(data[:i] + b"BIHBcLLeeEefX" + data[i + 13:])
    assert main(["replay", str(p), "--no-plot", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "could not be parsed" in err[0] and "Unsupported format char" in err[0], err


def test_starts_armed_reports_and_events():
    """A first armed *report* starts the first period at that report (not earlier); a first *event*
    that is a disarm means armed from 0. Both flag the log as starting armed."""
    import pandas as pd

    from mission_sim.mavlink.armed import armed_periods, starts_armed
    reports = pd.DataFrame({"t_s": [0.5, 1.0, 9.0], "armed": [True, True, False]})
    events = pd.DataFrame({"t_s": [9.0], "armed": [False]})
    assert starts_armed(reports) and not starts_armed(events)
    assert armed_periods(reports, 20.0, starts_armed(reports)) == [(0.5, 9.0)]
    assert armed_periods(events, 20.0, True) == [(0.0, 9.0)]
    assert armed_periods(events, 20.0, False) == []
    vtol = read_log(log_path("uavlogviewer_vtol_sitl.tlog"))
    assert vtol.starts_armed and vtol.armed_source == "HEARTBEAT"
