"""Junction temperatures: a fixed-point loop that settles the devices' losses at their own heat.

Each device ``k`` sits on a common heat sink: ``Tj_k = T_sink + P_k(Tj) (Rth_jc,k + Rth_cs,k)``,
with ``T_sink = T_amb + P_total Rth_sa`` (a given sink) or ``T_amb + dT_sink`` (a sink sized for
the loss at a fixed rise, :class:`wpt_receiver.sizing.SizingRules`). The losses depend on the
junction temperatures (R_DS(on) rises ~1.5-1.8x from 25 to 125 C, a Schottky's knee falls), so the
loop iterates ``Tj <- T_sink + P(Tj) Rth`` from 25 C until no junction moves by more than
``tol_k``. It stops with :class:`ThermalRunaway` when a junction passes its maximum (the part
cannot carry the load on this sink) or when the iteration does not contract (the loss grows
faster with temperature than the sink removes it: ``dP/dTj Rth >= 1``).
"""

from __future__ import annotations

import math

__all__ = ["ThermalRunaway", "settle_junctions"]


class ThermalRunaway(ValueError):
    """The junction temperatures do not settle below the parts' maxima."""


def settle_junctions(losses_w, rth_k_w: dict, tj_max_c: dict, t_amb_c: float = 40.0, dt_sink_k: float | None = None,
                     rth_sa_k_w: float | None = None, tol_k: float = 0.01, max_iter: int = 60) -> dict:
    """Fixed point of the junction temperatures (module docstring).

    ``losses_w(tj) -> {device: (loss_w, count)}``: the loss of one device at the junction
    temperatures ``tj`` ({device: C}) and how many such devices share the sink; ``rth_k_w``
    {device: Rth_jc + Rth_cs}; ``tj_max_c`` {device: C}; exactly one of ``dt_sink_k`` (sink sized
    for the loss at this rise) and ``rth_sa_k_w`` (a given sink). Returns ``tj_c``, ``loss_w`` (per
    device), ``total_w``, ``t_sink_c`` and ``iterations``."""
    if (dt_sink_k is None) == (rth_sa_k_w is None):
        raise ValueError("give exactly one of dt_sink_k and rth_sa_k_w")
    if not (math.isfinite(t_amb_c) and -55.0 <= t_amb_c <= 200.0):   # NaN was reported as "vf0_v=nan"
        raise ValueError(f"t_amb_c={t_amb_c!r} is invalid; valid range: [-55, 200] C")
    for key, v in (("dt_sink_k", dt_sink_k), ("rth_sa_k_w", rth_sa_k_w)):
        if v is not None and not (math.isfinite(v) and v >= 0.0):
            raise ValueError(f"{key}={v!r} is invalid; valid range: [0, inf)")
    tj = dict.fromkeys(rth_k_w, 25.0)
    step_prev = math.inf
    for it in range(1, max_iter + 1):
        loss = losses_w(tj)
        total = sum(p * n for p, n in loss.values())
        t_sink = t_amb_c + (dt_sink_k if dt_sink_k is not None else total * rth_sa_k_w)
        new = {k: t_sink + loss[k][0] * rth_k_w[k] for k in tj}
        hot = [k for k in new if new[k] > tj_max_c[k]]
        if hot:
            k = hot[0]
            raise ThermalRunaway(f"junction of {k} reaches {new[k]:.0f} C > its maximum {tj_max_c[k]:.0f} C "
                                 f"(loss {loss[k][0]:.2f} W, sink {t_sink:.0f} C): thermal runaway / overload")
        step = max(abs(new[k] - tj[k]) for k in tj)
        tj = new
        if step < tol_k:
            return {"tj_c": tj, "loss_w": {k: v[0] for k, v in loss.items()}, "total_w": total, "t_sink_c": t_sink,
                    "iterations": it}
        if it > 3 and step > step_prev:
            raise ThermalRunaway(f"junction temperatures diverge (step {step:.2f} K after {it} iterations): "
                                 "the loss rises faster with temperature than the sink removes it")
        step_prev = step
    raise ThermalRunaway(f"junction temperatures did not settle within {max_iter} iterations")


def steady_junctions(name: str, params, d_short: float, t_amb_c: float = 40.0, dt_sink_k: float | None = 50.0,
                     rth_sa_k_w: float | None = None) -> dict:
    """Junction temperatures [C] of a preset's devices at a steady operating point (duty
    ``d_short`` on link ``params``), with the averaged models: the fundamental currents of eq. 4 with
    the devices folded in at the current temperatures, :func:`wpt_receiver.sbar.conduction_losses`
    and :func:`wpt_receiver.edge_losses.averaged_edge_losses`, per device (two rectifier diodes, two
    rectifier switches, four inverter switches on one sink; their capacitances charge-equivalent at the link's VL
    and Vdc, as :func:`wpt_receiver.devices.link_preset`). The result's ``tj_c`` can be given to
    the mission (``link.device_tj_c``) or an env (``EnvConfig.device_tj_c``). Returns
    :func:`settle_junctions`' dict plus ``i1_a``, ``i2_a``."""
    import numpy as np

    from .devices import DeviceSet, diode_from_row, envelope_params, parts, switch_from_row
    from .edge_losses import averaged_edge_losses
    from .envelope import steady_state
    from .sbar import conduction_losses
    try:
        d = float(d_short)
    except (TypeError, ValueError):   # a list, a string: one line, not float()'s message
        d = math.nan
    if not (math.isfinite(d) and 0.0 <= d <= 1.0):   # d = 2 gave temperatures, NaN "vf0_v=nan"
        raise ValueError(f"d_short={d_short!r} is out of range; valid range: [0, 1] (one number)")
    pr = parts()["preset"].get(name)
    if pr is None:
        raise ValueError(f"device preset {name!r} has no parts (valid: {', '.join(parts()['preset'])})")
    rows = {"rect_diode": parts()["diode"][pr["rect_diode"]], "rect_switch": parts()["switch"][pr["rect_switch"]],
            "inv_switch": parts()["switch"][pr["inv_switch"]]}
    state = {}

    def losses(tj):
        dv = DeviceSet(diode_from_row(rows["rect_diode"], 1, tj["rect_diode"], params.vl_v),   # (the capacitances
                       switch_from_row(rows["rect_switch"], 1, tj["rect_switch"], params.vl_v),  # at the link's own
                       switch_from_row(rows["inv_switch"], 1, tj["inv_switch"], params.vdc_v), name)  # VL and Vdc)
        v2 = 4 / np.pi * (params.vl_v + dv.rect_vf_v) * (1 - np.sin(0.5 * np.pi * d_short))
        i1, i2 = (float(abs(v)) for v in steady_state(envelope_params(params, dv), v2))
        c = conduction_losses(d_short, i1, i2, dv)
        e = averaged_edge_losses(d_short, i2, params.vl_v, dv, params.rectifier_period_s, params.omega_rad_s,
                                 vdc_v=params.vdc_v)
        state.update(i1_a=i1, i2_a=i2)
        return {"rect_diode": (float(c["rectifier_diodes"]) / 2, 2),
                "rect_switch": ((float(c["rectifier_switches"]) + e["rectifier_w"]) / 2, 2),
                "inv_switch": ((float(c["inverter_switches"]) + e["inverter_w"]) / 4, 4)}
    out = settle_junctions(losses, {k: r["rth_jc_k_w"] + r["rth_cs_k_w"] for k, r in rows.items()},
                           {k: r["tj_max_c"] for k, r in rows.items()}, t_amb_c, dt_sink_k=dt_sink_k,
                           rth_sa_k_w=rth_sa_k_w)
    return {**out, **state}
