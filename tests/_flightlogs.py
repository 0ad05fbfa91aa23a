"""The real flight logs the tests use (tests/data/flightlogs, in the repository), and pymavlink references.

The logs are trimmed copies of public real logs, with their licences and attribution in
tests/data/flightlogs/SOURCES.md; no test reads data from outside the repository.
"""

from __future__ import annotations

import contextlib
import os
import struct
import tempfile
from pathlib import Path

import pytest

LOG_NAMES = ("dronekit-python_flight.tlog", "dronekit-la-testdata_log171.bin",
             "uavlogviewer_vtol_sitl.tlog", "ardusub_log_tools_small_rov.tlog")
ULOG_NAME = "pyulog_sample_log_small.ulg"
DATA_DIR = Path(__file__).resolve().parent / "data" / "flightlogs"
#: every test file that reads a flight log (the hypothesis fuzz tests aside: they read the same files);
#: tests/conftest.py runs them under :func:`log_guard`, tests/test_mavlink_selfcontained.py checks the list
LOG_TESTS = ("test_mavlink_io.py", "test_cli_replay_errors.py", "test_replay_integration.py",
             "test_mavlink_armed.py", "test_mavlink_ulog.py", "test_telemetry_loopback.py", "test_mavlink_clock.py",
             "test_calibrate.py", "test_integrator_newcomer.py", "test_owndata.py", "test_newcomer2.py",
             "test_mend_loose8.py")
LOG_SUFFIXES = (".tlog", ".bin", ".ulg", "SOURCES.md")


def log_guard(home: Path, refused: Path, active=lambda: True):
    """An audit hook (``sys.addaudithook``) under which opening a file named like a flight log
    (:data:`LOG_SUFFIXES`) fails with PermissionError unless it lies under ``home``, or in the
    temporary folder (copies the tests make) but not under ``refused``; inert while ``active()`` is false."""
    home_s, refused_s = str(Path(home).resolve()) + os.sep, str(Path(refused).resolve()) + os.sep
    tmp_s = str(Path(tempfile.gettempdir()).resolve()) + os.sep

    def hook(event, args):
        if event != "open" or not args or not isinstance(args[0], (str, bytes, os.PathLike)) or not active():
            return
        p = str(Path(os.fsdecode(args[0])).resolve())
        if p.endswith(LOG_SUFFIXES) and not p.startswith(home_s) and (p.startswith(refused_s) or not p.startswith(tmp_s)):
            raise PermissionError(f"test opened a flight log outside the repository: {p}")
    return hook


def flightlogs_dir() -> Path:
    if not (DATA_DIR / "SOURCES.md").is_file():
        pytest.fail(f"flight logs not found in the repository at {DATA_DIR}")
    return DATA_DIR


def log_path(name: str) -> Path:
    return flightlogs_dir() / name


def pymavlink_reference(path: Path) -> dict:
    """Facts computed with pymavlink directly (plain loops, independent of mission_sim.mavlink.logs).

    duration (last - first record timestamp), armed periods (vehicle HEARTBEAT base_mode bit 7 in a
    .tlog, EV 10/11 in a .bin), positions with a 3D fix, HDOP <= 10 and >= 4 satellites and an
    altitude within 100 m of the last GPS_RAW_INT's (``origin``: the positions that were not; lat/lon/alt extents and count), battery
    voltage range and sample count, (t, V I) of SYS_STATUS / CURR.
    """
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil

    # (closed on a failure too: left to the collector, a ResourceWarning in a later test, test_reading_a_log_..._no_file_open's)
    with contextlib.closing(mavutil.mavlink_connection(str(path))) as m:
        first = last = None
        armed_state, armed_start, periods = False, None, []
        fix, gps_alt, origin = 0, float("nan"), 0
        lats, lons, alts, volts, volts_bs, power = [], [], [], [], [], []
        bad = 0
        while True:
            msg = m.recv_match(blocking=False)
            if msg is None:
                break
            t = msg._timestamp
            first = t if first is None else first
            last = t
            typ = msg.get_type()
            if typ == "BAD_DATA":
                bad += 1
                continue
            rel = t - first
            new_armed = None
            if typ == "HEARTBEAT" and msg.autopilot != 8 and msg.get_srcComponent() == 1:
                new_armed = bool(msg.base_mode & 128)
            elif typ == "EV" and msg.Id in (10, 11):
                new_armed = msg.Id == 10
            if new_armed is not None and new_armed != armed_state:
                if new_armed:
                    armed_start = rel
                else:
                    periods.append((armed_start, rel))
                armed_state = new_armed
            if typ == "GPS_RAW_INT" and msg.get_srcComponent() == 1:
                poor = (msg.eph != 65535 and msg.eph > 1000) or msg.satellites_visible < 4  # HDOP > 10, < 4 sats
                fix = 0 if poor else msg.fix_type
                gps_alt = msg.alt / 1e3
            if typ == "GLOBAL_POSITION_INT" and msg.get_srcComponent() == 1 and fix >= 3 and msg.lat != 0:
                if abs(msg.alt / 1e3 - gps_alt) > 100:   # estimator altitude without a GPS origin
                    origin += 1
                    continue
                lats.append(msg.lat / 1e7), lons.append(msg.lon / 1e7), alts.append(msg.alt / 1e3)
            if typ == "GPS" and msg.Status >= 3 and msg.HDop <= 10 and msg.NSats >= 4:
                lats.append(msg.Lat), lons.append(msg.Lng), alts.append(msg.Alt)
            if typ == "SYS_STATUS" and msg.voltage_battery not in (0, 65535) and msg.current_battery != -1:
                volts.append(msg.voltage_battery / 1000)
                power.append((rel, msg.voltage_battery / 1000 * msg.current_battery / 100))
            if typ == "CURR":
                volts.append(msg.Volt / 100)
                power.append((rel, msg.Volt / 100 * msg.Curr / 100))
            if typ == "BATTERY_STATUS" and msg.id == 0:
                volts_bs.append(sum(v for v in msg.voltages if v != 65535) / 1000)
    if armed_state:
        periods.append((armed_start, last - first))
    return {"duration_s": last - first, "armed_periods": periods, "n_pos": len(lats),
            "lat": (min(lats), max(lats)), "lon": (min(lons), max(lons)), "alt": (min(alts), max(alts)),
            "volt": (min(volts), max(volts)) if volts else None, "n_volt": len(volts), "bad": bad, "power": power,
            "volt_bs": (min(volts_bs), max(volts_bs)) if volts_bs else None, "n_volt_bs": len(volts_bs),
            "origin": origin}


def dataflash_records(data: bytes):
    """(offset, type name, length) of each record of a DataFlash log, from its FMT records.

    Stops at the first byte that does not start a known record (a truncated tail)."""
    lengths, names = {128: 89}, {128: "FMT"}
    off = 0
    while off + 3 <= len(data) and data[off:off + 2] == b"\xa3\x95":
        typ = data[off + 2]
        if typ not in lengths or off + lengths[typ] > len(data):
            return
        if typ == 128:
            t, length, name = struct.unpack("<BB4s", data[off + 3:off + 9])
            lengths[t], names[t] = length, name.rstrip(b"\0").decode("ascii", "replace")
        yield off, names[typ], lengths[typ]
        off += lengths[typ]


def tlog_records(path) -> list[tuple[float, bytes]]:
    """(receive time [s], frame bytes) of every record of a .tlog, by pymavlink."""
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil
    with contextlib.closing(mavutil.mavlink_connection(str(path))) as m:
        out = []
        while (msg := m.recv_match(blocking=False)) is not None:
            out.append((msg._timestamp, bytes(msg.get_msgbuf())))
    return out


def write_tlog(path: Path, records) -> Path:
    """A .tlog of ``records`` (receive time [s], frame bytes): 8-byte big-endian microseconds, then the frame."""
    path.write_bytes(b"".join(struct.pack(">Q", int(round(t * 1e6))) + f for t, f in records))
    return path
