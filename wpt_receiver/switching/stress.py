"""Voltage stress of the SBAR: the open-load (BMS disconnect) fault and the ringing of an edge.

**Open load.** A series-series link drives its secondary like a current source: at resonance
``I2 = Vdc (4/pi) / (omega Lm)`` whatever the load voltage, so when the battery disconnects (BMS
contactor, connector bounce) while the diodes rectify, ``i2`` keeps charging the rectifier's output
capacitor ``c_out_f`` and its voltage rises (at first ``(2/pi) I2 / C_out`` per second, then slower
while the tanks' beat lowers I2 for ~ms; the steady state is a current source again) until a device
breaks down (avalanche) or a protection shorts the SBAR (both lower switches on: the diodes stop,
the output holds its voltage). :func:`open_load_run` simulates it on the event-exact switching
model: the link runs at its periodic steady state with the battery behind ``r_bat_ohm``, the
battery opens at ``t = 0`` (``r_bat -> 1e9 ohm``) with the SBAR at duty ``d_short`` (0 = RM; a duty
in (0, 1) = the fault while switching to SM), and the table gives the peak blocked voltage of
every diode and lower switch (output voltage plus the rectifying path's forward drop) against the
protection's time to short. ``c_out_f`` is an input of the study: the project's env assumes a
4.7 mF bus (``envs.core.EnvConfig.bus_c_f``); a receiver with only ceramic capacitors (10 uF)
has 470x less time.

**Edge ringing.** At a hard turn-off of a lower switch the node capacitance ``C = Coss + Cj`` is
charged by ``I`` and, at the clamp, the current has to move into the diode path through the stray
loop inductance ``L_s`` (package + layout): a series RLC. :func:`edge_ring` gives its closed-form
first peak above the clamp (``I sqrt(L_s/C)`` without resistance; the path's resistance raises it)
and its frequency ``1 / (2 pi sqrt(L_s C))``, with the channel's fall time taken as zero;
:func:`edge_turn_off_transient` has the fall (checked against SPICE).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

__all__ = ["open_load_run", "edge_ring", "edge_turn_off_transient", "voltage_stress"]

_R_OPEN_OHM = 1e9


def edge_ring(i_a: float, l_stray_h: float, c_f: float, r_ohm: float = 0.0) -> dict:
    """Overshoot [V] above the clamp and ring frequency [Hz] of the series RLC of an edge
    (module docstring): ``z0 = sqrt(L/C)``, ``zeta = R / (2 z0)``.

    The circuit: the current ``I`` charges the node ``C`` to the clamp, then has to move into the
    diode path ``L`` + ``R``: ``C de/dt = I - i_L``, ``L di_L/dt = e - R i_L`` from ``e = i_L = 0``
    (``e`` = node voltage above the clamp). Its first maximum in closed form: with
    ``s = -alpha +- j wd``, ``e(t) = R I + I e^(-alpha t) (a cos wd t + b sin wd t)``,
    ``a = -R``, ``b = (1/C - R alpha)/wd``, at ``wd t* = atan2(wd b - alpha a, alpha b + wd a)``.
    ``I z0`` for ``R = 0``; the path's resistance *raises* the first peak (``e`` ends at ``R I``),
    it does not damp it (an earlier ``I z0 exp(-zeta pi / (2 sqrt(1 - zeta^2)))`` was 2 % low at
    zeta = 0.01 and 47 % low at 0.3 against this circuit integrated). Overdamped (zeta >= 1) ``e``
    rises monotonically to ``R I``."""
    i, l, c, r = np.abs(np.asarray(i_a, dtype=float)), float(l_stray_h), float(c_f), float(r_ohm)   # i: scalar or array
    if not (math.isfinite(r) and r >= 0.0):
        raise ValueError(f"r_ohm={r_ohm!r} is invalid; valid range: [0, inf) ohm (the diode path's resistance)")
    if not (l > 0 and c > 0):
        return {"overshoot_v": 0.0, "ring_hz": math.inf, "z0_ohm": 0.0, "zeta": 0.0}
    z0 = math.sqrt(l / c)
    zeta = r / (2.0 * z0)
    return {"overshoot_v": i * _rlc_first_peak(l, c, r), "ring_hz": 1.0 / (2.0 * math.pi * math.sqrt(l * c)),
            "z0_ohm": z0, "zeta": zeta}


def _rlc_first_peak(l: float, c: float, r: float) -> float:
    """First maximum of ``e(t)`` per ampere [ohm] for :func:`edge_ring`'s circuit."""
    alpha, w0 = r / (2.0 * l), 1.0 / math.sqrt(l * c)
    if alpha < w0:
        wd = math.sqrt(w0 * w0 - alpha * alpha)
        a, b = -r, (1.0 / c - r * alpha) / wd
        th = math.atan2(wd * b - alpha * a, alpha * b + wd * a)
        return r + math.exp(-alpha * th / wd) * (a * math.cos(th) + b * math.sin(th))
    # overdamped: de/dt is proportional to e^(s1 t)(R + L s1) - e^(s2 t)(R + L s2) with s2 < s1 < 0 and
    # R + L s2 = R/2 - L q > 0: positive for all t, so e rises monotonically to R I
    return r


def edge_turn_off_transient(i_a: float, v_clamp_v: float, c_f: float, l_stray_h: float, r_ohm: float,
                            t_f_s: float) -> dict:
    """First voltage peak [V] of a hard turn-off edge with the stray loop inductance: the channel
    current falls linearly from ``i_a`` in ``t_f_s`` (as :func:`wpt_receiver.edge_losses.turn_off_energy`),
    the excess charges the node capacitance ``c_f`` from 0; at ``v_clamp_v`` the diode path (``l_stray_h``
    in series with ``r_ohm``) starts to conduct: ``C dv/dt = I - i_ch(t) - i_L``,
    ``L di_L/dt = v - V - R i_L``, integrated (scipy ``solve_ivp``, rtol 1e-10) to the first maximum
    of ``v``. Returns ``peak_v``, ``overshoot_v`` and the clamp time ``t1_s``. Checked against ngspice
    (``tests/spice/edge_ring.cir``)."""
    from scipy.integrate import solve_ivp
    i, tf = abs(float(i_a)), float(t_f_s)
    if i <= 0 or c_f <= 0:
        return {"peak_v": float(v_clamp_v), "overshoot_v": 0.0, "t1_s": math.inf}

    def ich(t):
        return i * max(0.0, 1.0 - t / tf) if tf > 0 else 0.0
    # phase 1: v = int (I - i_ch) / C, closed form while the channel still falls
    t1 = math.sqrt(2.0 * tf * c_f * v_clamp_v / i) if tf > 0 else c_f * v_clamp_v / i
    if tf > 0 and t1 > tf:  # the channel is off before the clamp: then v rises at I / C
        t1 = tf + (c_f * v_clamp_v - i * tf / 2.0) / i

    def rhs(t, y):
        return [(i - ich(t) - y[1]) / c_f, (y[0] - v_clamp_v - r_ohm * y[1]) / l_stray_h]

    def top(t, y):
        return i - ich(t) - y[1]   # dv/dt = 0
    top.terminal, top.direction = True, -1
    period = 2 * math.pi * math.sqrt(l_stray_h * c_f)
    sol = solve_ivp(rhs, (t1, t1 + 2 * period + tf), [v_clamp_v, 0.0], events=top, rtol=1e-10, atol=1e-12,
                    max_step=period / 50)
    peak = float(sol.y_events[0][0][0]) if sol.t_events[0].size else float(np.max(sol.y[0]))
    return {"peak_v": peak, "overshoot_v": peak - v_clamp_v, "t1_s": t1}


def open_load_run(params, devices, c_out_f: float = 4.7e-3, r_bat_ohm: float = 0.05, d_short: float = 0.0,
                  t_max_s: float = 2e-3, times_to_short_s=(1e-6, 1e-5, 1e-4, 1e-3)) -> dict:
    """Open-load fault on the switching model (module docstring). Returns ``v_out_v`` at
    ``t_s`` (dense, from the opening), ``peak_v`` per time to short (``times_to_short_s``, the
    largest blocked voltage up to that time), the initial output voltage, ``dv_dt0_v_s`` (over the
    first rectifier period: ``(2/pi) I2 / C``) and ``dv_dt_v_s`` (fit over the second half of the run:
    slower, the link's current falls back while V2 rises, for the ~ms of its beat, before the
    current-source steady state returns)."""
    from .circuit import VO, SwitchingConfig
    from .link import SwitchingLink
    for name, v in (("c_out_f", c_out_f), ("r_bat_ohm", r_bat_ohm), ("t_max_s", t_max_s)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name}={v!r} is invalid; valid range: (0, inf)")
    cfg = SwitchingConfig(devices=devices, c_out_f=c_out_f, r_bat_ohm=r_bat_ohm)
    normal = SwitchingLink(params, cfg)
    x0 = normal.periodic_steady_state(d_short)
    opened = SwitchingLink(params, replace(cfg, r_bat_ohm=_R_OPEN_OHM))
    T = opened.T
    n = int(math.ceil(t_max_s / T))
    res = opened.simulate(np.full(n, float(d_short)), x0=x0)
    ts = res.sample_times(16)
    x, _ = res.states(ts, cols=[VO])
    v = x[:, 0] + devices.rect_vf_v
    vmax = np.maximum.accumulate(v)
    peaks = {float(t): float(np.interp(t, ts, vmax)) for t in times_to_short_s if t <= ts[-1]}
    slope = float(np.polyfit(ts[len(ts) // 2:], x[len(ts) // 2:, 0], 1)[0])
    slope0 = float((np.interp(ts[0] + T, ts, x[:, 0]) - x[0, 0]) / T)
    return {"t_s": ts, "v_block_v": v, "peak_v": peaks, "v0_v": float(v[0]), "dv_dt_v_s": slope, "dv_dt0_v_s": slope0,
            "c_out_f": c_out_f, "d_short": float(d_short)}


def voltage_stress(params, devices, t_protect_s: float = 1e-4, c_out_f: float = 4.7e-3, l_stray_h: float = 20e-9,
                   i_edge_a: float = 0.0, duties=(0.0, 0.5)) -> dict:
    """Worst simulated blocking voltage [V] of the SBAR's devices: the open-load fault in RM and
    while switching to SM (``duties``), shorted after ``t_protect_s``, against the clamp plus the
    ring of a hard edge at ``i_edge_a`` (:func:`edge_ring` with ``Coss + Cj`` and ``l_stray_h``).
    Returns ``v_worst_v``, ``case`` and the parts."""
    runs = {d: open_load_run(params, devices, c_out_f=c_out_f, d_short=d, t_max_s=max(1.2 * t_protect_s, 4e-5),
                             times_to_short_s=(t_protect_s,)) for d in duties}
    ring = edge_ring(i_edge_a, l_stray_h, devices.rect_switch.coss_f + devices.rect_diode.c_f,
                     devices.rect_diode.rd_ohm + devices.rect_switch.body.rd_ohm)
    cases = {f"open load, d = {d:g}, short after {t_protect_s * 1e6:g} us": r["peak_v"][t_protect_s]
             for d, r in runs.items()}
    cases["edge ring"] = params.vl_v + devices.rect_vf_v + ring["overshoot_v"]
    case = max(cases, key=cases.get)
    return {"v_worst_v": cases[case], "case": case, "cases": cases, "ring": ring, "runs": runs,
            "t_protect_s": t_protect_s, "c_out_f": c_out_f}
