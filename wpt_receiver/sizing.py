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
  (1.25 by default) for tolerances and ageing; the voltage rating must be ``v_margin`` (1.5) times
  the battery voltage;
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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .devices import DeviceSet, Diode, Switch, parts
from .params import LinkParams

__all__ = ["SizingRules", "rectifier_currents", "candidates", "size_policy", "paper_policy", "size_policies"]


@dataclass(frozen=True)
class SizingRules:
    """Margins and the heat-sink model (see the module docstring)."""

    margin: float = 1.25
    v_margin: float = 1.5
    window_s: float = 1e-3
    h_w_m2k: float = 40.0
    dt_sink_k: float = 50.0
    fin_m: float = 1e-3
    rho_kg_m3: float = 2700.0

    def __post_init__(self):
        for name in ("margin", "v_margin", "window_s", "h_w_m2k", "dt_sink_k", "fin_m", "rho_kg_m3"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}={v!r} is invalid; valid range: (0, inf)")
        if self.margin < 1.0:
            raise ValueError(f"margin={self.margin!r} is invalid; valid range: [1, inf)")

    def sink_mass_g(self, loss_w: float) -> float:
        """Plate-fin heat-sink mass [g] for a loss [W] (module docstring)."""
        area = max(loss_w, 0.0) / (self.h_w_m2k * self.dt_sink_k)
        return 1e3 * self.rho_kg_m3 * self.fin_m * area / 2.0


def _window_max(y, n):
    """Largest mean of ``y`` over ``n`` consecutive samples (``n`` clipped to the length)."""
    n = max(1, min(int(n), len(y)))
    c = np.concatenate([[0.0], np.cumsum(y)])
    return float(np.max(c[n:] - c[:-n]) / n)


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
    return {"peak_i2_a": float(res.envelope()["i2_env_a"].max()),
            "diode_rms_a": math.sqrt(max(_window_max(d1 * d1, n), _window_max(d2 * d2, n))),
            "diode_avg_a": max(_window_max(d1, n), _window_max(d2, n)),
            "switch_rms_a": math.sqrt(max(_window_max(sh * sh + d2 * d2, n), _window_max(sh * sh + d1 * d1, n))),
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


def _paralleled(base: DeviceSet, diode: dict, switch: dict) -> DeviceSet:
    """The rectifier built from ``n`` paralleled dies of each part (inverter kept from ``base``)."""
    nd, ns = diode["n"], switch["n"]
    return DeviceSet(Diode(diode["vf0_v"], diode["rd_ohm"] / nd),
                     Switch(switch["ron_ohm"] / ns, Diode(switch["body_vf0_v"], switch["body_rd_ohm"] / ns)),
                     base.inv_switch, f"{diode['name']}x{nd}/{switch['name']}x{ns}")


def size_policy(run, params: LinkParams, base: DeviceSet, rules: SizingRules = SizingRules()) -> dict:
    """Size the rectifier for one policy. ``run(devices) -> SwitchingResult`` simulates the
    policy's duty sequence with a device set. Returns the row of the sizing table."""
    first = rectifier_currents(run(base), rules.window_s)
    required = rules.margin * first["peak_i2_a"]
    v_min = rules.v_margin * params.vl_v
    best = None
    for dio in candidates(required, v_min, "diode"):
        for sw in candidates(required, v_min, "switch"):
            dev_mass = 2 * dio["n"] * dio["mass_g"] / dio["legs"] + 2 * sw["n"] * sw["mass_g"] / sw["legs"]
            if best is not None and dev_mass >= best["mass_g"]:
                continue  # the sink only adds: cannot beat the best
            dv = _paralleled(base, dio, sw)
            cur = rectifier_currents(run(dv), rules.window_s)
            mass = dev_mass + rules.sink_mass_g(cur["conduction_loss_w"])
            if best is None or mass < best["mass_g"]:
                best = {**cur, "required_rating_a": required, "part": dv.name, "mass_g": mass,
                        "device_mass_g": dev_mass, "sink_mass_g": mass - dev_mass, "devices": dv}
    return best


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


def size_policies(names, params: LinkParams, base: DeviceSet, rules: SizingRules = SizingRules(),
                  t_switch_s: float = 1e-3, t_end_s: float = 10e-3, progress=None) -> list[dict]:
    """Sizing rows (:func:`size_policy`) for the paper's transitions ``names``; ``progress`` is an
    optional callable advanced once per policy."""
    rows = []
    for name in names:
        row = size_policy(paper_policy(name, params, t_switch_s, t_end_s), params, base, rules)
        rows.append({"policy": name, **row})
        if progress is not None:
            progress()
    return rows
