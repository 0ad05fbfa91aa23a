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
from .circuit import I1, I2, P_OPEN, S_OPEN, S_SHORT, Circuit, SwitchingConfig
from .result import SwitchingResult
from .schedule import Schedule, duty_windows, make_schedule

__all__ = ["SwitchingLink"]

_GRID = 16           # guard sampling points per rectifier period T (root bracketing)


class SwitchingLink:
    """Event-exact simulator of one link (paper eq. 1) with the SBAR.

    Parameters
    ----------
    params : LinkParams
        Table I values by default.
    cfg : SwitchingConfig
        Capacitors, dead time, battery model, gate phase, dense-output resolution.
    """

    def __init__(self, params: LinkParams, cfg: SwitchingConfig = SwitchingConfig()):
        self.params, self.cfg = params, cfg
        self.cir = cir = Circuit(params, cfg)
        self.T = cir.T
        h = self.T / _GRID
        self._h = h
        self._grid = [np.exp(np.outer(np.arange(_GRID + 2) * h, lam)) for lam in cir.lam]
        m = cir.m
        e = np.eye(m)
        # guard rows (positive while the mode is valid), in modal coordinates per topology
        self._guards = {}
        for k, (p, s) in enumerate(cir.keys):
            sec = []
            if s in (1, -1):
                sec = [s * e[I2]]
            elif s == S_OPEN:
                vo, vop = cir.vout_row(), cir.v2_open_row(p)
                sec = [vo - vop, vo + vop]
            pri = []
            if p in (1, -1):
                pri = [-p * e[I1]]
            elif p == P_OPEN:
                vd, v1o = e[-1] * params.vdc_v, cir.v1_open_row(s)
                pri = [vd - v1o, vd + v1o]
            vec = cir.vec[k]
            self._guards[k] = ({"sec": np.array([g @ vec for g in sec]).reshape(-1, m) if sec else None,
                                "pri": np.array([g @ vec for g in pri]).reshape(-1, m) if pri else None})
        # (topology, gate, inverter command) -> (stacked guard rows or None, number of secondary rows)
        self._guard_table = {}
        for k in range(len(cir.keys)):
            for gate in (0, 1):
                for cmd in (1, -1, 0):
                    gs = self._guards[k]["sec"] if not gate else None
                    gp = self._guards[k]["pri"] if cmd == 0 else None
                    parts = [r for r in (gs, gp) if r is not None]
                    rows = np.vstack(parts) if parts else None
                    # guard values on the bracketing grid: (ge[j] @ z).real = guards at (j+1) h
                    ge = None if rows is None else self._grid[k][1:, None, :] * rows[None, :, :]
                    self._guard_table[(k, gate, cmd)] = (rows, len(gs) if gs is not None else 0, ge)
        self._v2open = {p: cir.v2_open_row(p) for p in (1, -1, P_OPEN)}
        self._v1open = {s: cir.v1_open_row(s) for s in (1, -1, S_SHORT, S_OPEN)}
        self._vout = cir.vout_row()

    # ------------------------------------------------------------------ mode rules
    def _secondary_at_zero(self, x, p):
        """Diode state when i2 = 0 and the gate is off: by the open-circuit voltage."""
        v, vo = x @ self._v2open[p], x @ self._vout
        return 1 if v > vo else (-1 if v < -vo else S_OPEN)

    def _primary_at_zero(self, x, s):
        """Inverter freewheel state when i1 = 0 during dead time."""
        v, vd = x @ self._v1open[s], self.params.vdc_v
        return 1 if v > vd else (-1 if v < -vd else P_OPEN)

    def _modes(self, x, cmd, gate, p, s):
        """Modes after a drive change: the inverter follows its command (in dead time the current
        freewheels through the diodes opposite to its sign), the SBAR shorts while the gate is on,
        else the diode pair of the current's sign conducts; a zero current is decided by the
        open-circuit voltage."""
        if cmd != 0:
            p = cmd
        else:
            p = -1 if x[I1] > 0 else (1 if x[I1] < 0 else None)
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

    # ------------------------------------------------------------------ core loop
    def run(self, schedule: Schedule, x0: np.ndarray) -> SwitchingResult:
        """Integrate exactly over the schedule from augmented state ``x0`` (m,)."""
        cir = self.cir
        lam, vec, inv, trans, grid = cir.lam, cir.vec, cir.inv, cir.trans, self._grid
        guards, h = self._guard_table, self._h
        ecache = {}
        tol = 1e-12 * self.T
        ts, cmds, gates = schedule.t, schedule.cmd, schedule.gate
        x = np.array(x0, dtype=float)
        x[-1] = 1.0
        p = s = None
        # initial modes
        p = int(cmds[0]) if cmds[0] != 0 else (-1 if x[I1] > 0 else (1 if x[I1] < 0 else P_OPEN))
        if gates[0]:
            s = S_SHORT
        else:
            s = 1 if x[I2] > 0 else (-1 if x[I2] < 0 else self._secondary_at_zero(x, p))
        if p == P_OPEN:
            x[I1] = 0.0
        if s == S_OPEN:
            x[I2] = 0.0
        k = cir.index[(p, s)]
        z = inv[k] @ x
        seg_t, seg_k, seg_z = [], [], []
        t = float(ts[0])
        n_int = len(cmds)
        for j in range(n_int):
            t_b = float(ts[j + 1])
            cmd, gate = int(cmds[j]), int(gates[j])
            if j > 0 and (cmd != cmds[j - 1] or gate != gates[j - 1]):
                x = (vec[k] @ z).real
                p2, s2 = self._modes(x, cmd, gate, p, s)
                if (p2, s2) != (p, s):
                    if p2 == P_OPEN or s2 == S_OPEN:
                        if p2 == P_OPEN:
                            x[I1] = 0.0
                        if s2 == S_OPEN:
                            x[I2] = 0.0
                        p, s = p2, s2
                        k = cir.index[(p, s)]
                        z = inv[k] @ x
                    else:
                        p, s = p2, s2
                        k2 = cir.index[(p, s)]
                        z = trans[k][k2] @ z
                        k = k2
            n_same = 0
            t_int = t
            while True:
                seg_t.append(t)
                seg_k.append(k)
                seg_z.append(z)
                tau = t_b - t
                rows, ns, ge = guards[(k, gate, cmd)]
                if n_same == 0 and t == t_int:  # full interval: its exponential repeats, cache it
                    key = (k, round(tau * 1e18))
                    ez = ecache.get(key)
                    if ez is None:
                        ez = ecache[key] = np.exp(lam[k] * tau)
                else:
                    ez = np.exp(lam[k] * tau)
                z_end = z * ez
                if rows is None:
                    z = z_end
                    break
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
                        z = z_end
                        break
                    b = tau
                else:
                    vb = (ge[jh] @ z).real
                    b = (jh + 1) * h
                a = jh * h
                c = rows * z
                va = (c @ grid[k][jh]).real
                best, which = b, -1
                lk = lam[k].tolist()
                for gi in range(len(c)):
                    if vb[gi] <= 0.0:
                        r = _refine(c[gi].tolist(), lk, a, float(va[gi]), b, float(vb[gi]), tol)
                        if r < best or which < 0:
                            best, which = r, gi
                if best <= 1e-13 * self.T:
                    n_same += 1
                    if n_same > 4:  # a mode chatters at one instant: take the open state
                        best = 0.0
                else:
                    n_same = 0
                z = z * np.exp(lam[k] * best)
                t += best
                x = (vec[k] @ z).real
                if which < ns:  # secondary event
                    if s in (1, -1) or n_same > 4:
                        x[I2] = 0.0
                        s = self._secondary_at_zero(x, p) if n_same <= 4 else S_OPEN
                    else:  # blocked interval ends
                        s = 1 if (x @ self._v2open[p]) > 0 else -1
                    if s == S_OPEN:
                        x[I2] = 0.0
                else:
                    if p in (1, -1) or n_same > 4:
                        x[I1] = 0.0
                        p = self._primary_at_zero(x, s) if n_same <= 4 else P_OPEN
                    else:
                        p = 1 if (x @ self._v1open[s]) > 0 else -1
                    if p == P_OPEN:
                        x[I1] = 0.0
                k = cir.index[(p, s)]
                z = inv[k] @ x
                if t >= t_b:
                    break
            t = t_b
        seg_t.append(t)
        return SwitchingResult(cir, schedule, np.array(seg_t), np.array(seg_k, dtype=int), np.array(seg_z))

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
        bad = ~np.isfinite(d) | (d < 0) | (d > 1)
        if bad.any():
            raise ValueError(f"d_short={d[bad][0]!r} is out of range; valid range: [0, 1]")
        cp = self.T if control_period_s is None else float(control_period_s)
        t_end = len(d) * cp if t_end_s is None else float(t_end_s)
        if x0 is None:
            x0 = self.periodic_steady_state(d[0], phase_rad)
        return self.run(self.schedule(0.0, t_end, d, cp, phase_rad), x0)


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
