"""SPICE netlist of the switching model's circuit with its devices (ngspice; LTspice-compatible syntax).

The scenario (model time; SPICE time is model time - T/2): the link starts at the fundamental
(phasor) solution of eq. 4 with the devices folded in (closed form, not from the switching model),
runs in RM until ``t_step_s``, then the SBAR shorts with duty ``d_short`` until ``t_end_s``
(``d_short = None`` or 1: the gate stays on, short mode). Both simulators can start from the same
state, so the numbers compare the same transient. Measured (``.meas``): max and min of i2 and i1
over the last 4 rectifier periods before the step (``rm_*``), after the step (``step_*``) and
before the end (``sm_*``).

Device models: every diode is a near-ideal junction (``IS = 1 uA``, ``N = 0.01``: 4 mV at 10 A,
1 uA leakage) in series with a DC source ``vf0_v`` and a resistor ``rd_ohm``; every MOSFET channel
a voltage-controlled switch with ``RON = ron_ohm`` (the piecewise-linear parts of
:mod:`wpt_receiver.devices`). The inverter is either a square-wave source with the two driven
channels' resistance in series (``dead_time_s=None``, no dead time) or a real full bridge: a DC
source, four switches with ``RON`` of the inverter switch, each with its body diode, and one gate
source per diagonal with the dead time after every commutation. The SBAR gate windows of duty
``d < 1`` are centred at ``n T`` in SPICE time (the switching model's clock at phase pi/2).

This is the generator of the stored netlists in ``tests/spice/`` (``tests/_spice.py`` uses it)
and of ``dronewpt netlist``.
"""

from __future__ import annotations

import math

from ..devices import DeviceSet
from ..envelope import steady_state
from ..params import TABLE_I, warn_off_resonance

__all__ = ["T_STEP_S", "T_END_S", "initial_state", "netlist"]

T_STEP_S = 3e-3
T_END_S = 9e-3
_TR_S = 1e-9   # gate and source edge time [s]


def initial_state(p, dv: DeviceSet):
    """(i1, vC1, i2, vC2) at t = T/2 (a quarter inverter period) of the phasor solution
    i1 = I1 sin wt, i2 = I2 cos wt: i2 = 0 there, so SPICE starts with the diodes off."""
    pd = p.with_(r1_ohm=p.r1_ohm + dv.inv_r_ohm, r2_ohm=p.r2_ohm + dv.rect_rd_ohm)
    i1, i2 = steady_state(pd, 4 / math.pi * (p.vl_v + dv.rect_vf_v))
    w = p.omega_rad_s
    c2 = 1 / (w * w * p.l2_h)
    return float(i1), 0.0, 0.0, float(i2) / (w * c2)


def _diode(name, anode, cathode, vf, rd):
    """Near-ideal junction + forward drop source + slope resistance."""
    return (f"D{name} {anode} x{name} DI\nVF{name} x{name} y{name} DC {vf!r}\n"
            f"RD{name} y{name} {cathode} {max(rd, 1e-6)!r}\n")


def _diodes(diode, places) -> str:
    """:func:`_diode` of one device model at each ``(name, anode, cathode)``."""
    return "".join(_diode(name, a, k, diode.vf0_v, diode.rd_ohm) for name, a, k in places)


def _check(p, t_step_s, t_end_s, d_short, dead_time_s) -> None:
    T = p.rectifier_period_s
    if not (8 * T <= t_step_s and t_step_s + 8 * T <= t_end_s <= 1.0):
        raise ValueError(f"t_step_s={t_step_s!r}, t_end_s={t_end_s!r} are invalid; valid: t_step_s >= 8 T = "
                         f"{8 * T:.3g} s, t_end_s >= t_step_s + 8 T, t_end_s <= 1 s")
    if d_short is not None and not (0.0 <= d_short <= 1.0):
        raise ValueError(f"d_short={d_short!r} is invalid; valid range: [0, 1]")
    if dead_time_s is not None and not (0.0 <= dead_time_s <= 0.25 * T):
        raise ValueError(f"dead_time_s={dead_time_s!r} is invalid; valid range: [0, {0.25 * T:.3g}] s (T/4)")


def netlist(p=TABLE_I, dv: DeviceSet = DeviceSet(), label: str = "ideal", dead_time_s: float | None = None,
            t_step_s: float = T_STEP_S, t_end_s: float = T_END_S, d_short: float | None = None) -> str:
    """ngspice netlist of the scenario (module docstring): ``dead_time_s=None`` models the inverter
    as a square-wave source, a number [s] as a full bridge with that dead time; ``d_short`` the SBAR
    duty from ``t_step_s`` on (None: 1, the gate stays on). Warns an ``f_hz`` far off the coils' resonance
    (:func:`wpt_receiver.params.warn_off_resonance`)."""
    _check(p, t_step_s, t_end_s, d_short, dead_time_s)
    warn_off_resonance(p)
    w, T = p.omega_rad_s, p.rectifier_period_s
    c1, c2 = 1 / (w * w * p.l1_h), 1 / (w * w * p.l2_h)
    i10, vc10, i20, vc20 = initial_state(p, dv)
    k = p.lm_h / math.sqrt(p.l1_h * p.l2_h)
    ron, body = dv.rect_switch.ron_ohm, dv.rect_switch.body
    tr = _TR_S
    if dead_time_s is None:
        primary = [
            "* primary: square wave +-Vdc (no dead time), 2 Ron + R1, C1, L1; secondary: L2 (i2 = -I(L2)), R2, C2, SBAR\n",
            f"VINV p 0 PULSE({p.vdc_v!r} {-p.vdc_v!r} {T / 2 - tr / 2!r} {tr!r} {tr!r} {T - tr!r} {2 * T!r})\n",
            f"C1 p c1 {c1!r} IC={vc10!r}\n",
            f"R1 c1 c {p.r1_ohm + dv.inv_r_ohm!r}\n",
            f"L1 c 0 {p.l1_h!r} IC={i10!r}\n"]
    else:
        primary = _bridge(p, dv, dead_time_s, tr) + [
            f"C1 ma c1 {c1!r} IC={vc10!r}\n",
            f"R1 c1 c {p.r1_ohm!r}\n",
            f"L1 c mb {p.l1_h!r} IC={i10!r}\n"]
    return "".join([
        f"* dronewpt SPICE check, devices: {label}\n",
        *primary,
        f"L2 a b {p.l2_h!r} IC={-i20!r}\n",
        f"K12 L1 L2 {k!r}\n",
        f"R2 bb b {p.r2_ohm!r}\n",
        f"C2 bq bb {c2!r} IC={vc20!r}\n",
        "VSENSE bq bn DC 0\n",
        # SBAR: A = a, B = bn, battery between bat and ground (SPICE node names are case-insensitive)
        _diodes(dv.rect_diode, (("U1", "a", "bat"), ("U2", "bn", "bat"))),
        _diodes(body, (("B1", "0", "a"), ("B2", "0", "bn"))),
        "S1 a 0 g 0 SWM\nS2 bn 0 g 0 SWM\n",
        _gate(T, t_step_s, d_short, tr),
        f"VL bat 0 DC {p.vl_v!r}\n",
        ".model DI D(IS=1e-6 N=0.01)\n",
        f".model SWM SW(VT=0.5 VH=0.1 RON={max(ron, 1e-6)!r} ROFF=1e7)\n",
        ".options reltol=1e-6 abstol=1e-9 vntol=1e-7 method=gear maxord=2 itl4=200\n",
        f".tran {T / 1000!r} {t_end_s - T / 2!r} 0 {T / 1000!r} uic\n",
        _measures(T, t_step_s, t_end_s),
        ".end\n"])


def _gate(T: float, t_step_s: float, d_short, tr: float) -> str:
    """The SBAR gate source: a step to on at ``t_step_s`` (``d_short`` None or 1), off (0) or a pulse
    train of windows ``d T`` wide centred at ``n T`` (SPICE time), ``n T >= t_step_s - T/2``."""
    if d_short is None or d_short >= 1.0:
        return f"VG g 0 PWL(0 0 {t_step_s - T / 2!r} 0 {t_step_s - T / 2 + tr!r} 1)\n"
    if d_short * T <= tr:
        return "VG g 0 DC 0\n"
    n0 = round(t_step_s / T)        # first window of the switching model's clock (phase pi/2)
    td = n0 * T - d_short * T / 2 - tr / 2
    return f"VG g 0 PULSE(0 1 {td!r} {tr!r} {tr!r} {d_short * T - tr!r} {T!r})\n"


def _bridge(p, dv: DeviceSet, td: float, tr: float) -> list:
    """Full bridge between the leg midpoints ``ma`` (v1 = v(ma) - v(mb)) and ``mb``: switches with
    the inverter switch's ``RON``, each with its body diode. Model time ``[k T, (k+1) T)`` drives
    +Vdc for even k, -Vdc for odd k, after a dead time ``td`` from ``k T`` (both diagonals off);
    SPICE time 0 is model time T/2 (diagonal P = A high + B low on). The gates switch at the
    midpoints of their ``tr`` edges."""
    T, sw = p.rectifier_period_s, dv.inv_switch
    return [
        f"* primary: full bridge from Vdc, switches Ron, body diodes, dead time {td!r} s; C1, R1, L1 from ma to mb;\n",
        "* secondary: L2 (i2 = -I(L2)), R2, C2, SBAR\n",
        f"VDC vdc 0 DC {p.vdc_v!r}\n",
        f"VGP gp 0 PULSE(1 0 {T / 2 - tr / 2!r} {tr!r} {tr!r} {T + td - tr!r} {2 * T!r})\n",
        f"VGN gn 0 PULSE(0 1 {T / 2 + td - tr / 2!r} {tr!r} {tr!r} {T - td - tr!r} {2 * T!r})\n",
        "SAH vdc ma gp 0 SWI\nSBL mb 0 gp 0 SWI\nSAL ma 0 gn 0 SWI\nSBH vdc mb gn 0 SWI\n",
        _diodes(sw.body, (("AH", "ma", "vdc"), ("AL", "0", "ma"), ("BH", "mb", "vdc"), ("BL", "0", "mb"))),
        f".model SWI SW(VT=0.5 VH=0.1 RON={max(sw.ron_ohm, 1e-6)!r} ROFF=1e7)\n"]


def _measures(T, t_step_s: float = T_STEP_S, t_end_s: float = T_END_S):
    w, o = 4 * T, T / 2  # o: SPICE time origin in model time
    spans = {"rm": (t_step_s - w - o, t_step_s - o), "step": (t_step_s - o, t_end_s - o),
             "sm": (t_end_s - w - o, t_end_s - o)}
    out = []
    for name, (a, b) in spans.items():
        for sig, expr in (("i2", "I(VSENSE)"), ("i1", "I(L1)")):
            out.append(f".meas tran {name}_{sig}_max MAX {expr} from={a!r} to={b!r}\n")
            out.append(f".meas tran {name}_{sig}_min MIN {expr} from={a!r} to={b!r}\n")
    return "".join(out)
