"""One time base per .tlog: the vehicle's boot clock, mapped once onto the log (receive) clock.

A .tlog holds two clocks. The ground station stamps every frame when it arrives (the 8-byte
receive timestamp, ``msg._timestamp``); position and attitude messages also carry the vehicle's
own ``time_boot_ms``, battery messages (SYS_STATUS, BATTERY_STATUS) do not. The two clocks run at
different rates when the vehicle is simulated faster than real time (SITL ``--speedup``,
``dronewpt telemetry --speed 3`` recorded by a ground station), and the vehicle clock restarts at
every reboot. Timing positions by one clock and battery samples by the other made the replayed
energy wrong by +16 % at a 1.1x vehicle clock (issue 24).

So, per boot segment ``k`` (a segment ends where ``time_boot``, smoothed by a rolling median
of 5 so that one corrupt value is no reboot, drops by more than :data:`REBOOT_DROP_S`): a robust linear fit of receive time on boot time (Theil-Sen, the
median of pairwise slopes, so radio bursts and a few corrupt ``time_boot_ms`` values do not bend
it), ``recv = a_k + b_k * boot``; when 1 lies inside the fit's 99 % confidence interval of ``b_k``
(a real radio link: crystal drift of ppm hidden under the latency jitter) ``b_k = 1`` and ``a_k``
is the median offset; so is it when ``|b_k - 1| <=`` :data:`DRIFT_SNAP` (the dronekit radio log fits
a 240-390 ppm "drift" that is latency growing in the radio's buffers; the fitted value is kept in
``fit_slope`` and reported). The log's time base ``t`` runs at the **vehicle's** rate: in
segment ``k``

    t(boot) = t_k + (a_k + b_k * boot - r_k) / b_k    (records with a boot time: positions, attitude)
    t(recv) = t_k + (recv - r_k) / b_k                (records without one at b_k = 1: battery, heartbeats)
    t(recv) = t(boot interpolated at recv)            (... at b_k != 1, a faster vehicle clock)
    t(recv) = t(boot of the first / last node + (recv - its recv) / b_k)   (... before / after the nodes)

with ``r_k`` the receive time of the segment's first boot-stamped record and ``t_k`` chosen so
that ``t`` is continuous across segments and ``t(0) = 0`` at the start of the log. Within a
segment ``t`` is the boot clock plus one offset. On a real link (``b_k = 1``) a record without a
boot time keeps its receive time (latency jitter of ~0.1 s; the log's duration and armed edges are
the receive clock's, as a ground station shows them). With a faster vehicle clock (``b_k != 1``,
a simulated vehicle) a record without a boot time takes the boot time
of its receive time interpolated between the boot-stamped records around it (receive order; boot
times smoothed by a rolling median of 5 and made non-decreasing), not the fitted line: a sender
that stalls for a few seconds (a loaded machine pacing ``telemetry --speed 3``, a radio fade)
bends the receive clock against the boot clock, and a battery sample is then still placed at the
vehicle time it was sent at (the MAVProxy recording in tests/data/telemetry fits 2.78x, not 3x,
because of such a stall). At 1x (a real
radio link: ``b`` = 1 within crystal drift) ``t`` is the receive clock; at a vehicle clock ``s``
times faster, ``b = 1 / s`` and every sample -- battery too -- is on the vehicle's seconds, in
which its power was drawn. DataFlash and ULog logs are stamped by the vehicle alone and need
no map (:func:`identity_clock`).

Record-order mode (:attr:`BootSegment.by_record`): when a segment's receive stamps do not advance against its boot
clock -- the spans between the 5th and 95th percentiles (one corrupt value widens neither) give less than
:data:`FROZEN_RATIO` receive seconds per vehicle second over at least 1 s of boot time: one stamp or 0 on every
frame, or milliseconds / seconds written in the microsecond field -- there is no receive clock to place the records
without a boot time by. They are placed by **record order** instead: a record's boot time is interpolated in its
record number between the boot-stamped records around it (boot times smoothed and non-decreasing, as above). Its
limitation: records before the segment's first boot-stamped record, or after its last, have no neighbour on that
side and collapse onto its time (a landing's trailing heartbeats and battery samples all land at the last position's
instant, so the log's duration and disarm edge are the last position's, up to the length of that tail short).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BootSegment", "ClockMap", "fit_clock", "identity_clock", "REBOOT_DROP_S", "FIT_MAX_POINTS", "DRIFT_SNAP",
           "RECV_STEP_S", "FROZEN_RATIO"]

REBOOT_DROP_S = 10.0      # a time_boot drop this large is a reboot, not jitter between message types
RECV_STEP_S = 5.0         # receive minus boot time stepping by more than this is the ground station's clock set
DRIFT_SNAP = 1e-3         # |b - 1| up to this (1000 ppm, beyond any crystal) is link latency, not a faster clock
FIT_MAX_POINTS = 600      # Theil-Sen is O(n^2): fit on this many evenly spread samples per segment
_SLOPE_RANGE = (1e-3, 1e3)  # receive seconds per vehicle second accepted from a fit (else 1)
#: receive seconds per vehicle second (5-95 % spans) below this: the receive stamps do not advance (one value, 0, or
#: milliseconds / seconds written in the microsecond field: 1e-3 / 1e-6, which sat on the fit's edge) and the records
#: are placed by record order. Twice the fit's lower bound: a SITL run up to 500x faster than real time is still fitted.
FROZEN_RATIO = 2 * _SLOPE_RANGE[0]


@dataclass(frozen=True)
class BootSegment:
    """One boot of the vehicle: records ``rec_start`` .. (next segment's) on the log's time base.

    ``slope`` b [log s per vehicle s] and ``offset_s`` a [s] of the fit ``recv = a + b boot``;
    ``recv_start_s`` r_k, ``t_start_s`` t_k; ``n_fit`` boot-stamped samples it was fitted on."""

    index: int
    rec_start: int
    recv_start_s: float
    t_start_s: float
    slope: float
    offset_s: float
    boot_start_s: float
    boot_end_s: float
    n_fit: int
    fit_slope: float = float("nan")   # the fitted b before the snap to 1 (reported: the link's drift)
    #: steps of the receive clock within the boot (the ground station's clock set back or forward), each
    #: (rec_before, recv_before, rec_after, recv_after, step_s): the last boot-stamped record before the
    #: step and the first after it (record numbers, receive times) and the step [s]; receive times
    #: after a step are taken back by the sum of the steps so far (:meth:`unstep`)
    steps: tuple = ()
    #: the receive timestamps do not advance (a log written with one stamp, or 0, on every frame): records without
    #: a boot time are placed by record order between the boot-stamped ones (:meth:`ClockMap.map`)
    by_record: bool = False

    def unstep(self, rec, recv) -> np.ndarray:
        """Receive times ``recv`` of records ``rec`` of this segment with its receive-clock :attr:`steps`
        taken out. A record between the two boot-stamped records around a step goes with the one whose
        receive time is nearer."""
        return _unstep(self.steps, rec, recv)

    @property
    def rate(self) -> float:
        """Vehicle seconds per log (receive) second: 1 on a real link, ``s`` for a clock ``s`` x faster."""
        return 1.0 / self.slope

    def recv_to_t(self, recv):
        return self.t_start_s + (np.asarray(recv, dtype=float) - self.recv_start_s) / self.slope

    def boot_to_t(self, boot):
        return self.recv_to_t(self.offset_s + self.slope * np.asarray(boot, dtype=float))


def _unstep(steps, rec, recv) -> np.ndarray:
    """:meth:`BootSegment.unstep` of the receive-clock ``steps`` (also before the segment is built)."""
    recv = np.asarray(recv, dtype=float)
    if not steps:
        return recv
    rec, out, total = np.asarray(rec), recv.copy(), 0.0
    for rec_b, recv_b, rec_a, recv_a, step in steps:
        total += step
        after = (rec >= rec_a) | ((rec > rec_b) & (np.abs(recv - recv_a) < np.abs(recv - recv_b)))
        out[after] = recv[after] - total
    return out


@dataclass(frozen=True)
class ClockMap:
    """The log's time base: its boot segments (one for a log without boot times) and where it came from."""

    segments: tuple
    source: str
    anchors: tuple = ()    # per segment: (receive times, boot times) of its boot-stamped records, sorted

    def segment_of(self, rec) -> np.ndarray:
        """Segment index of each record number ``rec`` (records before the first segment: 0)."""
        starts = np.array([s.rec_start for s in self.segments])
        return np.clip(np.searchsorted(starts, np.asarray(rec), side="right") - 1, 0, len(starts) - 1)

    def map(self, rec, recv, boot=None, spike_s: float = np.inf) -> np.ndarray:
        """Times on the log's base of records ``rec`` received at ``recv`` [s] (and with boot time
        ``boot`` [s], nan where none). A boot time that lands more than ``spike_s`` from its own
        receive time's mapping (a corrupt ``time_boot_ms``) is not used."""
        rec, recv = np.asarray(rec), np.asarray(recv, dtype=float)
        seg = self.segment_of(rec)
        out = np.empty(len(recv))
        for k, s in enumerate(self.segments):
            m = seg == k
            r = s.unstep(rec[m], recv[m])
            out[m] = s.recv_to_t(r)
            if k < len(self.anchors) and len(self.anchors[k][0]) >= 1 and s.by_record:
                x, y = self.anchors[k]   # (record numbers, boot times): no receive clock to place them by
                out[m] = s.boot_to_t(np.interp(rec[m], x, y))
            elif k < len(self.anchors) and len(self.anchors[k][0]) >= 1 and s.slope != 1.0:
                x, y = self.anchors[k]
                # between nodes: interpolated; beyond them: the fitted rate from the end node
                est = np.interp(r, x, y) + np.minimum(r - x[0], 0.0) / s.slope + np.maximum(r - x[-1], 0.0) / s.slope
                out[m] = s.boot_to_t(est)
            if boot is not None:
                tb = s.boot_to_t(np.asarray(boot, dtype=float)[m])
                ok = np.isfinite(tb) & (np.abs(tb - out[m]) <= spike_s)
                out[np.flatnonzero(m)[ok]] = tb[ok]
        return out

    def spans(self, end_t_s: float) -> list[tuple[float, float]]:
        """(start, end) of each segment on the log's time base; the first starts at 0, the last ends at ``end_t_s``."""
        starts = [0.0] + [s.t_start_s for s in self.segments[1:]]
        ends = starts[1:] + [float(end_t_s)]
        return list(zip(starts, ends))

    def describe(self) -> list[dict]:
        """JSON-ready facts per segment (1-based numbers, rates, boot-time spans)."""
        return [{"segment": s.index + 1, "clock_rate": round(s.rate, 6),
                 "fitted_rate": round(1.0 / s.fit_slope, 6) if s.fit_slope == s.fit_slope else None,
                 "boot_start_s": round(s.boot_start_s, 3),
                 "boot_end_s": round(s.boot_end_s, 3), "n_fit": s.n_fit} for s in self.segments]


def identity_clock(source: str = "log clock") -> ClockMap:
    """One segment, ``t = recv``: logs stamped by the vehicle itself (DataFlash, ULog) or without boot times."""
    return ClockMap((BootSegment(0, 0, 0.0, 0.0, 1.0, 0.0, float("nan"), float("nan"), 0),), source)


def _theil_sen(boot: np.ndarray, recv: np.ndarray) -> tuple[float, float, float]:
    """(a, b, fitted b) of ``recv = a + b boot`` by Theil-Sen on at most :data:`FIT_MAX_POINTS`
    samples; ``b`` is 1 (and ``a`` the median offset) when the fitted drift is not resolved or
    within :data:`DRIFT_SNAP`."""
    from scipy.stats import theilslopes

    if len(boot) < 2 or np.ptp(boot) <= 0:
        return (float(np.median(recv - boot)) if len(boot) else 0.0), 1.0, float("nan")
    idx = np.unique(np.linspace(0, len(boot) - 1, min(len(boot), FIT_MAX_POINTS)).astype(int))
    b, a, lo, hi = theilslopes(recv[idx], boot[idx], alpha=0.99)
    if not (np.isfinite(b) and _SLOPE_RANGE[0] <= b <= _SLOPE_RANGE[1]):
        return float(np.median(recv - boot)), 1.0, float("nan")
    if lo <= 1.0 <= hi or abs(b - 1.0) <= DRIFT_SNAP:
        return float(np.median(recv - boot)), 1.0, float(b)   # a real link: keep the receive rate
    return float(a), float(b), float(b)


def _anchors(recv: np.ndarray, boot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(receive, boot) interpolation nodes of one segment: receive times non-decreasing, boot times
    smoothed (rolling median of 5: one corrupt time_boot_ms does not move its neighbours) and
    non-decreasing."""
    import pandas as pd

    y = pd.Series(boot).rolling(5, center=True).median().to_numpy()   # nan at the 2 + 2 edge nodes
    y = np.where(np.isfinite(y), y, boot)
    return np.maximum.accumulate(recv), np.maximum.accumulate(y)


def _recv_steps(rec: np.ndarray, recv: np.ndarray, boot: np.ndarray) -> tuple:
    """:attr:`BootSegment.steps` of one boot segment's boot-stamped records: where receive minus boot time
    (smoothed by a rolling median of 5: one late frame is no step) moves by more than :data:`RECV_STEP_S`."""
    import pandas as pd

    if len(rec) < 2:
        return ()
    d = pd.Series(recv - boot).rolling(5, center=True, min_periods=1).median().to_numpy()
    cuts = (np.flatnonzero(np.abs(np.diff(d)) > RECV_STEP_S) + 1).tolist()
    # a step persists: the levels (medians) on either side differ, and the level after it runs on the receive clock
    # (receive span at least half its boot span). A sender's stall and catch-up mid-log leave the levels equal; one at
    # the log's end leaves its burst (receive span ~0) as the last level, which differs.
    while cuts:
        bounds = [0, *cuts, len(rec)]
        med = [float(np.median(recv[i:j] - boot[i:j])) for i, j in zip(bounds[:-1], bounds[1:])]
        keep = [c for n, (c, j) in enumerate(zip(cuts, bounds[2:])) if abs(med[n + 1] - med[n]) > RECV_STEP_S
                and recv[j - 1] - recv[c] >= 0.5 * (boot[j - 1] - boot[c])]
        if keep == cuts:
            return tuple((int(rec[c - 1]), float(recv[c - 1]), int(rec[c]), float(recv[c]), med[n + 1] - med[n])
                         for n, c in enumerate(cuts))
        cuts = keep
    return ()


def _span(x: np.ndarray) -> float:
    """The span of ``x`` between its 5th and 95th percentiles (a few corrupt values do not widen it)."""
    lo, hi = np.percentile(x, [5.0, 95.0])
    return float(hi - lo)


def fit_clock(rec, recv, boot) -> ClockMap:
    """The :class:`ClockMap` of a .tlog from its boot-stamped records: record numbers ``rec``,
    receive times ``recv`` [s from the log start] and boot times ``boot`` [s] (any order; sorted
    by record here). No boot-stamped record: :func:`identity_clock`."""
    rec, recv, boot = (np.asarray(x) for x in (rec, recv, boot))
    ok = np.isfinite(recv) & np.isfinite(boot)
    order = np.argsort(rec[ok], kind="stable")
    rec, recv, boot = rec[ok][order], recv[ok][order].astype(float), boot[ok][order].astype(float)
    if not len(rec):
        return identity_clock("log clock (no time_boot_ms in the log)")
    import pandas as pd
    smooth = pd.Series(boot).rolling(5, center=True, min_periods=1).median().to_numpy()  # a corrupt value is no reboot
    cuts = np.flatnonzero(np.diff(smooth) < -REBOOT_DROP_S) + 1
    bounds = [0, *cuts.tolist(), len(rec)]
    segments, anchors, t_start = [], [], 0.0
    for k, (i, j) in enumerate(zip(bounds[:-1], bounds[1:])):
        steps = _recv_steps(rec[i:j], recv[i:j], boot[i:j])
        seg_recv = _unstep(steps, rec[i:j], recv[i:j])
        # the receive clock does not advance against the boot clock (slower than any rate a fit accepts): no clock to
        # place the battery and heartbeat records by (they all landed at one instant: "0.0 s logged", never armed)
        # (spans between the 5th and 95th percentiles: one corrupt time_boot_ms, 4e9 ms, made the boot span huge)
        span_boot, span_recv = _span(boot[i:j]), _span(seg_recv)
        frozen = span_boot >= 1.0 and span_recv < FROZEN_RATIO * span_boot
        if frozen:
            anchors.append(_anchors(rec[i:j].astype(float), boot[i:j]))
            a, b, b_fit = float(seg_recv[0] - boot[i]), 1.0, float("nan")   # the segment starts at its first record
        else:
            anchors.append(_anchors(seg_recv, boot[i:j]))
            a, b, b_fit = _theil_sen(boot[i:j], seg_recv)
        r_k = float(recv[i])
        if k == 0:
            t_start = r_k / b        # t(recv = 0) = 0
        else:
            prev = segments[-1]
            t_start = float(prev.recv_to_t(prev.unstep([rec[i]], [r_k])[0]))   # a clock step persists
            # the receive clock set back across the reboot (or two logs joined): the boot starts where the last ended
            t_start = max(t_start, float(prev.boot_to_t(prev.boot_end_s)))
        segments.append(BootSegment(k, int(rec[i]), r_k, t_start, b, a, float(boot[i]), float(boot[j - 1]), j - i, b_fit,
                                    steps, frozen))
    if any(s.by_record for s in segments):
        return ClockMap(tuple(segments), anchors=tuple(anchors),
                        source="vehicle boot clock (time_boot_ms; the log's receive timestamps do not advance, or advance "
                               f"less than {FROZEN_RATIO:g} s per vehicle second (ms written as us?): records "
                               "without a boot time placed by record order)")
    rates = sorted({round(s.rate, 3) for s in segments})
    return ClockMap(tuple(segments), anchors=tuple(anchors), source=f"vehicle boot clock (time_boot_ms; rate {', '.join(f'{r:g}' for r in rates)} "
                                     "x the receive clock, Theil-Sen fit)")
