"""Slow reference for the switching-level model: the same circuit by ``scipy.integrate.solve_ivp``.

The right-hand side and the guards are written directly from eq. 1 and the device equations
(:mod:`wpt_receiver.devices`), not from the topology matrices of :mod:`.circuit`; only the mode
decisions at a drive change or a zero current are shared with :class:`~.link.SwitchingLink` (the
functions of :mod:`.mode_rules`, on the circuit's rows, :func:`.mode_rules.mode_rows`, which :mod:`.compiled` compiles
into its event loop; numba-free, so neither importing this module nor a call imports numba;
``tests/test_switching_compiled.py`` checks those rules against the circuit's rows on their own).
"""

from __future__ import annotations

import numpy as np

from ..params import LinkParams
from .circuit import P_OPEN, S_OPEN, Circuit, SwitchingConfig
from .schedule import Schedule

__all__ = ["simulate_ivp"]


def _terminal_voltages(P, cfg, cap, p, s, y):
    """Inverter output v1 and SBAR input v2 [V] of conducting topologies (devices included)."""
    dv = cfg.devices
    i1, i2 = y[0], y[2]
    if p in (1, -1):
        v1 = p * P.vdc_v - dv.inv_r_ohm * i1
    elif p in (2, -2):
        v1 = 0.5 * p * (P.vdc_v + dv.fw_vf_v) - dv.fw_rd_ohm * i1
    else:
        v1 = 0.0
    if s in (1, -1):
        vout = y[4] if cap else P.vl_v + cfg.r_bat_ohm * s * i2
        v2 = s * (vout + dv.rect_vf_v) + dv.rect_rd_ohm * i2
    elif s == 0:
        v2 = dv.short_r_ohm * i2
    else:
        v2 = 0.0
    return v1, v2


def _rhs_factory(P, cfg, cir, p, s):
    """Right-hand side of eq. 1 in topology ``(p, s)`` over the state ``[i1, vC1, i2, vC2, (vout)]``."""
    det = P.l1_h * P.l2_h - P.lm_h**2
    cap = cir.has_cap

    def rhs(t, y):
        i1, vc1, i2, vc2 = y[0], y[1], y[2], y[3]
        v1, v2 = _terminal_voltages(P, cfg, cap, p, s, y)
        e1 = v1 - P.r1_ohm * i1 - vc1
        e2 = -v2 - P.r2_ohm * i2 - vc2
        if p != P_OPEN and s != S_OPEN:
            di1, di2 = (P.l2_h * e1 + P.lm_h * e2) / det, (P.lm_h * e1 + P.l1_h * e2) / det
        elif p != P_OPEN:
            di1, di2 = e1 / P.l1_h, 0.0
        elif s != S_OPEN:
            di1, di2 = 0.0, e2 / P.l2_h
        else:
            di1 = di2 = 0.0
        out = [di1, i1 / cir.c1_f, di2, i2 / cir.c2_f]
        if cap:
            il = s * i2 if s in (1, -1) else 0.0
            out.append((il - (y[4] - P.vl_v) / cfg.r_bat_ohm) / cfg.c_out_f)
        return out
    return rhs


def _guard_factory(P, cfg, cir, p, s, cmd, gate):
    """Terminal events (direction -1) ending the topology: ``[("sec"|"pri", fn), ...]``."""
    fns = []
    one = np.eye(cir.m)[-1]
    if not gate and s in (1, -1):
        fns.append(("sec", lambda t, y, s=s: s * y[2]))
    if not gate and s == S_OPEN:
        th, vop = cir.vout_row() + one * cfg.devices.rect_vf_v, cir.v2_open_row(p)
        fns.append(("sec", lambda t, y, r=th - vop: np.append(y, 1.0) @ r))
        fns.append(("sec", lambda t, y, r=th + vop: np.append(y, 1.0) @ r))
    if cmd == 0 and p in (2, -2):
        fns.append(("pri", lambda t, y, p=p: -0.5 * p * y[0]))
    if cmd == 0 and p == P_OPEN:
        vd = one * (P.vdc_v + cfg.devices.fw_vf_v)
        fns.append(("pri", lambda t, y, r=vd - cir.v1_open_row(s): np.append(y, 1.0) @ r))
        fns.append(("pri", lambda t, y, r=vd + cir.v1_open_row(s): np.append(y, 1.0) @ r))
    for _, f in fns:
        f.terminal, f.direction = True, -1
    return fns


def simulate_ivp(params: LinkParams, cfg: SwitchingConfig, schedule: Schedule, x0, rtol: float = 1e-10,
                 atol: float = 1e-10, method: str | None = None, t_eval=None):
    """Slow reference: the same circuit integrated by ``scipy.integrate.solve_ivp`` between
    events; diode commutations are terminal events. Returns ``(t, x)`` with x (N, n) at
    ``t_eval`` (default: the ends).

    ``method`` defaults to DOP853, or Radau when the smoothing capacitor makes the system stiff
    (``r_bat_ohm * c_out_f < T / 10``): an explicit method then loses accuracy on the fast mode."""
    from scipy.integrate import solve_ivp

    from .mode_rules import _after_event, _modes, mode_rows  # the kernel's mode decisions, numba-free: one source
    cir = Circuit(params, cfg)
    if method is None:
        stiff = cir.has_cap and cfg.r_bat_ohm * cfg.c_out_f < cir.T / 10
        method = "Radau" if stiff else "DOP853"
    rules = mode_rows(cir)
    x = np.array(x0, dtype=float)[:cir.n]
    pieces = []  # (t_a, t_b, OdeSolution)
    p = s = None
    for j in range(len(schedule.cmd)):
        t, t_b = float(schedule.t[j]), float(schedule.t[j + 1])
        cmd, gate = int(schedule.cmd[j]), int(schedule.gate[j])
        p, s = _modes(np.append(x, 1.0), cmd, gate, *rules)
        while t < t_b:
            gl = _guard_factory(params, cfg, cir, p, s, cmd, gate)
            sol = solve_ivp(_rhs_factory(params, cfg, cir, p, s), (t, t_b), x, method=method, rtol=rtol, atol=atol,
                            events=[f for _, f in gl] or None, dense_output=True)
            pieces.append((t, float(sol.t[-1]), sol.sol))
            x, t = sol.y[:, -1].copy(), float(sol.t[-1])
            if sol.status == 1:
                which = [i for i, e in enumerate(sol.t_events) if len(e)][0]
                xa = np.append(sol.y_events[which][0], 1.0)
                t = float(sol.t_events[which][0])
                p, s = _after_event(xa, gl[which][0] == "sec", p, s, False, *rules)
                x = xa[:cir.n]
            else:
                t = t_b
    return _dense(pieces, schedule, t_eval, cir.n)


def _dense(pieces, schedule, t_eval, n):
    """States at ``t_eval`` from the pieces' dense outputs."""
    starts = np.array([pc[0] for pc in pieces])
    t_eval = np.asarray([schedule.t[0], schedule.t[-1]] if t_eval is None else t_eval, dtype=float)
    idx = np.clip(np.searchsorted(starts, t_eval, side="right") - 1, 0, len(pieces) - 1)
    xs = np.empty((len(t_eval), n))
    for i in np.unique(idx):
        sel = idx == i
        xs[sel] = np.atleast_2d(pieces[i][2](t_eval[sel]).T)
    return t_eval, xs
