"""Fuzz: truncated and byte-flipped copies of the real logs never crash the reader or the track builder."""

import math
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from _flightlogs import LOG_NAMES, log_path
from mission_sim.mavlink.logs import read_log
from mission_sim.mavlink.replay import NoPositionError, track_from_log

PREFIX = 48_000  # bytes of each log: holds the DataFlash FMT header and hundreds of MAVLink frames
_prefixes: dict[str, bytes] = {}


def _prefix(name):
    if name not in _prefixes:
        with open(log_path(name), "rb") as fh:
            _prefixes[name] = fh.read(PREFIX)
    return _prefixes[name]


def _check(data: bytes, suffix: str):
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / f"fuzz{suffix}"
        p.write_bytes(data)
        log = read_log(p)
        assert log.bad_frames >= 0 and log.n_records >= 0
        assert math.isfinite(log.duration_s) and log.duration_s >= 0
        pos = log.position
        assert pos["lat_deg"].between(-90, 90).all() and pos["lon_deg"].between(-180, 180).all()
        assert np.all(np.diff(pos["t_s"].to_numpy()) > 0)
        assert log.armed_time_s >= 0
        try:
            tr = track_from_log(log)
        except NoPositionError:
            return log
        assert np.all(np.isfinite(tr.pos_m)) and np.all(np.diff(tr.t_s) > 0)
        return log


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(name=st.sampled_from(LOG_NAMES), cut=st.floats(0.0, 1.0),
       flips=st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(1, 255)), max_size=40))
def test_truncated_and_flipped_logs_never_raise(name, cut, flips):
    data = bytearray(_prefix(name)[: int(cut * PREFIX)])
    for where, xor in flips:
        if data:
            data[min(int(where * len(data)), len(data) - 1)] ^= xor
    _check(bytes(data), Path(name).suffix)


def test_empty_and_garbage_files():
    assert read_log_bytes(b"", ".tlog").n_records == 0
    assert read_log_bytes(b"", ".bin").n_records == 0
    rng = np.random.default_rng(0)
    junk = rng.integers(0, 256, 20_000, dtype=np.uint8).tobytes()
    for suffix in (".tlog", ".bin"):
        log = read_log_bytes(junk, suffix)
        assert len(log.position) == 0


def test_flipped_bytes_are_counted_as_bad_frames():
    """Corrupting MAVLink frames inside the good tlog adds bad frames, and the rest is still read."""
    data = bytearray(_prefix("uavlogviewer_vtol_sitl.tlog"))
    clean = read_log_bytes(bytes(data), ".tlog")
    assert clean.bad_frames == 0
    for off in range(1000, len(data), 4000):
        data[off] ^= 0x5A
    dirty = read_log_bytes(bytes(data), ".tlog")
    assert dirty.bad_frames >= 5
    assert dirty.n_records - dirty.bad_frames >= 0.9 * clean.n_records


def read_log_bytes(data: bytes, suffix: str):
    return _check(data, suffix)
