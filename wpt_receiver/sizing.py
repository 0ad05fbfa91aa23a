"""Rectifier sizing: what the overshoot costs in current rating, devices and mass (the paper's claim).

For one drive policy (a duty sequence of the RM -> SM transition) the event-exact switching
model with real devices gives the instantaneous secondary current; from it:

* ``peak_i2_a``: worst-case instantaneous |i2| (exact peak, not the envelope's);
* device currents, as RMS over the worst ``window_s`` (1 ms by default, the order of a power
  device's junction-to-case thermal time constant): each SBAR upper diode carries i2 in its
  polarity's conduction intervals; each lower switch carries i2 while the SBAR is shorted plus
  its body diode's share in the other polarity;
* ``required_rating_a = margin * peak_i2_a``: the devices' continuous current rating must cover the
  peak, because the overshoot lasts milliseconds (thermally long for a die), with ``margin``
  (1.25 by default) for tolerances and ageing (``peak_i2_a`` is measured with the preset's devices for the
  rating, again with the chosen parts for the row); the voltage rating: ``v_margin`` (1.1) times the
  simulated open-load peak (below; it was 1.5 x the battery voltage before issue 23);
* the part: every shipped diode / switch (``parts.toml``) meeting the voltage rule, paralleled
  ``n = ceil(required / rating)`` times (paralleled dies divide Rd and Ron by n), and the
  combination with the smallest rectifier mass is chosen;
* ``conduction_loss_w``: the rectifier's conduction loss (upper diodes + lower switches) with the
  chosen parts, averaged over the worst ``window_s`` of the policy's run;
* ``mass_g``: two diode positions and two switch positions (n dies each; a dual package holds
  two positions' dies, typical package masses) plus an aluminium plate-fin heat sink that rejects ``conduction_loss_w`` at a
  sink-to-air temperature rise ``dt_sink_k`` with a convection coefficient ``h_w_m2k`` (forced
  air in the rotor downwash): fin area ``A = P / (h dT)``, fins of thickness ``fin_m`` cooled on
  both sides, mass ``rho t A / 2``. A stated first-order method, not a thermal design.

Issue 23 additions: the losses are settled at the junction temperatures
(:func:`wpt_receiver.thermal.settle_junctions`: sink at ``t_amb_c + dt_sink_k``, Rth junction-case
and case-sink from ``parts.toml``, R_DS(on) / Vf at Tj), the switching-edge energies of the run
(:func:`wpt_receiver.edge_losses.edge_energies`, worst ``window_s``) are added to the lower
switches, the sink is sized for conduction + switching, and the voltage rating is ``v_margin``
(1.1) times the simulated worst blocking voltage of the open-load fault
(:func:`wpt_receiver.switching.stress.voltage_stress`: battery opened in RM and at d = 0.5, shorted
after ``t_protect_s`` with ``c_out_f`` on the DC side) instead of a 1.5 x VL rule.

From a mission (an envelope run) instead, :func:`envelope_currents` gives the same quantities from
the averaged device model and the run's instantaneous peak estimate; :func:`select_parts` is the
part choice both use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .devices import V_BLOCK_V, DeviceSet, diode_from_row, parts, switch_from_row
from .params import LinkParams

__all__ = ["SizingRules", "rating_shortfall", "link_devices", "open_load_study", "rectifier_currents", "envelope_currents", "candidates", "size_policy", "select_parts",
           "paper_policy", "size_policies"]


@dataclass(frozen=True)
class SizingRules:
    """Margins and the heat-sink model (see the module docstring)."""

    margin: float = 1.25
    v_margin: float = 1.1
    window_s: float = 1e-3
    h_w_m2k: float = 40.0
    dt_sink_k: float = 50.0
    fin_m: float = 1e-3
    rho_kg_m3: float = 2700.0
    t_amb_c: float = 40.0
    t_protect_s: float = 1e-4
    c_out_f: float = 4.7e-3
    l_stray_h: float = 8e-9

    def __post_init__(self):
        for name in ("margin", "v_margin", "window_s", "h_w_m2k", "dt_sink_k", "fin_m", "rho_kg_m3", "t_protect_s",
                     "c_out_f", "l_stray_h"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}={v!r} is invalid; valid range: (0, inf)")
        if self.margin < 1.0:
            raise ValueError(f"margin={self.margin!r} is invalid; valid range: [1, inf)")

    def required_rating_a(self, peak_i2_a: float) -> float:
        """The continuous current rating [A] a rectifier part must have for a peak ``|i2|`` of ``peak_i2_a`` [A]:
        ``margin * peak_i2_a`` (module docstring; the one source of the rule: :func:`select_parts`, the mission's
        rating row, :func:`rating_shortfall`)."""
        return self.margin * float(peak_i2_a)

    def sink_mass_g(self, loss_w: float) -> float:
        """Plate-fin heat-sink mass [g] for a loss [W] (module docstring)."""
        area = max(loss_w, 0.0) / (self.h_w_m2k * self.dt_sink_k)
        return 1e3 * self.rho_kg_m3 * self.fin_m * area / 2.0


def _window_max(y, n):
    """Largest mean of ``y`` over ``n`` consecutive samples (``n`` clipped to the length)."""
    n = max(1, min(int(n), len(y)))
    c = np.concatenate([[0.0], np.cumsum(y)])
    return float(np.max(c[n:] - c[:-n]) / n)


def rating_shortfall(devices: str, peak_i2_a: float, rules: SizingRules = SizingRules()) -> dict | None:
    """How far the preset ``devices``' own rectifier parts (one leg / die per position,
    :func:`wpt_receiver.devices.current_rating`: the lowest of its diode leg's and switch's continuous rating) fall
    below the sizing rule for a peak ``|i2|`` of ``peak_i2_a`` [A] (:meth:`SizingRules.required_rating_a`):
    ``{"rating_a", "part", "position", "required_a", "shortfall_a", "shortfall_rel"}``, or None when the part meets
    the rule (or ``ideal``: no parts). The default mission: ``schottky``'s 30CTT045 (15 A per leg, the datasheet's
    I_F(AV)) at a 13.32 A peak: 16.64 A required, 1.64 A (11.0 % of its rating) short; :func:`select_parts` then parallels two
    legs per position (docs/devices.md, "The default preset against the rule")."""
    from .devices import current_rating
    held = current_rating(devices)
    if held is None:
        return None
    rating, part, position = held
    required = rules.required_rating_a(peak_i2_a)
    if rating >= required:
        return None
    return {"rating_a": float(rating), "part": part, "position": position, "required_a": required,
            "shortfall_a": required - rating, "shortfall_rel": (required - rating) / rating}


def rectifier_currents(res, window_s: float = 1e-3, per_half_cycle: int = 64) -> dict:
    """Peak |i2|, worst-window RMS / average diode and switch currents and the worst-window
    rectifier conduction loss [A, W] of a :class:`~wpt_receiver.switching.SwitchingResult`."""
    cir = res.circuit
    ts = res.sample_times(per_half_cycle)
    x, k = res.states(ts, cols=[2])
    i2 = x[:, 0]
    s = np.array([key[1] for key in cir.keys])[k]
    d1, d2 = np.where(s == 1, i2, 0.0), np.where(s == -1, -i2, 0.0)
    sh = np.where(s == 0, i2, 0.0)
    n = window_s / (ts[1] - ts[0])
    dv = cir.cfg.devices
    body, dd = dv.rect_switch.body, dv.rect_diode
    loss = ((dd.vf0_v + body.vf0_v) * (d1 + d2) + (dd.rd_ohm + body.rd_ohm) * (d1 * d1 + d2 * d2)
            + dv.short_r_ohm * sh * sh)
    from .edge_losses import edge_energies
    w = min(window_s, res.t_end - res.t0)
    starts = np.arange(res.t0, res.t_end - w + 1e-12, w / 4) if res.t_end - res.t0 > w else np.array([res.t0])
    sw_loss = max(edge_energies(res, a, a + w)["rect_j"] for a in starts) / w
    g = np.asarray(res.schedule.gate)
    t_off = np.asarray(res.schedule.t)[np.nonzero(np.diff(g) < 0)[0] + 1]
    i_off = float(np.max(np.abs(res.states(t_off - 1e-12 * cir.T, cols=[2])[0]))) if len(t_off) else 0.0
    # the refined half-cycle peaks, or the dense samples where the peak sits on a gate-edge kink
    return {"peak_i2_a": float(max(res.envelope()["i2_env_a"].max(), np.abs(i2).max())),
            "diode_rms_a": math.sqrt(max(_window_max(d1 * d1, n), _window_max(d2 * d2, n))),
            "diode_avg_a": max(_window_max(d1, n), _window_max(d2, n)),
            "switch_rms_a": math.sqrt(max(_window_max(sh * sh + d2 * d2, n), _window_max(sh * sh + d1 * d1, n))),
            "short_rms_a": math.sqrt(_window_max(sh * sh, n)), "switching_loss_w": sw_loss, "turn_off_peak_a": i_off,
            "conduction_loss_w": _window_max(loss, n)}


def candidates(required_a: float, v_min_v: float, kind: str) -> list[dict]:
    """Shipped parts of ``kind`` ('diode' or 'switch') with voltage rating >= ``v_min_v``, each
    with the number ``n`` in parallel that carries ``required_a``."""
    out = []
    for row in parts()[kind].values():
        if row["v_rating_v"] >= v_min_v:
            n = max(1, math.ceil(required_a / row["rating_a"] - 1e-12))
            out.append({**row, "n": n})
    if not out:
        raise ValueError(f"no {kind} in parts.toml is rated for {v_min_v:.4g} V")
    return out


def _paralleled(base: DeviceSet, diode: dict, switch: dict, tj=None, v_block_v: float = V_BLOCK_V) -> DeviceSet:
    """The rectifier built from ``n`` paralleled dies of each part (inverter kept from ``base``),
    at junction temperatures ``tj = (diode C, switch C)`` (``None``: the table's values), blocking ``v_block_v`` [V]
    (the link's VL: their charge-equivalent capacitances)."""
    nd, ns = diode["n"], switch["n"]
    td, ts = (None, None) if tj is None else tj
    return DeviceSet(diode_from_row(diode, nd, td, v_block_v), switch_from_row(switch, ns, ts, v_block_v),
                     base.inv_switch, f"{diode['name']}x{nd}/{switch['name']}x{ns}")


def settle_losses(cur: dict, diode: dict, switch: dict, base: DeviceSet, rules: "SizingRules",
                  v_block_v: float = V_BLOCK_V) -> dict:
    """Junction temperatures and losses of one rectifier (two diode positions of ``diode["n"]``
    legs, two switch positions of ``switch["n"]`` dies) for the currents ``cur``
    (:func:`rectifier_currents` keys): per position ``P_d = Vf0(Tj) I_avg + Rd(Tj) I_rms^2`` and
    ``P_s = Vf0_body(Tj) I_avg + Rd_body I_rms^2 + Ron(Tj) I_short^2 + switching / 2``, settled by
    :func:`wpt_receiver.thermal.settle_junctions` on a sink at ``t_amb_c + dt_sink_k``; ``v_block_v`` [V]: the
    link's VL (:func:`_paralleled`)."""
    from .thermal import settle_junctions
    nd, ns = diode["n"], switch["n"]
    ia, ir2 = cur["diode_avg_a"], cur["diode_rms_a"] ** 2
    sh2 = cur.get("short_rms_a", 0.0) ** 2
    p_sw = 0.5 * cur.get("switching_loss_w", 0.0)

    def losses(tj):
        dv = _paralleled(base, diode, switch, (tj["diode"], tj["switch"]), v_block_v)
        d, s = dv.rect_diode, dv.rect_switch
        pd = d.vf0_v * ia + d.rd_ohm * ir2
        ps = s.body.vf0_v * ia + s.body.rd_ohm * ir2 + s.ron_ohm * sh2 + p_sw
        return {"diode": (pd / nd, 2 * nd), "switch": (ps / ns, 2 * ns)}
    out = settle_junctions(losses, {"diode": diode["rth_jc_k_w"] + diode["rth_cs_k_w"],
                                    "switch": switch["rth_jc_k_w"] + switch["rth_cs_k_w"]},
                           {"diode": diode["tj_max_c"], "switch": switch["tj_max_c"]}, rules.t_amb_c,
                           dt_sink_k=rules.dt_sink_k)
    total = out["total_w"]
    return {"tj_diode_c": out["tj_c"]["diode"], "tj_switch_c": out["tj_c"]["switch"],
            "conduction_loss_w": total - 2 * p_sw, "switching_loss_w": 2 * p_sw, "loss_w": total,
            "thermal_iterations": out["iterations"]}


def link_devices(base, params: LinkParams) -> DeviceSet:
    """The device set the sizing runs ``params`` with: ``base`` a preset's name (``"schottky"``: the natural call) is
    :func:`wpt_receiver.devices.link_preset` on the link, the capacitances at its VL and Vdc; a
    :class:`~wpt_receiver.devices.DeviceSet` is taken as given, with a :class:`~wpt_receiver.notices.DronewptWarning`
    when it is a preset's at Table I's 30 V (``preset(name)``) on a link with another VL or Vdc (its capacitances,
    so the edge energies and the open-load study, would be 30 V's: pass the name, or ``link_preset(name, params)``)."""
    from .devices import IDEAL, link_preset, preset, preset_names
    if isinstance(base, str):
        return link_preset(base, params)
    if (base != IDEAL and base.name in preset_names() and (params.vl_v, params.vdc_v) != (V_BLOCK_V, V_BLOCK_V)
            and base == preset(base.name)):
        from .notices import warn
        warn(f"devices {base.name!r} have their capacitances at Table I's {V_BLOCK_V:g} V, the link blocks VL = "
             f"{params.vl_v:g} V, Vdc = {params.vdc_v:g} V; pass the preset's name {base.name!r} or "
             f"link_preset({base.name!r}, params)")
    return base


def size_policy(run, params: LinkParams, base, rules: SizingRules = SizingRules()) -> dict:
    """Size the rectifier for one policy. ``run(devices) -> SwitchingResult`` simulates the
    policy's duty sequence with a device set; ``base``: a preset's name or a device set (:func:`link_devices`).
    Returns the row of the sizing table."""
    return select_parts(lambda dv: rectifier_currents(run(dv), rules.window_s), params, base, rules)


def select_parts(measure, params: LinkParams, base, rules: SizingRules = SizingRules(),
                 v_worst_v: float | None = None) -> dict:
    """The lightest rectifier for ``measure(devices) -> currents`` (the keys of
    :func:`rectifier_currents`): rating = margin x the peak measured with ``base``, voltage rating
    >= ``v_margin`` x the simulated worst blocking voltage (``v_worst_v``; default: the open-load
    study of :func:`wpt_receiver.switching.stress.voltage_stress`; the ring of the largest hard
    turn-off with ``l_stray_h`` is reported as ``edge_ring_peak_v``, not rated: see the docs), every combination of shipped
    parts meeting both (their capacitances charge-equivalent at ``params.vl_v``), losses settled at the junction
    temperatures (:func:`settle_losses`), mass =
    devices + heat sink for conduction + switching loss. A combination whose junctions run away is
    skipped (``thermal_rejected`` counts them). ``base``: a preset's name or a device set (:func:`link_devices`)."""
    from .thermal import ThermalRunaway
    base = link_devices(base, params)
    first = measure(base)
    required = rules.required_rating_a(first["peak_i2_a"])
    stress = None
    if v_worst_v is None:
        stress = _stress(params, base, rules, first)
        v_worst_v = stress["v_worst_v"]
    v_min = rules.v_margin * v_worst_v
    best, rejected = None, 0
    for dio in candidates(required, v_min, "diode"):
        for sw in candidates(required, v_min, "switch"):
            dev_mass = 2 * dio["n"] * dio["mass_g"] / dio["legs"] + 2 * sw["n"] * sw["mass_g"] / sw["legs"]
            if best is not None and dev_mass >= best["mass_g"]:
                continue  # the sink only adds: cannot beat the best
            dv = _paralleled(base, dio, sw, v_block_v=params.vl_v)
            cur = measure(dv)
            try:
                th = settle_losses(cur, dio, sw, base, rules, params.vl_v)
            except ThermalRunaway:
                rejected += 1
                continue
            mass = dev_mass + rules.sink_mass_g(th["loss_w"])
            if best is None or mass < best["mass_g"]:
                best = {**cur, **th, "conduction_loss_table_w": cur["conduction_loss_w"], "required_rating_a": required,
                        "part": dv.name, "mass_g": mass, "device_mass_g": dev_mass, "sink_mass_g": mass - dev_mass,
                        "devices": dv, "v_worst_v": v_worst_v, "required_v_rating_v": v_min}
    if best is None:
        raise ValueError(f"no combination of shipped parts carries {required:.3g} A at {v_min:.3g} V without "
                         f"thermal runaway ({rejected} rejected)")
    best["thermal_rejected"] = rejected
    if stress is not None:
        best["v_case"] = stress["case"]
        best["edge_ring_peak_v"] = stress["ring"]["peak_v"]
        best["turn_off_peak_a"] = first.get("turn_off_peak_a", 0.0)
    return best


def open_load_study(params: LinkParams, base, rules: SizingRules = SizingRules()) -> dict:
    """The open-load voltage study the sizing rates against (cached per link, devices and rules):
    :func:`wpt_receiver.switching.stress.voltage_stress` without the edge ring; ``base``: a preset's name or a device
    set (:func:`link_devices`)."""
    return _stress(params, link_devices(base, params), rules, {})


def _stress(params: LinkParams, base: DeviceSet, rules: SizingRules, cur: dict) -> dict:
    """Open-load voltage study of ``base`` (cached per link, devices and rules: it is the same for
    every policy). The edge ring at the peak current is reported, not rated (see the docs)."""
    key = (params, base, rules.t_protect_s, rules.c_out_f, rules.l_stray_h)
    if key not in _STRESS:
        from .switching.stress import voltage_stress
        _STRESS[key] = voltage_stress(params, base, rules.t_protect_s, rules.c_out_f, rules.l_stray_h, 0.0)
    out = dict(_STRESS[key])
    from .switching.stress import edge_turn_off_transient
    sw, dio = base.rect_switch, base.rect_diode
    out["ring"] = edge_turn_off_transient(cur.get("turn_off_peak_a", 0.0), params.vl_v + base.rect_vf_v,
                                          sw.coss_f + dio.c_f, rules.l_stray_h, dio.rd_ohm + sw.body.rd_ohm,
                                          2 * sw.eoff_j_va)
    out["cases"] = {k: v for k, v in out["cases"].items() if k != "edge ring"}
    out["case"] = max(out["cases"], key=out["cases"].get)
    out["v_worst_v"] = out["cases"][out["case"]]
    return out


_STRESS: dict = {}


def _window_mean_max(t_end_s, dt_s, y, window_s: float) -> float:
    """Largest mean of the step-wise constant ``y`` (value ``y[i]`` over ``(t_end - dt, t_end]``)
    over any window of ``window_s`` ending at a step end (exact for piecewise-constant data; the
    whole run when it is shorter)."""
    t_end, y = np.asarray(t_end_s, dtype=float), np.asarray(y, dtype=float)
    t = np.r_[t_end[0] - dt_s[0], t_end]
    c = np.r_[0.0, np.cumsum(y * np.asarray(dt_s, dtype=float))]
    w = min(window_s, t[-1] - t[0])
    ends = t[t >= t[0] + w - 1e-12]
    return float(np.max((np.interp(ends, t, c) - np.interp(ends - w, t, c)) / w))


def envelope_currents(t_end_s, dt_s, d_short, i1_amp_a, i2_amp_a, peak_i2_a: float, devices: DeviceSet,
                      window_s: float = 1e-3, *, vl_v, f_hz: float) -> dict:
    """:func:`rectifier_currents` from an envelope run (a mission's time series: one row per step,
    values at the step's end held over the step): with ``w`` = the short window's share of
    ``<i2^2>`` (:func:`wpt_receiver.sbar.short_weight`), an upper diode carries ``<i^2> =
    (I2^2/2)(1 - w)/2`` and ``<i> = I_L/2``, a lower switch the short, ``(I2^2/2) w``, plus its body
    diode's half; the loss is :func:`wpt_receiver.sbar.conduction_losses` (rectifier groups).
    ``peak_i2_a`` is the run's instantaneous peak (e.g. the mission's ``peak_i2_a``). ``vl_v`` [V] (a number or
    one per step, e.g. the mission's ``battery_v``) and ``f_hz`` [Hz] are the run's battery voltage and inverter
    frequency, for the SBAR's edge energies (:func:`wpt_receiver.edge_losses.averaged_edge_losses`; they were Table
    I's 30 V and 85 kHz whatever the run's link until 2026-11-27 night)."""
    from .params import positive_number, positive_numbers
    from .sbar import conduction_losses, rectifier_current, short_weight
    d, i2 = np.asarray(d_short, dtype=float), np.asarray(i2_amp_a, dtype=float)
    vl_v = positive_numbers("vl_v", vl_v, "V", size=np.size(t_end_s))   # (a number, or one per step)
    f_hz = positive_number("f_hz", f_hz, "Hz")
    w, sq = short_weight(d), 0.5 * i2 * i2
    loss = conduction_losses(d, np.asarray(i1_amp_a, dtype=float), i2, devices)
    args = (t_end_s, dt_s)
    return {"peak_i2_a": float(peak_i2_a),
            "diode_rms_a": math.sqrt(_window_mean_max(*args, 0.5 * sq * (1 - w), window_s)),
            "diode_avg_a": _window_mean_max(*args, 0.5 * rectifier_current(d, np.abs(i2)), window_s),
            "switch_rms_a": math.sqrt(_window_mean_max(*args, sq * w + 0.5 * sq * (1 - w), window_s)),
            "short_rms_a": math.sqrt(_window_mean_max(*args, sq * w, window_s)),
            "switching_loss_w": _window_mean_max(*args, _edge_w(d, i2, devices, vl_v, f_hz), window_s),
            "conduction_loss_w": _window_mean_max(*args, loss["rectifier_diodes"] + loss["rectifier_switches"],
                                                  window_s)}


def _edge_w(d, i2, devices, vl_v, f_hz: float):
    """Averaged SBAR edge power [W] (:func:`wpt_receiver.edge_losses.averaged_edge_losses`) along an envelope run
    at battery voltage ``vl_v`` [V] (a number or one per step) and inverter frequency ``f_hz`` [Hz]."""
    from .edge_losses import averaged_edge_losses
    from .params import TABLE_I
    link = TABLE_I.with_(f_hz=f_hz)   # (its periods at f_hz: one source of T and omega; f_hz checked before)
    return averaged_edge_losses(d, i2, vl_v, devices, link.rectifier_period_s, link.omega_rad_s)["rectifier_w"]


def paper_policy(name: str, params: LinkParams, t_switch_s: float = 1e-3, t_end_s: float = 10e-3):
    """``run(devices)`` for one of the paper's transitions (``step``, ``ramp``, ``proposed``: the
    RM -> SM switch at ``t_switch_s`` with one duty per rectifier period), simulated from the
    periodic RM steady state by the switching model with ``devices``."""
    from .references import reference_duty
    from .switching import SwitchingConfig, SwitchingLink
    T = params.rectifier_period_s
    _, d, _ = reference_duty(name, params, t_switch_s, t_end_s, T)
    cache = {}

    def run(devices: DeviceSet):
        if devices not in cache:
            cache[devices] = SwitchingLink(params, SwitchingConfig(devices=devices)).simulate(d, T)
        return cache[devices]
    return run


def size_policies(names, params: LinkParams, base, rules: SizingRules = SizingRules(),
                  t_switch_s: float = 1e-3, t_end_s: float = 10e-3, progress=None) -> list[dict]:
    """Sizing rows (:func:`size_policy`) for the paper's transitions ``names`` on the link ``params`` with the devices
    ``base``: a preset's name (``size_policies(names, my_link, "schottky")``: the preset on the link,
    :func:`wpt_receiver.devices.link_preset`) or a device set (a Table I ``preset(name)`` on another link warns:
    :func:`link_devices`, in :func:`select_parts`); ``progress`` is an optional callable advanced once per policy."""
    rows = []
    for name in names:
        row = size_policy(paper_policy(name, params, t_switch_s, t_end_s), params, base, rules)
        rows.append({"policy": name, **row})
        if progress is not None:
            progress()
    return rows
