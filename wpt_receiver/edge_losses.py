"""Switching-edge losses from datasheet data: energy per edge added to the loss integrals.

The event-exact switching model (:mod:`wpt_receiver.switching`) keeps the devices' conduction
models in its state equations; capacitances, reverse recovery and the V-I overlap of a hard edge
act within nanoseconds, far below the 5.9 us rectifier period, so they enter as an *energy per
edge*, evaluated with the exact current at each edge of a run (``edge_energies``) or, for an
averaged operating point, in closed form (``averaged_edge_losses``). Per edge, with ``V`` the
blocked voltage and ``I`` the switched current (``Diode`` / ``Switch`` fields of
:mod:`wpt_receiver.devices`):

* **hard turn-on** (SBAR: the gate turns a lower switch on while the upper diode of its node
  conducts, the node at ``V = VL + Vf``): the node's capacitance ``C = Coss + Cj`` is shorted,
  ``E = C V^2 / 2`` (the switch's own ``Coss`` energy plus the loss of charging the diode's ``Cj``
  from the battery), plus the overlap ``E_on = eon_j_va V I`` (current rising at full voltage);
* **hard turn-off** (gate off with current ``I`` in the channel's forward direction): the
  channel current falls linearly in ``t_f = 2 eoff_j_va`` (the datasheet's ``E_ref = V_ref I_ref
  t_f / 2``) while the excess current charges ``C``: the voltage reaches ``V`` at
  ``t_1 = sqrt(2 t_f C V / I)``; ``E = int v i_ch dt`` in closed form (:func:`turn_off_energy`),
  ``= eoff_j_va V I`` when ``C -> 0`` (the datasheet's linear scaling) and less when the
  capacitance snubs the edge;
* **reverse recovery**: a body diode that conducts when its switch's complement turns on hard
  (inverter) recovers ``Qrr = tt I`` against ``V``: ``E = Qrr V``; at a natural zero crossing of a
  sinusoidal current (SBAR) the charge left is ``tt^2 |di/dt|`` (the charge-control model the
  ``tt`` comes from), ``E = Qrr V`` as an upper bound (the swing is current-driven);
* **inverter**: a leg whose current has already swung it in the dead time turns on at zero
  voltage (no loss); otherwise both legs switch hard: ``2 Coss Vdc^2`` (own discharge plus the
  complementary device's charge from the source), ``2 eon Vdc |i1|`` and the opposite body diodes'
  recovery when they were freewheeling. A channel carrying forward current turns off with
  :func:`turn_off_energy`.

``edge_energies`` keys: ``rect_turn_on_j``, ``rect_turn_off_j``, ``rect_recovery_j``,
``inv_turn_on_j``, ``inv_turn_off_j``, ``inv_recovery_j`` (sums over the run's edges in
``[t_a, t_b)``), plus ``rect_j``, ``inv_j`` and ``total_j``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["turn_off_energy", "edge_energies", "averaged_edge_losses", "EDGE_KEYS"]

EDGE_KEYS = ("rect_turn_on_j", "rect_turn_off_j", "rect_recovery_j", "inv_turn_on_j", "inv_turn_off_j",
             "inv_recovery_j")


def turn_off_energy(v_v, i_a, t_f_s: float, c_f):
    """Overlap energy [J] of a channel whose current ``i_a`` falls linearly to 0 in ``t_f_s`` while
    the excess charges the node capacitance ``c_f`` from 0 towards the clamp ``v_v`` [V].

    ``v(t) = I t^2 / (2 t_f C)`` until ``t_1 = sqrt(2 t_f C V / I)``, then clamped at ``V``;
    ``E = int_0^t_f v(t) I (1 - t/t_f) dt``. Vectorised over ``v_v``, ``i_a`` (>= 0) and ``c_f`` [F]."""
    v, i = np.asarray(v_v, dtype=float), np.abs(np.asarray(i_a, dtype=float))
    if t_f_s <= 0:
        return np.zeros(np.broadcast(v, i).shape) + 0.0
    if np.ndim(c_f):   # (one capacitance per entry, e.g. per step of a mission at its own battery voltage)
        c = np.asarray(c_f, dtype=float)
        return np.where(c > 0, _turn_off_c(v, i, t_f_s, np.where(c > 0, c, 1.0)), 0.5 * v * i * t_f_s)
    if c_f <= 0:
        return 0.5 * v * i * t_f_s
    return _turn_off_c(v, i, t_f_s, c_f)


def _turn_off_c(v, i, t_f_s: float, c_f):
    """:func:`turn_off_energy` for a capacitance ``c_f`` > 0 (a number or one per entry)."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):   # a subnormal I: t1 = inf, u = 1
        t1 = np.sqrt(2.0 * t_f_s * c_f * v / np.where(i > 0, i, 1.0))
    u = np.minimum(t1 / t_f_s, 1.0)                          # share of the fall before the clamp
    # ramp part: int_0^{u tf} I^2 t^2/(2 tf C) (1 - t/tf) dt = I^2 tf^2 (u^3/3 - u^4/4) / (2 C)
    e_ramp = i * i * t_f_s * t_f_s * (u ** 3 / 3.0 - u ** 4 / 4.0) / (2.0 * c_f)
    # clamped part: int_{u tf}^{tf} V I (1 - t/tf) dt = V I tf (1 - u)^2 / 2
    e_clamp = 0.5 * v * i * t_f_s * (1.0 - u) ** 2
    return np.where(i > 0, e_ramp + e_clamp, 0.0)


def _rect_block_v(cir, x) -> np.ndarray:
    """Voltage a blocked SBAR node holds: rectifier output + the rectifying path's forward drops."""
    return x @ cir.rect_threshold_row()


def _changes(values, times, t_a: float, t_b: float):
    """``(values, j, t)``: the schedule's ``values`` as an array, and the indices ``j`` and times ``t``
    of its entries that change the value, in ``[t_a, t_b)``."""
    v = np.asarray(values)
    j = np.nonzero(np.diff(v) != 0)[0] + 1
    t = np.asarray(times)[j]
    sel = (t >= t_a) & (t < t_b)
    return v, j[sel], t[sel]


def _sbar_edges(res, t_a, t_b, dv):
    """SBAR gate edges in ``[t_a, t_b)``: hard turn-on and turn-off energies [J]."""
    from .switching.circuit import I2
    cir = res.circuit
    g, j, t = _changes(res.schedule.gate, res.schedule.t, t_a, t_b)
    if not len(t):
        return 0.0, 0.0
    x, k = res.states(t - 1e-12 * cir.T)
    keys = np.array(cir.keys)[k]
    on = g[j] == 1
    rect = np.isin(keys[:, 1], (1, -1))        # a diode pair conducted before the edge
    v = _rect_block_v(cir, x)
    i = np.abs(x[:, I2])
    sw, c = dv.rect_switch, dv.rect_switch.coss_f + dv.rect_diode.c_f
    e_on = np.where(on & rect, 0.5 * c * v * v + sw.eon_j_va * v * i, 0.0).sum()
    e_off = np.where(~on, turn_off_energy(v, i, 2.0 * sw.eoff_j_va, c), 0.0).sum()
    return float(e_on), float(e_off)


def _sbar_recovery(res, t_a, t_b, dv):
    """Natural commutations of the SBAR's diode pairs (s = +-1 -> other): the lower body diode that
    conducted recovers ``tt^2 |di2/dt|`` against the blocked voltage."""
    from .switching.circuit import I2
    tt = dv.rect_switch.body.tt_s
    if tt <= 0:
        return 0.0
    cir = res.circuit
    s = np.array([key[1] for key in cir.keys])[res.seg_k]
    ends = np.nonzero(np.isin(s[:-1], (1, -1)) & (s[1:] != s[:-1]) & (s[1:] != 0))[0] + 1
    t = res.seg_t[ends]
    t = t[(t >= t_a) & (t < t_b)]
    if not len(t):
        return 0.0
    eps = 1e-12 * cir.T
    x, _ = res.states(t - eps)
    di, _ = res.states(t - eps, cols=[I2], deriv=1)
    return float(np.sum(tt * tt * np.abs(di[:, 0]) * _rect_block_v(cir, x)))


def _inverter_edges(res, t_a, t_b, dv):
    """Inverter commutations: ``(turn-on, turn-off, recovery)`` energies [J] (module docstring)."""
    from .switching.circuit import I1
    cir = res.circuit
    cmd, j, t = _changes(res.schedule.cmd, res.schedule.t, t_a, t_b)
    if not len(t):
        return 0.0, 0.0, 0.0
    x, k = res.states(t - 1e-12 * cir.T)
    p_before = np.array(cir.keys)[k][:, 0]
    new, old = cmd[j], cmd[j - 1]
    i1 = x[:, I1]
    vdc, sw = cir.p.vdc_v, dv.inv_switch
    # turn-off: the outgoing channels carried forward current (i1 in the direction of their polarity)
    off = (old != 0) & (i1 * old > 0)
    e_off = 2.0 * np.where(off, turn_off_energy(vdc, i1, 2.0 * sw.eoff_j_va, 2.0 * sw.coss_f), 0.0).sum()
    # turn-on: soft if the new polarity's diodes already freewheel, else hard
    turn_on = new != 0
    soft = p_before == 2 * new
    hard = turn_on & ~soft
    e_on = np.where(hard, 2.0 * sw.coss_f * vdc * vdc + 2.0 * sw.eon_j_va * vdc * np.abs(i1), 0.0).sum()
    rec = hard & (p_before == -2 * new)
    e_rr = np.where(rec, 2.0 * sw.body.tt_s * np.abs(i1) * vdc, 0.0).sum()
    return float(e_on), float(e_off), float(e_rr)


def edge_energies(res, t_a: float | None = None, t_b: float | None = None) -> dict:
    """Energies of every switching edge of a :class:`~wpt_receiver.switching.SwitchingResult` in
    ``[t_a, t_b)`` [J], by group (module docstring); the devices are the run's
    (``res.circuit.cfg.devices``). Zero for devices without edge data (:data:`~.devices.IDEAL`)."""
    t_a = res.t0 if t_a is None else float(t_a)
    t_b = res.t_end if t_b is None else float(t_b)
    dv = res.circuit.cfg.devices
    on, off = _sbar_edges(res, t_a, t_b, dv)
    rr = _sbar_recovery(res, t_a, t_b, dv)
    ion, ioff, irr = _inverter_edges(res, t_a, t_b, dv)
    out = dict(zip(EDGE_KEYS, (on, off, rr, ion, ioff, irr)))
    out["rect_j"], out["inv_j"] = on + off + rr, ion + ioff + irr
    out["total_j"] = out["rect_j"] + out["inv_j"]
    return out


def averaged_edge_losses(d_short, i2_amp_a, vl_v: float, devices, rectifier_period_s: float, omega_rad_s: float,
                         *, i1_amp_a=0.0, vdc_v: float = 0.0, c_rect_f=None) -> dict:
    """Closed-form mean edge power [W] for fundamental amplitudes (the averaged counterpart of
    :func:`edge_energies`): with ``i2 = I2 cos(theta)`` and the short window centred on the peak
    (eq. 9's placement), each rectifier period has one hard turn-on and one hard turn-off at
    ``|i| = |I2| cos(pi d / 2)`` (for ``0 < d < 1``) and one natural commutation at slope
    ``omega |I2|``. The inverter (``i1 = I1 sin``, commutating at the current zero) is counted as
    hard-switched at zero current: ``2 Coss Vdc^2`` per commutation (an upper bound; ZVS when the
    tank is inductive). Keys ``rectifier_w``, ``inverter_w``. Vectorised over ``d_short``, ``i2_amp_a``.
    ``c_rect_f`` [F]: the SBAR node's capacitance (switch Coss + diode Cj; a number or one per entry, e.g. at each
    step's own battery voltage: :func:`wpt_receiver.devices.rect_node_c_f`); ``None``: the devices' own."""
    d = np.asarray(d_short, dtype=float)
    i2 = np.abs(np.asarray(i2_amp_a, dtype=float))
    sw, dio = devices.rect_switch, devices.rect_diode
    v = vl_v + devices.rect_vf_v
    c = sw.coss_f + dio.c_f if c_rect_f is None else c_rect_f
    edge = (d > 0) & (d < 1)
    i_edge = i2 * np.cos(0.5 * np.pi * d)
    e = np.where(edge, 0.5 * c * v * v + sw.eon_j_va * v * i_edge + turn_off_energy(v, i_edge, 2 * sw.eoff_j_va, c), 0.0)
    tt = sw.body.tt_s
    e = e + np.where(d < 1, tt * tt * omega_rad_s * i2 * v, 0.0)
    inv = devices.inv_switch
    p_inv = 2.0 * inv.coss_f * vdc_v * vdc_v / rectifier_period_s + 0.0 * np.asarray(i1_amp_a, dtype=float)
    out = {"rectifier_w": e / rectifier_period_s, "inverter_w": p_inv}
    return {k: (val if np.ndim(val) else float(val)) for k, val in out.items()}

