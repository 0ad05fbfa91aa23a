"""Switching-level (instantaneous) simulation of the link and the SBAR, event-exact.

The circuit (eq. 1, see :mod:`.circuit`) is linear in each topology, so between
switching events the solution is a matrix exponential: every topology is diagonalised once and
the state is advanced *exactly* over any duration in modal coordinates. Events:

* scheduled: inverter commutations at ``k T`` (optional dead time), and the SBAR gate edges.
  The gate comes from the controller's own clock: the short window of rectifier period ``n`` is
  centred at ``n T + gate_phase_rad / omega`` and lasts ``d_short[n] T`` (``T`` = half the
  inverter period). Phase 0 centres it on the peak of the i2 fundamental (``i2 ~ cos wt``), the
  place eq. 9 assumes; :func:`sbar_relation` can instead centre it on the actual half-cycle.
* state events: diode commutations at the zero crossings of i2 (i1 in dead time) and the end of
  a blocked interval (open-circuit voltage reaching the DC voltage). They are located on a
  coarse grid of the exact solution (precomputed exponentials per topology) and refined by a
  safeguarded Newton iteration on the exact solution.

Outputs (:class:`~.result.SwitchingResult`) are exact dense samples (a pandas
DataFrame), the per-half-cycle envelope (peak of |i1| and |i2| in each half cycle, fundamental of
i2 and v2, mean battery current) and closed-form energy integrals. :func:`~.ivp.simulate_ivp`
integrates the same circuit with ``scipy.integrate.solve_ivp`` as a slow reference.
"""

from __future__ import annotations

import math

import numpy as np

from ..envelope import steady_state
from ..params import LinkParams
from ..sbar import v2_from_duty
from .circuit import I1, I2, P_OPEN, S_OPEN, Circuit, SwitchingConfig
from .result import SwitchingResult
from .schedule import Schedule, duty_windows, make_schedule

__all__ = ["SwitchingLink"]

_GRID = 16           # guard sampling points per rectifier period T (root bracketing)
_ITOL_A = 1e-9       # current guards: a current within 1 nA of zero does not end its mode
_VTOL_V = 1e-9       # voltage guards: a blocked voltage within 1 nV of its threshold stays blocked
_MAX_ZERO_EVENTS = 50  # consecutive zero-length events before the model gives up (never hangs)


class SwitchingLink:
    """Event-exact simulator of one link (paper eq. 1) with the SBAR and its devices.

    Parameters
    ----------
    params : LinkParams
        Table I values by default.
    cfg : SwitchingConfig
        Capacitors, dead time, battery model, gate phase, dense-output resolution, devices.
    compiled : bool or None
        Run the event loop (:mod:`.compiled`, its one source) compiled with numba (``None`` or ``True``,
        the default) or the same source run by the interpreter (``False``: slow, for tests). numba is
        imported, and the loop compiled or loaded from numba's disk cache, on the first :meth:`run`,
        never on import.
    """

    def __init__(self, params: LinkParams, cfg: SwitchingConfig = SwitchingConfig(), compiled: bool | None = None):
        self.params, self.cfg = params, cfg
        self.compiled = True if compiled is None else bool(compiled)
        self._packed = None
        self.cir = cir = Circuit(params, cfg)
        self.T = cir.T
        self._h = self.T / _GRID
        self._grid = [np.exp(np.outer(np.arange(_GRID + 2) * self._h, lam)) for lam in cir.lam]
        self._guard_table = self._build_guards()

    def _guard_rows(self, p, s):
        """Guard rows over the augmented state (positive while the mode is valid), shifted by a
        tolerance so that a guard sitting at exactly zero (a current that stays 0, a blocked
        voltage exactly at its threshold) is a valid mode, not an event at every instant."""
        cir, e = self.cir, np.eye(self.cir.m)
        sec, pri = [], []
        if s in (1, -1):
            sec = [s * e[I2] + _ITOL_A * e[-1]]
        elif s == S_OPEN:
            th, vop = cir.rect_threshold_row(), cir.v2_open_row(p)
            sec = [th - vop + _VTOL_V * e[-1], th + vop + _VTOL_V * e[-1]]
        if p in (2, -2):
            pri = [-0.5 * p * e[I1] + _ITOL_A * e[-1]]
        elif p == P_OPEN:
            vd, v1o = e[-1] * (cir.inverter_threshold_v + _VTOL_V), cir.v1_open_row(s)
            pri = [vd - v1o, vd + v1o]
        return sec, pri

    def _build_guards(self):
        """(topology, gate, inverter command) -> (modal guard rows or None, number of secondary rows)."""
        cir, table = self.cir, {}
        for k, (p, s) in enumerate(cir.keys):
            sec, pri = self._guard_rows(p, s)
            for gate in (0, 1):
                for cmd in (1, -1, 0):
                    parts = (sec if not gate else []) + (pri if cmd == 0 else [])
                    rows = np.array([g @ cir.vec[k] for g in parts]) if parts else None
                    table[(k, gate, cmd)] = (rows, len(sec) if not gate else 0)
        return table

    # ------------------------------------------------------------------ core loop
    def run(self, schedule: Schedule, x0: np.ndarray) -> SwitchingResult:
        """Integrate exactly over the schedule from augmented state ``x0`` (m,) with the event loop of
        :mod:`.compiled` (:func:`~.compiled.run_kernel`, the one source of the mode rules, the event search and
        the stepping): compiled when :attr:`compiled`, else the same source run by the interpreter (its
        ``py_func``; the functions it calls are looked up in the module at each call, so a test may swap them).
        Raises ``ArithmeticError`` rather than looping on zero-length events."""
        from .compiled import FULL, STUCK, pack, run_kernel  # numba: imported on the first run only
        if self._packed is None:
            self._packed = pack(self)
        a = self._packed
        ts = np.ascontiguousarray(schedule.t, dtype=float)
        cmds = np.ascontiguousarray(schedule.cmd, dtype=np.int64)
        gates = np.ascontiguousarray(schedule.gate, dtype=np.int64)
        x = np.array(x0, dtype=float)
        loop = run_kernel if self.compiled else getattr(run_kernel, "py_func", run_kernel)
        cap = 4 * len(cmds) + 16
        while True:
            status, n, seg_t, seg_k, seg_z, j = loop(
                ts, cmds, gates, x, a["lam"], a["vec"], a["inv"], a["trans"], a["grid"], a["grows"], a["gnum"],
                a["gsec"], a["v2open"], a["v1open"], a["sec_th"], a["pri_th"], a["h"], a["T"], cap, _MAX_ZERO_EVENTS)
            if status != FULL:
                break
            cap *= 4
        if status == STUCK:
            t, k = float(seg_t[n - 1]), int(seg_k[n - 1])   # (j: the kernel's interval; repeated times are several)
            state = (self.cir.vec[k] @ seg_z[n - 1]).real
            raise ArithmeticError(
                f"switching model stuck: more than {_MAX_ZERO_EVENTS} zero-length events at t={t!r} s in topology "
                f"{self.cir.keys[k]} (cmd={int(cmds[j])}, gate={int(gates[j])}); state {state.tolist()}")
        return SwitchingResult(self.cir, schedule, seg_t[:n + 1].copy(), seg_k[:n].copy(), seg_z[:n].copy())

    # ------------------------------------------------------------------ convenience
    def final_state(self, res: SwitchingResult) -> np.ndarray:
        k = res.seg_k[-1]
        z = res.seg_z[-1] * np.exp(self.cir.lam[k] * (res.seg_t[-1] - res.seg_t[-2]))
        return (self.cir.vec[k] @ z).real

    def schedule(self, t0_s, t_end_s, d_short, control_period_s=None, phase_rad=None) -> Schedule:
        """Schedule for a duty per control period (scalar = constant duty)."""
        T = self.T
        phase = self.cfg.gate_phase_rad if phase_rad is None else float(phase_rad)
        if not math.isfinite(phase):
            raise ValueError(f"phase_rad={phase_rad!r} is invalid; valid range: finite (radians at f)")
        if control_period_s is not None and not (math.isfinite(control_period_s) and control_period_s > 0):
            raise ValueError(f"control_period_s={control_period_s!r} is invalid; valid range: (0, inf)")
        w = self.params.omega_rad_s
        if np.ndim(d_short) == 0:
            dval = float(d_short)
            fn = lambda n: np.full(np.shape(n), dval)  # noqa: E731
        else:
            fn = duty_windows(d_short, control_period_s or T, T, phase, w)
        return make_schedule(t0_s, t_end_s, T, fn, phase, self.cfg.dead_time_s, w)

    def periodic_steady_state(self, d_short: float, phase_rad=None, iters: int = 6, tol: float = 1e-11):
        """Periodic steady state at t = 0 (mod 2T) for a constant duty: Newton shooting on the
        one-inverter-period map (finite-difference Jacobian), started from the phasor solution
        of the envelope model with V2 = f(d)."""
        P = self.params
        i1, i2 = steady_state(P, v2_from_duty(float(np.clip(d_short, 0, 1)), P.vl_v))
        x = self.cir.phasor_state(float(i1), float(i2))
        sch = self.schedule(0.0, 2 * self.T, float(d_short), phase_rad=phase_rad)
        n = self.cir.n
        scale = np.abs(x[:n]) + 1.0

        def pmap(xx):
            return self.final_state(self.run(sch, xx))[:n]
        for _ in range(iters):
            fx = pmap(x)
            r = fx - x[:n]
            if np.max(np.abs(r) / scale) < tol:
                break
            jac = np.empty((n, n))
            for i in range(n):
                dx = x.copy()
                eps = 1e-7 * scale[i]
                dx[i] += eps
                jac[:, i] = (pmap(dx) - fx) / eps
            x[:n] = x[:n] - np.linalg.solve(jac - np.eye(n), r)
        return x

    def simulate(self, d_short, control_period_s=None, t_end_s=None, phase_rad=None, x0=None) -> SwitchingResult:
        """Run a duty sequence (one duty per control period) from t = 0, starting at the periodic
        steady state of the first duty unless ``x0`` is given."""
        d = np.atleast_1d(np.asarray(d_short, dtype=float))
        if d.ndim != 1 or len(d) == 0:   # an empty sequence raised IndexError
            raise ValueError(f"d_short has shape {d.shape}; valid: a non-empty 1-D sequence of duties in [0, 1]")
        bad = ~np.isfinite(d) | (d < 0) | (d > 1)
        if bad.any():
            raise ValueError(f"d_short={float(d[bad][0])!r} is out of range; valid range: [0, 1]")
        cp = self.T if control_period_s is None else float(control_period_s)
        t_end = len(d) * cp if t_end_s is None else float(t_end_s)
        if not (math.isfinite(t_end) and t_end > 0):   # a negative one raised IndexError deep in the result
            raise ValueError(f"t_end_s={t_end_s!r} is invalid; valid range: (0, inf) s")
        if x0 is not None and np.shape(x0) != (self.cir.m,):
            raise ValueError(f"x0 has shape {np.shape(x0)}; valid: ({self.cir.m},), the circuit's state "
                             "(SwitchingLink.periodic_steady_state gives one)")
        if x0 is None:
            x0 = self.periodic_steady_state(d[0], phase_rad)
        return self.run(self.schedule(0.0, t_end, d, cp, phase_rad), x0)
