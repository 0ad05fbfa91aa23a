"""The tables read from one flight log (:class:`FlightLog`), whatever the format: MAVLink .tlog and
DataFlash .bin (logs.py), PX4 ULog (ulog.py). Column sets and units: see logs.py."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .armed import armed_periods

__all__ = ["FlightLog", "NoPositionError", "LogParseError", "check_decoded", "clean_time", "good_timestamps", "TIME_SPIKE_S", "POSITION_COLUMNS", "ATTITUDE_COLUMNS", "ARMED_COLUMNS", "BATTERY_COLUMNS"]

POSITION_COLUMNS = ("t_s", "lat_deg", "lon_deg", "alt_m")
ATTITUDE_COLUMNS = ("t_s", "roll_rad", "pitch_rad")
ARMED_COLUMNS = ("t_s", "armed")
BATTERY_COLUMNS = ("t_s", "voltage_v", "current_a", "power_w")
TIME_SPIKE_S = 60.0   # a record this far off its neighbours' time is corrupt (logs.py, ulog.py)


@dataclass
class FlightLog:
    """What :func:`~mission_sim.mavlink.logs.read_log` found in one log (tables: see logs.py)."""

    path: Path
    kind: str                      # "tlog", "dataflash" or "ulog"
    t0_epoch_s: float              # timestamp of the first record (Unix s); nan if none
    duration_s: float              # last minus first record timestamp
    position: pd.DataFrame
    attitude: pd.DataFrame
    armed: pd.DataFrame
    battery: pd.DataFrame
    battery_source: str | None     # SYS_STATUS, BATTERY_STATUS, CURR, BAT or battery_status (ULog)
    bad_frames: int                # corrupt frames counted and skipped
    n_records: int                 # records decoded (bad frames included)
    mavlink_frames: dict[int, int] = field(default_factory=dict)  # protocol version -> frames (.tlog)
    reboots: int = 0               # time_boot_ms drops seen in GLOBAL_POSITION_INT
    fix_checked: bool = True       # False: the log had no GPS fix information at all
    vehicle: dict = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)
    armed_source: str | None = None  # the records the armed state comes from (see armed.py)
    starts_armed: bool = False     # armed at the first record (first armed-state event a disarm)
    gps_rejected: dict = field(default_factory=dict)  # implausible fixes rejected, by reason (gpsclean.py)
    clock: object = None           # the log's time base (clock.ClockMap); None: the log's own clock, one segment
    airspeed: pd.DataFrame | None = None   # t_s, airspeed_m_s from an airspeed sensor (logs.py); None / empty: none
    #: records whose own timestamp is outside 1970..2100 (counted in bad_frames too) and the first such stamp [s]
    bad_time: int = 0
    first_bad_time_s: float = float("nan")

    @property
    def segments(self) -> list[tuple[float, float]]:
        """(start_s, end_s) of each boot segment (a reboot starts a new one); one for the whole log
        when the log has no boot clock or no reboot."""
        if self.clock is None:
            return [(0.0, float(self.duration_s))]
        return self.clock.spans(self.duration_s)

    @property
    def armed_periods(self) -> list[tuple[float, float]]:
        return armed_periods(self.armed, self.duration_s, self.starts_armed)

    @property
    def armed_time_s(self) -> float:
        return float(sum(b - a for a, b in self.armed_periods))


def clean_time(df: pd.DataFrame, columns, dedupe: bool = True) -> pd.DataFrame:
    """Keep ``columns``, sort by time (stable), drop repeated timestamps (the last report wins)."""
    if not len(df):
        return pd.DataFrame({c: pd.Series(dtype=bool if c == "armed" else float) for c in columns})
    out = df[list(columns)].sort_values("t_s", kind="stable")
    if dedupe:
        out = out.drop_duplicates("t_s", keep="last")
    return out.reset_index(drop=True)


def good_timestamps(ts: np.ndarray) -> np.ndarray:
    """Records whose timestamp is plausible: within :data:`TIME_SPIKE_S` of the centred rolling
    median of 9, or continuing the timeline (0 .. TIME_SPIKE_S after the previous good record).

    A corrupt byte in a .tlog record's 8-byte timestamp (or in a DataFlash TimeUS) makes an
    isolated spike of hours or years; steps (logging paused) and any spacing of a monotonic
    clock pass, since the centred median of a sorted window is its middle element. At the end of
    a log the window is one-sided: a few sparse records (a parameter write 31 s after the
    previous record) would be judged against older ones; the continuation rule keeps them.
    """
    if len(ts) == 0:
        return np.zeros(0, dtype=bool)
    med = pd.Series(ts).rolling(9, center=True, min_periods=1).median().to_numpy()
    good = np.abs(ts - med) <= TIME_SPIKE_S  # False for nan (implausible timestamps)
    for i in np.flatnonzero(~good & np.isfinite(ts)):
        prev = np.flatnonzero(good[:i])
        last = ts[prev[-1]] if len(prev) else np.nan
        if 0.0 <= ts[i] - last <= TIME_SPIKE_S:
            good[i] = True
    return good


class NoPositionError(ValueError):
    """The log holds fewer than two usable (GPS fix >= 3) positions."""


class LogParseError(NoPositionError):
    """pymavlink (or pyulog) failed on the log before any usable position: says what failed."""


def check_decoded(log: FlightLog) -> None:
    """:class:`NoPositionError` saying what the file is when not one good record was decoded from it (an empty file, a
    text file, a log cut before its first record): "0 usable position sample(s)" said nothing of that."""
    if log.errors or log.n_records > log.bad_frames:
        return
    try:
        size = log.path.stat().st_size
    except OSError:
        size = -1
    bad = f", {log.bad_frames} corrupt frame(s)" if log.bad_frames else ""
    what = ("the file is empty (0 bytes)" if size == 0 else
            f"no readable record in its {size} bytes{bad}: cut short before its first record, or not a flight log")
    if size > 0 and log.n_records and log.bad_time == log.n_records:   # the frames decode; only their stamps are wrong
        what = (f"every one of its {log.n_records} records has an implausible timestamp (the first "
                f"{log.first_bad_time_s:.6g} s since 1970, outside 1970..2100: nanoseconds? a .tlog stamps each frame "
                "with 8-byte big-endian microseconds since 1970)")
    raise NoPositionError(f"{log.path.name}: no usable position (GPS fix >= 3): {what}; valid: a MAVLink .tlog, a "
                          "DataFlash .bin or a PX4 .ulg")


def _no_position(log: FlightLog, detail: str) -> NoPositionError:
    """The error for a log without enough positions: the parser's own error first if it failed."""
    check_decoded(log)
    if log.errors:
        return LogParseError(f"{log.path.name}: the log could not be parsed: {log.errors[0]} "
                             f"({log.n_records} records decoded before it{detail})")
    rejected = sum(log.gps_rejected.values())
    why = f"; {rejected} implausible fixes rejected ({_fmt_counts(log.gps_rejected)})" if rejected else ""
    return NoPositionError(f"{log.path.name}: no usable position (GPS fix >= 3){detail}{why}")


def _fmt_counts(counts: dict) -> str:
    return ", ".join(f"{k} {v}" for k, v in counts.items() if v)
