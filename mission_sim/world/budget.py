"""Size of a mission run, estimated from its config before anything is allocated.

The mission loop holds neither the trajectory nor the time series whole: the trajectory is planned
in blocks of :data:`~.trajectory.PLAN_BLOCK` samples and the per-sample arrays are computed in chunks
of :data:`~.samples.SAMPLE_CHUNK` (:mod:`.samples`); the rows are streamed in blocks (:mod:`.stream`:
the summary on the fly, Parquet row groups). So a streamed run's memory is bounded whatever its
length, unless a DataFrame of the rows is asked for (``run_mission(frame=True)``, the API default).
:func:`estimate_run` predicts the sizes from the planned segment durations (no sampling) and
:func:`check_run_size` refuses a run beyond :data:`MAX_MEMORY_BYTES` / :data:`MAX_OUTPUT_BYTES`, naming
the config key that dominates.

Memory (peak RSS, measured with ``dronewpt mission --no-plot``, CPython 3.11, numba 0.68, pyarrow 26;
the default pads repeated n times): 222 MB (n = 1), 235 MB (10), 243 MB (30), 270 MB (200), i.e.
:data:`FIXED_BYTES` (interpreter, numpy, numba with the loop's compiled kernels, pyarrow and the Parquet
writer, the row blocks) plus :data:`SAMPLE_BYTES` per trajectory sample up to :data:`HELD_SAMPLES`
(a planned block and a chunk of per-sample arrays; the allocator's growth beyond that is within it).
The five figures of ``dronewpt mission`` add ~50-100 MB (matplotlib, see docs/streaming.md); a row
held in a DataFrame costs :data:`ROW_MEMORY_BYTES`.

Rows (one per control period in a fine window, the rectifier-period sub-steps merged; one per
trajectory sample while charging; one per ``sim.flight_dt_s`` in quiet flight): measured on the default
mission 3,463 rows (2,515 fine in 11 windows, 948 coarse) and 40,334 with its pads repeated 10 times
(30,962 fine in 132 windows, 9,372 coarse): ~6.6 fine windows per pad of ~0.39 ``sim.max_fine_s``
each. Estimated as ``7 n_pads + 1`` windows of :data:`FINE_FRACTION` ``max_fine_s``: 4,546 and 43,196
rows (1.31x and 1.07x the real counts; an estimate for a limit errs high). Output: ~138-146 B of
Parquet per stored row measured (zstd, byte-stream-split floats; :data:`ROW_OUTPUT_BYTES`; ~510 B
more with ``--csv``). ``tests/test_budget.py`` compares the estimate with real runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .trajectory import _path

__all__ = ["RunEstimate", "estimate_run", "check_run_size", "MAX_MEMORY_BYTES", "MAX_OUTPUT_BYTES", "FIXED_BYTES",
           "SAMPLE_BYTES", "HELD_SAMPLES"]

MAX_MEMORY_BYTES = 1 << 30  # 1 GiB
MAX_OUTPUT_BYTES = 1 << 30  # 1 GiB
FIXED_BYTES = 225e6       # the process and its fixed buffers (see the module notes)
SAMPLE_BYTES = 650.0      # per trajectory sample held (planning block, chunk arrays, their temporaries)
HELD_SAMPLES = (1 << 15) + (1 << 16)   # trajectory.PLAN_BLOCK + samples.SAMPLE_CHUNK: at most this many held
STREAM_BYTES = 0.0        # blocks of rows in flight: bounded, inside FIXED_BYTES (kept for callers)
FINE_FRACTION = 0.4       # a fine window's mean length as a fraction of sim.max_fine_s (measured 0.39)
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


def _segment_key(cfg, seg, pad_index: int, route_key=None) -> tuple[str, float]:
    """The config key that sets a planned segment's duration (``route_key``: the route's key that set it, ``_Path.
    keys``: a waypoint's speed for a move, a loiter's ``waypoints.{i}.hold_s`` or a charge's pad ``hover_time_s``
    for a hold; a slow DO_CHANGE_SPEED was blamed on mission.cruise_speed_m_s, a hold on a bare waypoints.hold_s)."""
    phase, _, u, _, _ = seg
    m = cfg.mission
    if u is None:
        if route_key is not None:  # a route: the hold of a loiter / charge waypoint
            return route_key
        if phase != "charge":
            return "mission.hover_time_s", m.hover_time_s
        pad = cfg.pads[pad_index]
        if pad.hover_time_s is None:
            return "mission.hover_time_s", m.hover_time_s
        return f"pads.{pad_index}.hover_time_s", pad.hover_time_s
    if abs(u[2]) > 1.0 - 1e-9:
        return ("mission.climb_rate_m_s", m.climb_rate_m_s) if u[2] > 0 else \
            ("mission.descent_rate_m_s", m.descent_rate_m_s)
    return route_key or ("mission.cruise_speed_m_s", m.cruise_speed_m_s)


def estimate_run(cfg, frame: bool = False) -> RunEstimate:
    """:class:`RunEstimate` of ``cfg`` (a MissionConfig) from its planned segment durations;
    ``frame``: the caller holds the time series as a DataFrame (``run_mission(frame=True)``, e.g.
    ``telemetry``), so every row costs memory, not only a streamed block."""
    sim = cfg.sim
    per_key: dict[tuple[str, float], float] = {}
    duration = charge_s = 0.0
    pad_index = 0
    path = _path(cfg)
    for seg, route_key in zip(path.segs, path.keys):
        dur = float(seg[3])
        key = _segment_key(cfg, seg, pad_index, route_key)
        if seg[2] is None and seg[0] == "charge":
            charge_s += dur
            pad_index += 1
            rows = dur / sim.traj_dt_s
        else:
            rows = dur / sim.flight_dt_s
        per_key[key] = per_key.get(key, 0.0) + rows
        duration += dur
    fine = (7 * len(cfg.pads) + 1) * FINE_FRACTION * sim.max_fine_s / sim.control_period_s
    per_key[("sim.control_period_s", sim.control_period_s)] = fine
    rows = sum(per_key.values())
    samples = duration / sim.traj_dt_s + 1
    memory = FIXED_BYTES + SAMPLE_BYTES * min(samples, HELD_SAMPLES) + (ROW_MEMORY_BYTES * rows if frame else 0.0)
    (key, value), _ = max(per_key.items(), key=lambda kv: kv[1])
    if samples > 0.5 * rows:  # the trajectory's samples set the rows (a fine sim.traj_dt_s)
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
