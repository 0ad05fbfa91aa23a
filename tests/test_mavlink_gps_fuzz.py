"""Fuzz over GPS corruption: no accepted fix lies farther than the flight's own extent (issue 12).

DataFlash records carry no checksum, so a flipped byte in a GPS record is decoded as a fix (92 km
away, 118 km high). The log used is log171's FMT and GPS records (a real flight, 1038 fixes at
5 Hz); hypothesis flips bytes inside the GPS payloads' satellites, HDOP, lat, lon and altitude
fields (payload bytes 7..25 of format BIHBcLLeeEefI). Not fuzzed: the status, time and week
bytes -- DFReader takes the whole log's time base from the first GPS record, so a flipped week
there moves every record past the year 2100 and the log reads as empty (a different failure). Every fix the reader accepts must lie within the clean flight's bounding box
widened by the filter's own bound (gpsclean.max_excursion_m).
"""

import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from _flightlogs import dataflash_records, log_path
from mission_sim.mavlink.geodesy import geodetic_to_enu
from mission_sim.mavlink.gpsclean import max_excursion_m
from mission_sim.mavlink.logs import read_log
from mission_sim.mavlink.replay import default_pad

_DATA = log_path("dronekit-la-testdata_log171.bin").read_bytes()
_RECS = [(o, n) for o, typ, n in dataflash_records(_DATA) if typ in ("FMT", "GPS")]
_BASE = b"".join(_DATA[o:o + n] for o, n in _RECS)
_GPS = []   # (offset in _BASE, length) of each GPS record
_pos = 0
for _o, _n in _RECS:
    if _DATA[_o + 2] != 128:
        _GPS.append((_pos, _n))
    _pos += _n


def _read(data: bytes):
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "gps.bin"
        p.write_bytes(data)
        return read_log(p)


_CLEAN = _read(_BASE)
_PAD = default_pad(_CLEAN)


def _enu(pos):
    return np.column_stack(geodetic_to_enu(pos["lat_deg"].to_numpy(), pos["lon_deg"].to_numpy(),
                                           pos["alt_m"].to_numpy(), _PAD))


_BOX = _enu(_CLEAN.position)
_LO, _HI = _BOX.min(axis=0), _BOX.max(axis=0)


def test_clean_log_loses_no_fix():
    assert len(_GPS) > 1000 and len(_CLEAN.position) > 1000
    assert sum(_CLEAN.gps_rejected.values()) == 0
    assert np.ptp(_BOX[:, 0]) < 200 and np.ptp(_BOX[:, 2]) < 30          # a small flight at CMAC


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(flips=st.lists(st.tuples(st.integers(0, 10_000), st.integers(7, 25), st.integers(1, 255)),
                      min_size=1, max_size=60))
def test_no_accepted_fix_beyond_the_flight_extent(flips):
    data = bytearray(_BASE)
    for rec, byte, xor in flips:
        off, n = _GPS[rec % len(_GPS)]
        data[off + 3 + byte] ^= xor                      # payload only: the record framing stays
    log = _read(bytes(data))
    assert log.errors == []
    enu = _enu(log.position)
    mh, mv = max_excursion_m()
    assert np.all(enu[:, :2] >= _LO[:2] - mh) and np.all(enu[:, :2] <= _HI[:2] + mh)
    assert np.all(enu[:, 2] >= _LO[2] - mv) and np.all(enu[:, 2] <= _HI[2] + mv)
    assert len(log.position) >= len(_CLEAN.position) - 3 * len(flips)   # the rest of the flight is kept


def test_the_issue_example_is_rejected_and_counted():
    """Fixes 92 km away and 118 km high (one byte each) are rejected, counted, and the replay's
    track stays within the flight."""
    import struct
    data = bytearray(_BASE)
    off, _ = _GPS[500]
    lat = struct.unpack_from("<i", data, off + 13)[0]
    struct.pack_into("<i", data, off + 13, lat + 8_300_000)          # +0.83 deg: 92 km north
    off2, _ = _GPS[600]
    struct.pack_into("<i", data, off2 + 25, 118_000_00)             # Alt 118 km (cm)
    log = _read(bytes(data))
    assert len(log.position) == len(_CLEAN.position) - 2
    assert log.gps_rejected == {"quality": 0, "origin": 0, "altitude": 1, "jump": 1}
    enu = _enu(log.position)
    assert np.all(enu >= _LO - 1e-6) and np.all(enu <= _HI + 1e-6)
