"""Users' own files from other tools and vehicles (2026-11-27 night): public real mission plans and logs that the
tests before did not hold, run through the readers the commands use (tests/data/flightlogs/SOURCES.md and
tests/data/missions/SOURCES.md, "Added 2026-11-27 night", for each file's origin and licence)."""

import numpy as np
import pytest

from _flightlogs import log_path
from mission_sim.mavlink.logs import read_log

PX4_EVENTS = "pyulog_sample_px4_events.ulg"   # PX4 SITL (v1.15 dev), arms, hops to ~2 m; battery_status current -1


def test_px4_unknown_battery_current_is_not_a_charge():
    """PX4's battery_status.current_a = -1 means "unknown" (its simulated battery sends it on every sample): it was
    read as a 1 A charge, so `replay` printed "logged -16 W" airborne and `calibrate` fitted a 0.1 kg drone to it.
    As SYS_STATUS's -1: no battery data."""
    from pyulog import ULog
    u = ULog(str(log_path(PX4_EVENTS)))
    b = next(d.data for d in u.data_list if d.name == "battery_status")
    assert len(b["current_a"]) == 157 and np.all(b["current_a"] == -1.0) and np.all(b["voltage_v"] > 15)
    log = read_log(log_path(PX4_EVENTS))
    assert len(log.position) == 109 and log.duration_s == pytest.approx(31.1, abs=0.05)
    assert log.battery_source is None and len(log.battery) == 0
