"""Size of a mission run, estimated from its config before anything is allocated.

The mission loop holds the whole trajectory (one sample per ``sim.traj_dt_s``) in memory; its
time-series rows are streamed in blocks (:mod:`.stream`: the summary on the fly, Parquet row groups)
and cost a bounded amount of memory whatever their number, unless a DataFrame of them is asked for
(``run_mission(frame=True)``, the API default). :func:`estimate_run` predicts the sizes from the
planned segment durations (no sampling) and :func:`check_run_size` refuses a run beyond
:data:`MAX_MEMORY_BYTES` / :data:`MAX_OUTPUT_BYTES`, naming the config key that dominates.

Per-unit costs (peak RSS and file sizes, CPython 3.12, pandas 2, pyarrow): a trajectory sample
~200 B, a streamed block of rows ~:data:`STREAM_BYTES` in all, ~145 B of Parquet per stored row
(zstd, byte-stream-split floats; ~510 B more with ``--csv``). Row counts: one coarse row per
trajectory sample while charging, one per ``sim.flight_dt_s`` in flight (and in the uncharged
baseline run, summary only), and about ``6 n_pads + 2`` fine windows of half ``sim.max_fine_s``
each (the default mission has 13 windows and 2720 fine rows; estimate 4200).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .trajectory import _segments

__all__ = ["RunEstimate", "estimate_run", "check_run_size", "MAX_MEMORY_BYTES", "MAX_OUTPUT_BYTES"]

MAX_MEMORY_BYTES = 1 << 30  # 1 GiB
MAX_OUTPUT_BYTES = 1 << 30  # 1 GiB
SAMPLE_BYTES = 200.0
STREAM_BYTES = 64e6       # blocks of rows in flight (loop buffer, the Parquet writer's row group, candidates)
ROW_OUTPUT_BYTES = 145.0  # Parquet per stored row
ROW_MEMORY_BYTES = 1500.0  # a row held in a DataFrame at peak (row tuples, the frame, its copies): frame=True


@dataclass(frozen=True)
class RunEstimate:
    """Estimated size of one ``run_mission`` call (the charged run and its uncharged baseline)."""

    duration_s: float
    samples: float  # trajectory samples
    rows: float  # time-series rows of the charged run
    memory_bytes: float  # peak, both runs (rows streamed)
    output_bytes: float  # timeseries.parquet with every row stored
    key: str  # the dotted config key that contributes most
    value: float


def _segment_key(cfg, seg, pad_index: int) -> tuple[str, float]:
    """The config key that sets a planned segment's duration."""
    phase, _, u, _, _ = seg
    m = cfg.mission
    if u is None:
        if cfg.waypoints and phase in ("charge", "hover"):  # a route: the hold of a loiter / charge waypoint
            return "waypoints.hold_s", seg[3]
        if phase != "charge":
            return "mission.hover_time_s", m.hover_time_s
        pad = cfg.pads[pad_index]
        if pad.hover_time_s is None:
            return "mission.hover_time_s", m.hover_time_s
        return f"pads.{pad_index}.hover_time_s", pad.hover_time_s
    if abs(u[2]) > 1.0 - 1e-9:
        return ("mission.climb_rate_m_s", m.climb_rate_m_s) if u[2] > 0 else \
            ("mission.descent_rate_m_s", m.descent_rate_m_s)
    return "mission.cruise_speed_m_s", m.cruise_speed_m_s


def estimate_run(cfg, frame: bool = False) -> RunEstimate:
    """:class:`RunEstimate` of ``cfg`` (a MissionConfig) from its planned segment durations;
    ``frame``: the caller holds the time series as a DataFrame (``run_mission(frame=True)``, e.g.
    ``telemetry``), so every row costs memory, not only a streamed block."""
    sim = cfg.sim
    per_key: dict[tuple[str, float], float] = {}
    duration = charge_s = 0.0
    pad_index = 0
    for seg in _segments(cfg):
        dur = float(seg[3])
        key = _segment_key(cfg, seg, pad_index)
        if seg[2] is None and seg[0] == "charge":
            charge_s += dur
            pad_index += 1
            rows = dur / sim.traj_dt_s
        else:
            rows = dur / sim.flight_dt_s
        per_key[key] = per_key.get(key, 0.0) + rows
        duration += dur
    fine = (6 * len(cfg.pads) + 2) * 0.5 * sim.max_fine_s / sim.control_period_s
    per_key[("sim.control_period_s", sim.control_period_s)] = fine
    rows = sum(per_key.values())
    samples = duration / sim.traj_dt_s + 1
    memory = SAMPLE_BYTES * samples + STREAM_BYTES + (ROW_MEMORY_BYTES * rows if frame else 0.0)
    (key, value), _ = max(per_key.items(), key=lambda kv: kv[1])
    if samples * SAMPLE_BYTES > ROW_OUTPUT_BYTES * rows:  # the trajectory itself dominates
        key, value = ("sim.traj_dt_s", sim.traj_dt_s) if sim.traj_dt_s < 0.05 else (key, value)
    return RunEstimate(duration_s=duration, samples=samples, rows=rows, memory_bytes=memory,
                       output_bytes=ROW_OUTPUT_BYTES * rows, key=key, value=value)


def _size(n_bytes: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.3g} {unit}"
    return f"{n_bytes / 1e3:.3g} kB"


def check_run_size(cfg, force: bool = False, frame: bool = False) -> RunEstimate:
    """The run's :class:`RunEstimate` (``frame`` as in :func:`estimate_run`); ``ValueError`` (one line
    naming the dominant key and the estimate) when it exceeds the memory or output limit, unless ``force``."""
    est = estimate_run(cfg, frame)
    too_big = est.memory_bytes > MAX_MEMORY_BYTES or est.output_bytes > MAX_OUTPUT_BYTES
    if too_big and not force and math.isfinite(est.memory_bytes):
        raise ValueError(
            f"{est.key}={est.value!r} makes the run too large: {est.duration_s:.4g} s simulated, about "
            f"{est.samples:.2g} trajectory samples and {est.rows:.2g} time-series rows, ~{_size(est.memory_bytes)} "
            f"in memory and ~{_size(est.output_bytes)} of output (limits {MAX_MEMORY_BYTES / 2**30:g} GiB in memory, {MAX_OUTPUT_BYTES / 2**30:g} GiB of output); "
            "use --force to run it anyway")
    if too_big and not force:
        raise ValueError(f"{est.key}={est.value!r} makes the run unbounded; use --force to try anyway")
    return est
