"""The mission loop's per-sample arrays, produced in chunks of trajectory samples as the loop advances.

Per trajectory sample the loop needs its time ``t_s``, Lm (nearest pad, coupling table), the coupling
``k``, the propulsion power and whether the pad may energise (an energising phase of a charged run),
and, for the stored rows, the pose and phase. :class:`MissionSamples` computes them for samples
``[k0, k1)`` (:meth:`MissionSamples.chunk`) from the trajectory's samples ``[k0 - 1, k1 + 1)`` (the
velocity is a central difference): the same numbers, sample for sample, as computing them for all
samples at once (:func:`gradient_rows` is ``numpy.gradient``'s arithmetic with the whole
trajectory's spacing decision), so the compiled loop runs a 50 h mission through chunks of
:data:`SAMPLE_CHUNK` samples with nothing of the mission's length in memory
(:class:`~.trajectory.PlannedTrajectory` generates its samples in blocks too).

The nearest-pad search (:func:`pad_offsets`) and Lm along samples (:func:`lm_along`) live here;
:mod:`.runner` re-exports the latter under its old name ``_lm_along``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .trajectory import propulsion_from

__all__ = ["MissionSamples", "SampleChunk", "SAMPLE_CHUNK", "ENERGISE_PHASES", "gradient_rows", "pad_offsets",
           "near_pad", "lm_along"]

#: trajectory samples per chunk of per-sample arrays (~5 MB of them; the planning temporaries of a block, ~300 B a sample, dominate)
SAMPLE_CHUNK = 1 << 16
ENERGISE_PHASES = ("charge", "hover")


@dataclass
class SampleChunk:
    """Per-sample arrays of samples ``[k0, k0 + len)``: times [s], Lm [H], coupling k [-], propulsion
    power [W], eligibility (1.0: energising phase of a charged run), pose (n, 3) [m], phase names."""

    k0: int
    t_s: np.ndarray
    lm_h: np.ndarray
    k: np.ndarray
    p_w: np.ndarray
    elig: np.ndarray
    pos_m: np.ndarray
    phase: np.ndarray

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def arrays(self) -> tuple:
        """``(t, lm, k, p, elig)`` contiguous float64: the compiled kernel's per-sample arrays."""
        return tuple(np.ascontiguousarray(x, dtype=float) for x in (self.t_s, self.lm_h, self.k, self.p_w, self.elig))


def uniform_spacing(t_s) -> bool:
    """``numpy.gradient``'s test on sample times: all steps bitwise equal (then it uses the
    uniform-grid formula)."""
    d = np.diff(np.asarray(t_s, dtype=float))
    return bool(len(d) == 0 or (d == d[0]).all())


def gradient_rows(f, t_s, uniform: bool) -> np.ndarray:
    """``numpy.gradient(f, t_s, axis=0)`` (edge order 1) with the spacing decision ``uniform`` taken
    for the whole series (:func:`uniform_spacing`), so a window of it gives the whole series' numbers
    at the window's interior rows (and at its ends where they are the series' ends)."""
    f = np.asarray(f, dtype=float)
    dx = np.diff(np.asarray(t_s, dtype=float))
    out = np.empty_like(f)
    if uniform:
        h = dx[0]
        out[1:-1] = (f[2:] - f[:-2]) / (2.0 * h)
        out[0], out[-1] = (f[1] - f[0]) / h, (f[-1] - f[-2]) / h
        return out
    dx1, dx2 = dx[:-1], dx[1:]
    shape = (-1,) + (1,) * (f.ndim - 1)
    a = (-dx2 / (dx1 * (dx1 + dx2))).reshape(shape)
    b = ((dx2 - dx1) / (dx1 * dx2)).reshape(shape)
    c = (dx1 / (dx2 * (dx1 + dx2))).reshape(shape)
    out[1:-1] = a * f[:-2] + b * f[1:-1] + c * f[2:]
    out[0], out[-1] = (f[1] - f[0]) / dx[0], (f[-1] - f[-2]) / dx[-1]
    return out


def pad_offsets(cfg, pos_m):
    """Offsets (N, 3) of the receiver at ``pos_m`` (N, 3) from the nearest pad (horizontally) and that
    pad's index (the first of equally near ones). Pads at the same place (a route flown again) are
    searched once, and the samples in chunks, so memory stays ~32 MB whatever the number of samples
    and pads."""
    pads = np.array([[p.x_m, p.y_m, p.z_m] for p in cfg.pads])
    _, first = np.unique(pads[:, :2], axis=0, return_index=True)
    first.sort()  # distinct places in the order of their first pad: argmin's tie-break is unchanged
    cand = pads[first, :2]
    step = max(1, (1 << 21) // len(cand))
    idx = np.empty(len(pos_m), dtype=np.int64)
    for a in range(0, len(pos_m), step):
        d = pos_m[a:a + step, None, :2] - cand[None, :, :]
        idx[a:a + step] = first[np.argmin(np.einsum("nkj,nkj->nk", d, d), axis=1)]
    return pos_m - pads[idx], idx


def near_pad(model, off) -> np.ndarray:
    """Which receivers at offsets ``off`` (N, 3) from their nearest pad (:func:`pad_offsets`) are inside the
    coupling table's range (``model.table_range_m``): the only poses with Lm > 0 (:func:`lm_along`), so the only
    ones a pad energises (in :data:`ENERGISE_PHASES`). One rule for the run and for
    :func:`mission_sim.setup_warnings.energised_pads`."""
    off = np.asarray(off, dtype=float).reshape(-1, 3)
    rho_max, z_min, z_max = model.table_range_m
    return (np.hypot(off[:, 0], off[:, 1]) < rho_max) & (off[:, 2] < z_max) & (off[:, 2] > 0.5 * z_min)


def lm_along(cfg, model, traj, compiled: bool = False):
    """Lm [H] per sample of ``traj`` (a :class:`~.trajectory.Trajectory` or a chunk of one; 0 away from
    the pads) and the nearest pad's index; the coupling table is always evaluated compiled
    (:mod:`wpt_receiver.coupling_kernel`, its one implementation; ``compiled`` is passed on and ignored)."""
    off, idx = pad_offsets(cfg, traj.pos_m)
    lm = np.zeros(len(traj.pos_m))
    near = near_pad(model, off)
    if np.any(near):
        lm[near] = model.lm_h(off[near, 0], off[near, 1], off[near, 2], traj.tilt_rad[near],
                              tilt_axis_rad=traj.tilt_axis_rad[near], compiled=compiled)
    return lm, idx


class MissionSamples:
    """The per-sample arrays of one run over ``traj`` (a :class:`~.trajectory.Trajectory` or a
    :class:`~.trajectory.PlannedTrajectory`), chunk by chunk.

    ``lm_h``: None computes Lm per chunk (:func:`lm_along`); an array (one per sample) or a number
    (e.g. 0.0 for a run whose pads never energise: Lm does not enter it) is used as given. The last
    chunk is kept, so :meth:`pose` of the rows just produced costs nothing."""

    def __init__(self, cfg, traj, charge: bool, lm_h=None):
        self.cfg, self.traj, self.charge, self.lm_given = cfg, traj, bool(charge), lm_h
        self.model = cfg.coupling.model()
        self.inv_sqrt_l1l2 = 1.0 / math.sqrt(self.model.l1_h * self.model.l2_h)
        self.n = len(traj)
        self.uniform = getattr(traj, "uniform_spacing", None)
        if self.uniform is None:
            self.uniform = uniform_spacing(traj.t_s)
        self.last: SampleChunk | None = None
        #: the route's :class:`~.trajectory.MassSchedule` when the mass flown changes on the way (a planned route's
        #: payload release), else None: every sample flies ``drone.total_mass_kg`` (a replay's trajectory too)
        sched = getattr(traj, "mass", None)
        if sched is not None:
            sched.check_drone(cfg.drone)   # (one source: the run's drone; a trajectory planned for other masses refused)
        self.schedule = sched if sched is not None and sched.changes else None
        self.mass_changes = self.schedule is not None

    def mass_kg(self, t_s) -> np.ndarray:
        """The total mass [kg] flown at the sample times ``t_s``."""
        if self.mass_changes:
            return self.schedule.at(t_s)
        return np.full(np.shape(t_s), float(self.cfg.drone.total_mass_kg))

    def row_mass_kg(self, rows_k, end_s, dt_s) -> np.ndarray:
        """The total mass [kg] each row flew: rows ``rows_k`` (the global index of each step's first sample), steps
        ``[end_s - dt_s, end_s]``. The mass of the row's first sample, but for a step holding a payload release inside
        it (a quiet-flight step merging samples across the drop): there the mean over the step of the samples' masses,
        each held over its sample period as the loop holds its power (:meth:`chunk`), so weighted by time as the
        row's energy columns are and the summary's ``propulsion_energy_before_release_j`` / ``_after_release_j`` split
        it (that row's mass had been its first sample's, the take-off mass, over a step mostly flown lighter)."""
        if not self.mass_changes:
            return np.full(len(np.asarray(rows_k)), float(self.cfg.drone.total_mass_kg))
        sched = self.schedule
        out = sched.at_samples(rows_k).astype(float)
        end = np.asarray(end_s, dtype=float)
        start = end - np.asarray(dt_s, dtype=float)
        dt = sched.dt_s
        last = sched.at_samples(np.maximum(np.ceil(end / dt - 1e-9).astype(np.int64) - 1, 0))   # the step's last sample
        for j in np.flatnonzero(last != out):   # (the samples' masses differ within the step: a drop inside it)
            k = np.arange(max(int(math.floor(start[j] / dt)) - 1, 0), int(math.ceil(end[j] / dt)) + 1)
            t_k = k * dt
            held = np.maximum(np.minimum(t_k + dt, end[j]) - np.maximum(t_k, start[j]), 0.0)
            out[j] = float(np.dot(held, sched.at(t_k)) / held.sum())
        return out

    @property
    def t_first_s(self) -> float:
        return self.traj.t_start_s

    @property
    def t_last_s(self) -> float:
        return self.traj.t_end_s

    def chunk(self, k0: int, k1: int) -> SampleChunk:
        """The arrays of samples ``[k0, min(k1, n))``."""
        k0, k1 = int(k0), min(int(k1), self.n)
        a, b = max(k0 - 1, 0), min(k1 + 1, self.n)
        win = self.traj.chunk(a, b)
        vel = gradient_rows(win.pos_m, win.t_s, self.uniform)[k0 - a:k0 - a + k1 - k0]
        tr = self.traj.chunk(k0, k1) if (a, b) != (k0, k1) else win
        p_w = np.asarray(propulsion_from(self.cfg.drone, vel, tr.wind_m_s, tr.phase,
                                         getattr(self.traj, "motors_off_phases", ()),
                                         self.mass_kg(tr.t_s) if self.mass_changes else None),
                         dtype=float).reshape(-1)
        if self.lm_given is None:
            lm = lm_along(self.cfg, self.model, tr)[0]
        elif np.ndim(self.lm_given):
            lm = np.asarray(self.lm_given, dtype=float)[k0:k1]
        else:
            lm = np.full(k1 - k0, float(self.lm_given))
        elig = (np.isin(tr.phase, ENERGISE_PHASES) & self.charge).astype(float)
        self.last = SampleChunk(k0, tr.t_s, lm, lm * self.inv_sqrt_l1l2, p_w, elig, tr.pos_m, tr.phase)
        return self.last

    def pose(self, rows_k):
        """Positions (n, 3) [m] and phase names of the samples ``rows_k`` (global indices)."""
        ri = np.asarray(rows_k, dtype=np.int64)
        c = self.last
        if len(ri) and (c is None or ri.min() < c.k0 or ri.max() >= c.k0 + len(c)):
            tr = self.traj.chunk(int(ri.min()), int(ri.max()) + 1)
            return tr.pos_m[ri - ri.min()], tr.phase[ri - ri.min()]
        k0 = c.k0 if c is not None else 0
        return (c.pos_m[ri - k0], c.phase[ri - k0]) if c is not None else (np.zeros((0, 3)), np.zeros(0, object))
