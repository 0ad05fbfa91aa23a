"""How the trimmed logs in this folder were made from the originals (see SOURCES.md).

usage: python tests/data/flightlogs/trim.py SHARED_FLIGHTLOGS_DIR

Trimming keeps whole records of the message types the tests and the replay use, byte for byte,
in their original order (and always the first and the last record, so the duration is the
original's). Nothing is re-encoded and no value is changed:

* .tlog: each record is the 8-byte big-endian microsecond timestamp and the MAVLink frame as
  pymavlink returns it (``msg.get_msgbuf()``); corrupt stretches (BAD_DATA) are kept as they are.
* DataFlash .bin: the records are walked with the log's own FMT table (header A3 95, type, fixed
  length per type) and the FMT records plus the kept types are copied.

The PX4 ULog file is copied unchanged (pyulog has no writer; it is under 1 MB).
"""

from __future__ import annotations

import os
import shutil
import struct
import sys
from pathlib import Path

os.environ["MAVLINK20"] = "1"
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # tests/: the DataFlash record walker
from _flightlogs import dataflash_records  # noqa: E402

TLOG_KEEP = {"HEARTBEAT", "GLOBAL_POSITION_INT", "GPS_RAW_INT", "ATTITUDE", "SYS_STATUS", "BATTERY_STATUS",
             "SERVO_OUTPUT_RAW", "VFR_HUD", "STATUSTEXT", "BAD_DATA"}
DF_KEEP = {"FMT", "GPS", "ATT", "CURR", "BAT", "EV", "ARM", "MODE", "MSG", "ERR", "RCOU", "CTUN", "PARM"}
FILES = {"dronekit-python_flight.tlog": "tlog", "uavlogviewer_vtol_sitl.tlog": "tlog",
         "ardusub_log_tools_small_rov.tlog": "tlog", "dronekit-la-testdata_log171.bin": "dataflash",
         "pyulog_sample_log_small.ulg": "copy"}


def trim_tlog(src: Path, dst: Path, keep=TLOG_KEEP) -> int:
    """Copy the records of the ``keep`` types (and the first and last record); returns records written."""
    from pymavlink import mavutil
    m = mavutil.mavlink_connection(str(src))
    recs = []
    while (msg := m.recv_match(blocking=False)) is not None:
        recs.append((msg.get_type(), struct.pack(">Q", int(round(msg._timestamp * 1e6))) + bytes(msg.get_msgbuf())))
    out = [r for i, (typ, r) in enumerate(recs) if typ in keep or i in (0, len(recs) - 1)]
    dst.write_bytes(b"".join(out))
    return len(out)


def trim_dataflash(src: Path, dst: Path, keep=DF_KEEP) -> int:
    data = src.read_bytes()
    recs = list(dataflash_records(data))
    out = [data[o:o + n] for i, (o, name, n) in enumerate(recs) if name in keep or i == len(recs) - 1]
    dst.write_bytes(b"".join(out))
    return len(out)


def main(shared: Path) -> None:
    here = Path(__file__).resolve().parent
    for name, kind in FILES.items():
        src, dst = shared / name, here / name
        if kind == "tlog":
            n = trim_tlog(src, dst)
        elif kind == "dataflash":
            n = trim_dataflash(src, dst)
        else:
            shutil.copyfile(src, dst)
            n = -1
        print(f"{name}: {src.stat().st_size} -> {dst.stat().st_size} bytes ({n} records)")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
