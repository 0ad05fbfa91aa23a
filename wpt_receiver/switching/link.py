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

import cmath
import math

import numpy as np

from ..envelope import steady_state
from ..params import LinkParams
from ..sbar import v2_from_duty
from .circuit import I1, I2, P_OPEN, PRIMARY, S_OPEN, S_SHORT, SECONDARY, Circuit, SwitchingConfig
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
        Run the event loop compiled with numba (:mod:`.compiled`, the default when numba is
        installed) or in pure Python/numpy (``False``: the reference the compiled loop is tested
        against). numba is imported, and the loop compiled or loaded from numba's disk cache, on
        the first :meth:`run`, never on import.
    """

    def __init__(self, params: LinkParams, cfg: SwitchingConfig = SwitchingConfig(), compiled: bool | None = None):
        self.params, self.cfg = params, cfg
        self.compiled = _numba_available() if compiled is None else bool(compiled)
        self._packed = None
        self.cir = cir = Circuit(params, cfg)
        self.T = cir.T
        self._h = self.T / _GRID
        self._grid = [np.exp(np.outer(np.arange(_GRID + 2) * self._h, lam)) for lam in cir.lam]
        self._guard_table = self._build_guards()
        self._v2open = {p: cir.v2_open_row(p) for p in PRIMARY}
        self._v1open = {s: cir.v1_open_row(s) for s in SECONDARY}
        self._sec_th = cir.rect_threshold_row()
        self._pri_th = cir.inverter_threshold_v

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
        """(topology, gate, inverter command) -> (modal guard rows or None, number of secondary
        rows, guard rows times the bracketing grid's exponentials)."""
        cir, table = self.cir, {}
        for k, (p, s) in enumerate(cir.keys):
            sec, pri = self._guard_rows(p, s)
            for gate in (0, 1):
                for cmd in (1, -1, 0):
                    parts = (sec if not gate else []) + (pri if cmd == 0 else [])
                    rows = np.array([g @ cir.vec[k] for g in parts]) if parts else None
                    # guard values on the bracketing grid: (ge[j] @ z).real = guards at (j+1) h
                    ge = None if rows is None else self._grid[k][1:, None, :] * rows[None, :, :]
                    table[(k, gate, cmd)] = (rows, len(sec) if not gate else 0, ge)
        return table

    # ------------------------------------------------------------------ mode rules
    def _secondary_at_zero(self, x, p):
        """Diode state when i2 = 0 and the gate is off: by the open-circuit voltage against the
        output voltage plus the forward drops."""
        v, th = x @ self._v2open[p], x @ self._sec_th
        return 1 if v > th else (-1 if v < -th else S_OPEN)

    def _primary_at_zero(self, x, s):
        """Inverter freewheel state when i1 = 0 during dead time (+-2 = freewheeling)."""
        v, th = x @ self._v1open[s], self._pri_th
        return 2 if v > th else (-2 if v < -th else P_OPEN)

    def _modes(self, x, cmd, gate, p=None, s=None):
        """Modes after a drive change: the inverter follows its command (in dead time the current
        freewheels through the diodes opposite to its sign), the SBAR shorts while the gate is on,
        else the diode pair of the current's sign conducts; a zero current is decided by the
        open-circuit voltage."""
        if cmd != 0:
            p = cmd
        else:
            p = -2 if x[I1] > 0 else (2 if x[I1] < 0 else None)
        if gate:
            s = S_SHORT
        elif x[I2] > 0:
            s = 1
        elif x[I2] < 0:
            s = -1
        else:
            s = self._secondary_at_zero(x, p if p is not None else P_OPEN)
        if p is None:
            p = self._primary_at_zero(x, s)
        return p, s

    def _after_event(self, x, secondary: bool, p, s, chatter: bool):
        """New modes after a guard event (``x`` is modified: a current that stops is set to 0).
        ``chatter``: several zero-length events in a row; take the blocked state."""
        if secondary:
            if s in (1, -1) or chatter:
                x[I2] = 0.0
                s = S_OPEN if chatter else self._secondary_at_zero(x, p)
            else:  # blocked interval ends
                s = 1 if (x @ self._v2open[p]) > 0 else -1
            if s == S_OPEN:
                x[I2] = 0.0
        else:
            if p in (2, -2) or chatter:
                x[I1] = 0.0
                p = P_OPEN if chatter else self._primary_at_zero(x, s)
            else:
                p = 2 if (x @ self._v1open[s]) > 0 else -2
            if p == P_OPEN:
                x[I1] = 0.0
        return p, s

    # ------------------------------------------------------------------ core loop
    def run(self, schedule: Schedule, x0: np.ndarray) -> SwitchingResult:
        """Integrate exactly over the schedule from augmented state ``x0`` (m,): compiled when
        :attr:`compiled`, else the pure-Python reference :meth:`run_reference`."""
        if self.compiled:
            return self._run_compiled(schedule, x0)
        return self.run_reference(schedule, x0)

    def _run_compiled(self, schedule: Schedule, x0: np.ndarray) -> SwitchingResult:
        """The same loop compiled with numba (:func:`.compiled.run_kernel`); when the model gets
        stuck on zero-length events the reference path re-runs to raise its error."""
        from .compiled import FULL, STUCK, pack, run_kernel  # numba: imported on the first compiled run only
        if self._packed is None:
            self._packed = pack(self)
        a = self._packed
        ts = np.ascontiguousarray(schedule.t, dtype=float)
        cmds = np.ascontiguousarray(schedule.cmd, dtype=np.int64)
        gates = np.ascontiguousarray(schedule.gate, dtype=np.int64)
        x = np.array(x0, dtype=float)
        cap = 4 * len(cmds) + 16
        while True:
            status, n, seg_t, seg_k, seg_z = run_kernel(
                ts, cmds, gates, x, a["lam"], a["vec"], a["inv"], a["trans"], a["grid"], a["grows"], a["gnum"],
                a["gsec"], a["v2open"], a["v1open"], a["sec_th"], a["pri_th"], a["h"], a["T"], cap, _MAX_ZERO_EVENTS)
            if status != FULL:
                break
            cap *= 4
        if status == STUCK:
            return self.run_reference(schedule, x0)
        return SwitchingResult(self.cir, schedule, seg_t[:n + 1].copy(), seg_k[:n].copy(), seg_z[:n].copy())

    def run_reference(self, schedule: Schedule, x0: np.ndarray) -> SwitchingResult:
        """The event loop in pure Python/numpy (the reference of the compiled loop)."""
        cir = self.cir
        ts, cmds, gates = schedule.t, schedule.cmd, schedule.gate
        x = np.array(x0, dtype=float)
        x[-1] = 1.0
        p, s = self._modes(x, int(cmds[0]), int(gates[0]))
        _zero_open(x, p, s)
        k = cir.index[(p, s)]
        z = cir.inv[k] @ x
        seg = ([], [], [])
        ecache = {}
        t = float(ts[0])
        for j in range(len(cmds)):
            cmd, gate = int(cmds[j]), int(gates[j])
            if j > 0 and (cmd != cmds[j - 1] or gate != gates[j - 1]):
                k, z, p, s = self._drive_change(k, z, p, s, cmd, gate)
            k, z, p, s = self._interval(t, float(ts[j + 1]), k, z, p, s, cmd, gate, seg, ecache)
            t = float(ts[j + 1])
        seg[0].append(t)
        return SwitchingResult(cir, schedule, np.array(seg[0]), np.array(seg[1], dtype=int), np.array(seg[2]))

    def _drive_change(self, k, z, p, s, cmd, gate):
        """Modes at a scheduled drive change; the state carries over (a blocked current is 0)."""
        cir = self.cir
        x = (cir.vec[k] @ z).real
        p2, s2 = self._modes(x, cmd, gate, p, s)
        if (p2, s2) == (p, s):
            return k, z, p, s
        k2 = cir.index[(p2, s2)]
        if p2 == P_OPEN or s2 == S_OPEN:
            _zero_open(x, p2, s2)
            return k2, cir.inv[k2] @ x, p2, s2
        return k2, cir.trans[k][k2] @ z, p2, s2

    def _interval(self, t, t_b, k, z, p, s, cmd, gate, seg, ecache):
        """Advance from ``t`` to the next scheduled edge ``t_b`` through the state events (diode
        commutations, end of blocked intervals); appends the segments to ``seg``. Raises
        ``ArithmeticError`` rather than looping on zero-length events."""
        cir, lam, T = self.cir, self.cir.lam, self.T
        n_zero, first = 0, True
        while True:
            seg[0].append(t)
            seg[1].append(k)
            seg[2].append(z)
            tau = t_b - t
            ez = _exp_cached(ecache, k, lam[k], tau) if first else np.exp(lam[k] * tau)
            first = False
            rows, ns, ge = self._guard_table[(k, gate, cmd)]
            hit = None if rows is None else _first_event(z, z * ez, rows, ge, self._grid[k], lam[k], self._h, tau,
                                                         1e-12 * T)
            if hit is None:
                return k, z * ez, p, s
            dt, which = hit
            n_zero = n_zero + 1 if dt <= 1e-13 * T else 0
            if n_zero > _MAX_ZERO_EVENTS:
                raise ArithmeticError(
                    f"switching model stuck: {n_zero} zero-length events at t={t!r} s in topology {cir.keys[k]} "
                    f"(cmd={cmd}, gate={gate}); state {(cir.vec[k] @ z).real.tolist()}")
            z = z * np.exp(lam[k] * dt)
            t += dt
            x = (cir.vec[k] @ z).real
            p, s = self._after_event(x, which < ns, p, s, n_zero > 4)
            k = cir.index[(p, s)]
            z = cir.inv[k] @ x
            if t >= t_b:
                return k, z, p, s

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


def _numba_available() -> bool:
    """numba installed? (found without importing it: the import costs ~0.3 s)."""
    import importlib.util
    return importlib.util.find_spec("numba") is not None


def _zero_open(x, p, s):
    """Blocked inverter / SBAR carry no current: zero it in the state ``x`` (in place)."""
    if p == P_OPEN:
        x[I1] = 0.0
    if s == S_OPEN:
        x[I2] = 0.0


def _exp_cached(cache, k, lam, tau):
    """``exp(lam tau)`` for a whole drive interval: the same durations repeat every period."""
    key = (k, round(tau * 1e18))
    ez = cache.get(key)
    if ez is None:
        ez = cache[key] = np.exp(lam * tau)
    return ez


def _first_event(z, z_end, rows, ge, grid, lam, h, tau, tol):
    """First guard crossing in ``(0, tau]`` for modal state ``z``: ``(dt, guard index)`` or None.

    ``rows`` (ng, m) modal guard rows, ``ge`` (G, ng, m) the rows times the grid exponentials
    (guard values at ``(j+1) h``), ``grid`` (G+1, m) the exponentials at ``j h``. The first grid
    step where a guard is <= 0 brackets the root, refined by :func:`_refine`. Pure function of
    arrays (no state)."""
    ng = len(rows)
    nj = int(tau / h)
    jh = nj
    if nj > 0:
        bad = ((ge[:nj] @ z).real <= 0.0).ravel()
        i = int(bad.argmax())
        if bad[i]:
            jh = i // ng
    if jh == nj:
        vb = (rows @ z_end).real
        if not (vb <= 0.0).any():
            return None
        b = tau
    else:
        vb = (ge[jh] @ z).real
        b = (jh + 1) * h
    a = jh * h
    c = rows * z
    va = (c @ grid[jh]).real
    best, which = b, -1
    lk = lam.tolist()
    for gi in range(ng):
        if vb[gi] <= 0.0:
            r = _refine(c[gi].tolist(), lk, a, float(va[gi]), b, float(vb[gi]), tol)
            if r < best or which < 0:
                best, which = r, gi
    return best, which


def _refine(c, lam, a, ga, b, gb, tol):
    """Root of ``g(t) = Re(sum c exp(lam t))`` in ``[a, b]`` with ``g(a) > 0 >= g(b)``:
    Newton on the exact solution, safeguarded by bisection (plain complex scalars: faster than
    numpy for 5-6 modes)."""
    if ga <= 0.0:
        return a
    exp = cmath.exp
    cl = [ci * li for ci, li in zip(c, lam)]
    t = a + (b - a) * ga / (ga - gb)
    for _ in range(60):
        g = dg = 0j
        for ci, cli, li in zip(c, cl, lam):
            e = exp(li * t)
            g += ci * e
            dg += cli * e
        g, dg = g.real, dg.real
        if g > 0:
            a = t
        else:
            b = t
        tn = t - g / dg if dg != 0 else 0.5 * (a + b)
        if not (a < tn < b):
            tn = 0.5 * (a + b)
        if abs(tn - t) <= tol or b - a <= tol:
            return t
        t = tn
    return b


# ============================================================================ SBAR relation
