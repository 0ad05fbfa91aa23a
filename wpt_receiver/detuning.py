"""Detuned series capacitors: the paper's stated limitation ("assumes the perfect resonance
condition"), quantified for the model-based controller.

C1 or C2 off its resonant value by a relative ``detuning`` (tolerance, temperature, a metal object
near the pad). The RM -> SM transition of a policy is run on

* the switching-level model (event-exact, instantaneous peaks), and
* the complex envelope model (:func:`wpt_receiver.envelope.simulate_complex`, both quadrature
  components; the SBAR's V2 follows the phase of i2), and
* the exact-mode envelope (:class:`wpt_receiver.modal.ModalEnvelope`: detuned modes, v2 from the
  harmonic balance, instantaneous peak),

with the controller designed on the nominal (tuned) model. Policies: ``step``, ``proposed`` (the
paper's controller with the nominal Lm) and ``proposed_online_lm``: the same controller built for
the Lm that the detuned link's measured RM current implies (what an online Lm estimator such as
:class:`policies.online.OnlineLmModelBasedPolicy` converges to before the switch: eq. 4's steady
state solved for Lm from the measured I2).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from .devices import IDEAL, DeviceSet
from .envelope import simulate_complex, steady_state
from .metrics import transition_metrics
from .modal import ModalEnvelope
from .params import LinkParams
from .references import reference_duty
from .sbar import v2_from_duty

__all__ = ["POLICIES", "detuned_capacitors", "lm_for_current", "detuning_row", "detuning_table"]

POLICIES = ("step", "proposed", "proposed_online_lm")


def detuned_capacitors(p: LinkParams, side: str, detuning: float) -> tuple[float, float]:
    """(C1, C2) [F] with ``side`` ('c1' or 'c2') scaled by ``1 + detuning``."""
    if side not in ("c1", "c2"):
        raise ValueError(f"side={side!r} is invalid; valid values: c1, c2")
    if not (math.isfinite(detuning) and -0.5 < detuning < 0.5):
        raise ValueError(f"detuning={detuning!r} is invalid; valid range: (-0.5, 0.5)")
    w = p.omega_rad_s
    c1, c2 = 1.0 / (w * w * p.l1_h), 1.0 / (w * w * p.l2_h)
    return (c1 * (1 + detuning), c2) if side == "c1" else (c1, c2 * (1 + detuning))


def lm_for_current(p: LinkParams, i2_a: float, v2_v: float) -> float:
    """The Lm [H] for which eq. 4's steady state gives ``i2_a`` at ``v2_v``: the larger-X root,
    above the X = w Lm that maximises ``I2 = (X V1 - R1 V2)/(R1 R2 + X^2)``."""
    v1, r1 = p.v1_amp_v, p.r1_ohm
    x_max = (r1 * v2_v + math.sqrt((r1 * v2_v) ** 2 + v1 * v1 * r1 * p.r2_ohm)) / v1
    lo, hi = x_max / p.omega_rad_s, 0.99 * math.sqrt(p.l1_h * p.l2_h)
    f = lambda lm: float(steady_state(p, v2_v, lm_h=lm)[1]) - i2_a  # noqa: E731
    if f(lo) * f(hi) > 0:
        raise ValueError(f"i2_a={i2_a!r} is not reachable by any Lm at V2 = {v2_v:.4g} V")
    return brentq(f, lo, hi, xtol=1e-15)


def _duties(policy, p, i2_rm_a, t_switch_s, t_end_s):
    """Duty per rectifier period of a policy; the online variant is built for the Lm that explains
    the measured RM current ``i2_rm_a`` (None when no Lm does)."""
    T = p.rectifier_period_s
    if policy == "proposed_online_lm":
        try:
            p = p.with_(lm_h=lm_for_current(p, i2_rm_a, p.v2_rm_amp_v))
        except ValueError:
            return None
        policy = "proposed"
    if policy not in ("step", "proposed"):
        raise ValueError(f"policy={policy!r} is invalid; valid values: {', '.join(POLICIES)}")
    return reference_duty(policy, p, t_switch_s, t_end_s, T)[1]


def _settled_rm(link, settle_s):
    """RM state after ``settle_s`` of RM from the periodic steady-state guess (a strongly detuned
    primary makes the rectifier conduct discontinuously; Newton shooting alone may not converge),
    and the RM fundamental of i2 over the last 8 periods."""
    T = link.T
    n = int(round(settle_s / T))
    res = link.run(link.schedule(0.0, n * T, 0.0), link.periodic_steady_state(0.0))
    env = res.envelope(res.t_end - 8 * T, res.t_end)
    x = link.final_state(res)
    return x, float(env["i2_fund_a"].mean())


def detuning_row(p: LinkParams, side: str, detuning: float, policy: str, t_switch_s: float = 1e-3,
                 t_end_s: float = 31e-3, devices: DeviceSet = IDEAL, settle_s: float = 20e-3,
                 modal: bool = True) -> dict:
    """One row: overshoot of the instantaneous peak (switching model), of the fundamental
    (switching model) and of the complex envelope model, for one side, detuning and policy. Both
    models first settle ``settle_s`` in RM on the detuned link; ``rm_i2_a`` is the RM fundamental
    there. The online-Lm row is NaN when no Lm explains the measured RM current. ``modal=False``
    leaves out the exact-mode envelope (:class:`ModalEnvelope`, a harmonic balance per period and
    most of the row's time): its two columns are NaN."""
    from .switching import SwitchingConfig, SwitchingLink
    c1, c2 = detuned_capacitors(p, side, detuning)
    T = p.rectifier_period_s
    link = SwitchingLink(p, SwitchingConfig(c1_f=c1, c2_f=c2, devices=devices))
    x0, i2_rm = _settled_rm(link, settle_s)
    row = {"side": side, "detuning_pct": 100 * detuning, "policy": policy, "rm_i2_a": i2_rm}
    d = _duties(policy, p, i2_rm, t_switch_s, t_end_s)
    if d is None:
        return {**row, **dict.fromkeys(_METRICS, float("nan"))}
    env = link.simulate(d, T, x0=x0).envelope()
    t = env["t_s"].to_numpy()
    peak = transition_metrics(t, env["i2_env_a"].to_numpy(), t_switch_s)
    fund = transition_metrics(t, env["i2_fund_a"].to_numpy(), t_switch_s)
    n_settle = int(round(settle_s / T)) * 4
    v2 = v2_from_duty(np.r_[np.zeros(n_settle), np.repeat(d, 4)], p.vl_v)
    tc, _, j2 = simulate_complex(p, v2, T / 4, c1, c2)
    keep = n_settle + 1
    cm = transition_metrics(tc[keep:] - tc[keep - 1], np.abs(j2[keep:]), t_switch_s)
    if i2_rm < _MIN_CONDUCTION_A or not modal:   # the diodes block in RM: the harmonic balance assumes conduction
        return {**row, **_switching_only(peak, fund, cm), "modal_overshoot_pct": float("nan"),
                "modal_peak_a": float("nan")}
    mo = ModalEnvelope(p, devices, c1, c2).run(d, T)
    mm = transition_metrics(mo["t_s"], mo["peak_i2_a"], t_switch_s)
    return {**row, **_switching_only(peak, fund, cm), "modal_overshoot_pct": mm.overshoot_pct,
            "modal_peak_a": mm.max_current_a}


_MIN_CONDUCTION_A = 0.1
"""Below this RM fundamental [A] the SBAR's diodes do not conduct in RM (a primary detuned by 5 %
at Table I: the induced emf stays below the clamp) and the exact-mode envelope is not computed."""


def _switching_only(peak, fund, cm) -> dict:
    return {"peak_i2_a": peak.max_current_a, "final_i2_a": peak.final_current_a,
            "overshoot_pct": peak.overshoot_pct, "fund_overshoot_pct": fund.overshoot_pct,
            "envelope_overshoot_pct": cm.overshoot_pct, "envelope_peak_a": cm.max_current_a,
            "fund_peak_a": fund.max_current_a}


_METRICS = ("peak_i2_a", "final_i2_a", "overshoot_pct", "fund_overshoot_pct", "envelope_overshoot_pct",
            "envelope_peak_a", "fund_peak_a", "modal_overshoot_pct", "modal_peak_a")


def detuning_table(p: LinkParams, detunings=(-0.05, -0.02, 0.0, 0.02, 0.05), sides=("c1", "c2"),
                   policies=POLICIES, devices: DeviceSet = IDEAL, progress=None, **kw) -> list[dict]:
    """Rows of :func:`detuning_row` for every side x detuning x policy."""
    rows = []
    for side in sides:
        for det in detunings:
            for pol in policies:
                rows.append(detuning_row(p, side, float(det), pol, devices=devices, **kw))
                if progress is not None:
                    progress()
    return rows
