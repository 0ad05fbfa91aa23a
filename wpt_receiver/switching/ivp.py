"""Slow reference for the switching-level model: the same circuit by ``scipy.integrate.solve_ivp``."""

from __future__ import annotations

import numpy as np

from ..params import LinkParams
from .circuit import I1, I2, P_OPEN, S_OPEN, S_SHORT, Circuit, SwitchingConfig
from .schedule import Schedule

__all__ = ["simulate_ivp"]


def simulate_ivp(params: LinkParams, cfg: SwitchingConfig, schedule: Schedule, x0, rtol: float = 1e-10,
                 atol: float = 1e-10, method: str | None = None, t_eval=None):
    """Slow reference: the same circuit (written directly from eq. 1, not from the topology
    matrices) integrated by ``scipy.integrate.solve_ivp`` between events; diode commutations
    are terminal events. Returns ``(t, x)`` with x (N, n) at ``t_eval`` (default: the ends).

    ``method`` defaults to DOP853, or Radau when the smoothing capacitor makes the system stiff
    (``r_bat_ohm * c_out_f < T / 10``): an explicit method then loses accuracy on the fast mode."""
    from scipy.integrate import solve_ivp

    from .link import SwitchingLink  # mode decisions (diode / freewheel rules) are shared
    cir = Circuit(params, cfg)
    if method is None:
        stiff = cir.has_cap and cfg.r_bat_ohm * cfg.c_out_f < cir.T / 10
        method = "Radau" if stiff else "DOP853"
    P = params
    n = cir.n
    det = P.l1_h * P.l2_h - P.lm_h**2
    rb, cap = cfg.r_bat_ohm, cir.has_cap
    helper = SwitchingLink(params, cfg)

    def rhs_factory(p, s):
        def rhs(t, y):
            i1, vc1, i2, vc2 = y[0], y[1], y[2], y[3]
            v1 = p * P.vdc_v if p != P_OPEN else 0.0
            if s in (1, -1):
                vout = y[4] if cap else P.vl_v + rb * s * i2
                v2 = s * vout
            else:
                v2 = 0.0
            e1 = v1 - P.r1_ohm * i1 - vc1
            e2 = -v2 - P.r2_ohm * i2 - vc2
            if p != P_OPEN and s != S_OPEN:
                di1 = (P.l2_h * e1 + P.lm_h * e2) / det
                di2 = (P.lm_h * e1 + P.l1_h * e2) / det
            elif p != P_OPEN:
                di1, di2 = e1 / P.l1_h, 0.0
            elif s != S_OPEN:
                di1, di2 = 0.0, e2 / P.l2_h
            else:
                di1 = di2 = 0.0
            out = [di1, i1 / cir.c1_f, di2, i2 / cir.c2_f]
            if cap:
                il = s * i2 if s in (1, -1) else 0.0
                out.append((il - (y[4] - P.vl_v) / rb) / cfg.c_out_f)
            return out
        return rhs

    def guard_factory(p, s, cmd, gate):
        fns = []
        if not gate and s in (1, -1):
            fns.append(("sec", lambda t, y, s=s: s * y[2]))
        if not gate and s == S_OPEN:
            r1, r2 = cir.vout_row() - cir.v2_open_row(p), cir.vout_row() + cir.v2_open_row(p)
            fns.append(("sec", lambda t, y, r=r1: np.append(y, 1.0) @ r))
            fns.append(("sec", lambda t, y, r=r2: np.append(y, 1.0) @ r))
        if cmd == 0 and p in (1, -1):
            fns.append(("pri", lambda t, y, p=p: -p * y[0]))
        if cmd == 0 and p == P_OPEN:
            vd = np.eye(cir.m)[-1] * P.vdc_v
            r1, r2 = vd - cir.v1_open_row(s), vd + cir.v1_open_row(s)
            fns.append(("pri", lambda t, y, r=r1: np.append(y, 1.0) @ r))
            fns.append(("pri", lambda t, y, r=r2: np.append(y, 1.0) @ r))
        for _, f in fns:
            f.terminal, f.direction = True, -1
        return fns

    x = np.array(x0, dtype=float)[:n]
    pieces = []  # (t_a, t_b, OdeSolution)
    p = int(schedule.cmd[0]) if schedule.cmd[0] != 0 else (-1 if x[0] > 0 else 1)
    s = S_SHORT if schedule.gate[0] else (1 if x[2] > 0 else -1)
    for j in range(len(schedule.cmd)):
        t, t_b = float(schedule.t[j]), float(schedule.t[j + 1])
        cmd, gate = int(schedule.cmd[j]), int(schedule.gate[j])
        xa = np.append(x, 1.0)
        p, s = helper._modes(xa, cmd, gate, p, s)
        while t < t_b:
            gl = guard_factory(p, s, cmd, gate)
            sol = solve_ivp(rhs_factory(p, s), (t, t_b), x, method=method, rtol=rtol, atol=atol,
                            events=[f for _, f in gl] or None, dense_output=True)
            pieces.append((t, float(sol.t[-1]), sol.sol))
            x = sol.y[:, -1].copy()
            t = float(sol.t[-1])
            if sol.status == 1:
                which = [i for i, e in enumerate(sol.t_events) if len(e)][0]
                x = sol.y_events[which][0].copy()
                t = float(sol.t_events[which][0])
                xa = np.append(x, 1.0)
                if gl[which][0] == "sec":
                    if s in (1, -1):
                        xa[I2] = 0.0
                        s = helper._secondary_at_zero(xa, p)
                    else:
                        s = 1 if xa @ cir.v2_open_row(p) > 0 else -1
                    if s == S_OPEN:
                        xa[I2] = 0.0
                else:
                    if p in (1, -1):
                        xa[I1] = 0.0
                        p = helper._primary_at_zero(xa, s)
                    else:
                        p = 1 if xa @ cir.v1_open_row(s) > 0 else -1
                    if p == P_OPEN:
                        xa[I1] = 0.0
                x = xa[:n]
            else:
                t = t_b
    starts = np.array([pc[0] for pc in pieces])
    t_eval = np.asarray([schedule.t[0], schedule.t[-1]] if t_eval is None else t_eval, dtype=float)
    idx = np.clip(np.searchsorted(starts, t_eval, side="right") - 1, 0, len(pieces) - 1)
    xs = np.empty((len(t_eval), n))
    for i in np.unique(idx):
        sel = idx == i
        xs[sel] = np.atleast_2d(pieces[i][2](t_eval[sel]).T)
    return t_eval, xs
