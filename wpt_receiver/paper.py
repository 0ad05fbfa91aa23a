"""The paper's simulation section (Fig. 6, Table II) as a reusable scenario.

The link starts at its RM steady state, the transition starts at ``t_switch_s`` and the window
runs to ``t_end_s``. Each trajectory gives a duty sequence on the controller's grid; a *plant
model* turns duties into current envelopes. :data:`MODELS` names them: the envelope model
(built in) and the switching-level model (:mod:`.switching`, imported on first use).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import math

import numpy as np

from .envelope import simulate, steady_state
from .inverse_controller import LowPassFilter
from .metrics import TransitionMetrics, transition_metrics
from .notices import warn
from .params import TABLE_I, LinkParams, warn_off_resonance
from .references import TRAJECTORIES, reference_duty
from .sbar import v2_from_duty

__all__ = ["PAPER_TABLE_II", "PaperRun", "MODELS", "envelope_plant", "modal_plant", "run_paper", "rm_emf_margin",
           "modal_range_problem", "MODAL_MIN_EMF_MARGIN", "MODAL_MIN_VOLTAGE_RATIO", "envelope_range_problem"]

#: Table II of the paper: trajectory -> (maximum current amplitude [A], overshoot [%]).
PAPER_TABLE_II = {"step": (49.1, 368.0), "ramp": (11.4, 8.6), "proposed": (10.5, 0.0)}


@dataclass
class PaperRun:
    trajectory: str
    t_s: np.ndarray          # time grid of the envelope outputs
    v2_ref_v: np.ndarray     # V2* on the control grid (same grid as t_ctrl_s)
    t_ctrl_s: np.ndarray
    d_short: np.ndarray
    i1_a: np.ndarray
    i2_a: np.ndarray
    v2_v: np.ndarray         # fundamental of v2 applied by the plant
    metrics: TransitionMetrics
    sim_wall_s: float = 0.0
    extra: dict = field(default_factory=dict)


def envelope_plant(params: LinkParams, d_short: np.ndarray, control_period_s: float, substeps: int = 4):
    """Envelope model driven by a duty per control period (V2 = f(d), eq. 9).

    Returns a dict with ``t_s, i1_a, i2_a, v2_v`` on a grid ``control_period_s / substeps``; the
    run starts at the steady state of the first duty.
    """
    v2 = np.repeat(v2_from_duty(np.asarray(d_short, dtype=float), params.vl_v), substeps)
    t, i1, i2 = simulate(params, v2, control_period_s / substeps)
    return {"t_s": t, "i1_a": i1, "i2_a": i2, "v2_v": np.append(v2, v2[-1])}


def _switching_plant(params: LinkParams, d_short: np.ndarray, control_period_s: float):
    """The switching-level model (:func:`wpt_receiver.switching.switching_plant`), imported on first use."""
    from .switching.plant import switching_plant
    return switching_plant(params, d_short, control_period_s)


def modal_plant(params: LinkParams, d_short: np.ndarray, control_period_s: float):
    """The exact-mode envelope with the SBAR's balanced v2, compiled (:func:`wpt_receiver.modal_kernel.simulate`,
    imported on first use; within 0.1 % of the switching model's peaks on the three trajectories at Table I; on a
    link whose envelope beats fast, k ~ 0.2-0.25, the step's peak differs by 1-2 % (it depends on where in the
    carrier cycle the SBAR shorts, which an envelope does not resolve), the ramp and proposed within 0.3 %:
    docs/robustness.md, "Own links (2026-11-27 night)").

    Like the switching plant, ``i2_a`` is the instantaneous peak |i2| [A] (fundamental + ripple) per
    control period, ``i2_fund_a`` the fundamental's amplitude, ``v2_v`` the fundamental of v2 in
    phase with i2 [V], ``i1_a`` |I1| [A]."""
    from .modal_kernel import simulate as simulate_compiled
    reason = modal_range_problem(params)
    if reason is not None:
        warn(reason)   # (pointed at the caller outside dronewpt: run_paper's, or modal_plant's own)
    # the SBAR's v2 is updated at least twice a rectifier period whatever the control period (the kernel's
    # default 2 sub-steps per control period rang up to 187 A at 2e-4 s on Table I)
    substeps = max(2, 2 * math.ceil(control_period_s / params.rectifier_period_s - 1e-9))
    out = simulate_compiled(params, d_short, control_period_s, substeps=substeps)
    i2 = out["i2"]
    fund = np.abs(i2)
    v2_in_phase = np.real(out["v2"] * np.conj(i2)) / np.where(fund > 0, fund, 1.0)
    return {"t_s": out["t_s"], "i1_a": np.abs(out["i1"]), "i2_a": out["peak_i2_a"], "v2_v": v2_in_phase,
            "i2_fund_a": fund}


#: :func:`modal_range_problem`'s limits. Against the switching model (ramp trajectory; RM I2 / peak / battery energy):
#: the emf margin matters only close to blocking (Lm 0.42 uH, M = 2.08: 0.0 / 0.0 / +0.2 %; f 5 kHz, M = 1.82: the
#: RM steady state +45 %; Lm 0.25 uH, M = 1.24: 195 A against 45.7 A), the voltage ratio where the clamp is high
#: against V1 (Vdc/VL = 0.32: -0.0 / -0.4 / -0.4 %; 0.25-0.26: +0.0 / +2 / -1.2 %; 0.20: +0.5 / +1.5 / -3.4 %; 0.13:
#: +4.4 / +5.5 / -31 %; docs/robustness.md, "A power-electronics researcher's pass")
MODAL_MIN_EMF_MARGIN = 2.0
MODAL_MIN_VOLTAGE_RATIO = 0.25


def rm_emf_margin(params: LinkParams) -> float:
    """``w Lm V1 / (R1 (4/pi) VL)`` [-]: eq. 4's V2 that holds I2 at 0 (the rectifier blocks) over the RM clamp
    ``(4/pi) VL``. Below 1 the tuned link cannot conduct in RM; ``1/M`` is about the share of V1 lost on R1.
    Table I: 30.9. The tuned, ideal-device case of :func:`wpt_receiver.rm_state.rm_steady`'s ``clamp_margin``
    (computed there: one source for both; that module alone, not the tolerance study that re-exports it)."""
    from .rm_state import rm_steady
    return float(rm_steady(params, None, None)["clamp_margin"])


def modal_range_problem(params: LinkParams, remedy="use model='switching'") -> str | None:
    """Why the exact-mode model (:func:`modal_plant`, the missions' and envs' link) is outside the range where it
    was checked against the switching model, or None (Table I: emf margin 30.9, Vdc/VL 1). ``remedy`` ends the
    message (what to do: the missions and envs, which have no switching model, name their own keys): a string,
    or ``remedy(limit)`` for the limit that failed, ``"emf_margin"`` or ``"voltage_ratio"`` (a remedy for the one
    that failed: a lower hover gap raises the emf margin, not Vdc/VL). The one source of these limits for
    ``paper``, the missions (:mod:`mission_sim.setup_warnings`) and the envs."""
    m, ratio = rm_emf_margin(params), params.vdc_v / params.vl_v
    if m < MODAL_MIN_EMF_MARGIN:
        return (f"emf margin wLm V1 / (R1 (4/pi) VL) = {m:.3g} is below the exact-mode model's checked range "
                f"(>= {MODAL_MIN_EMF_MARGIN:g}; Table I: 30.9): this close to the rectifier's blocking point its RM "
                f"state departs from the switching model's; {remedy('emf_margin') if callable(remedy) else remedy}")
    if ratio < MODAL_MIN_VOLTAGE_RATIO:
        return (f"vdc_v / vl_v = {ratio:.3g} is below the exact-mode model's checked range (>= "
                f"{MODAL_MIN_VOLTAGE_RATIO:g}; Table I: 1): with the clamp this high against V1 its battery energy is "
                f"low against the switching model (-3 % at 0.2, -31 % at 0.13); "
                f"{remedy('voltage_ratio') if callable(remedy) else remedy}")
    return None


def envelope_range_problem(params: LinkParams) -> str | None:
    """Why eq. 4's envelope (:func:`envelope_plant`) gives no physical RM state on this link, or None: below an emf
    margin of 1 (:func:`rm_emf_margin`) the rectifier blocks in RM, and the linear envelope with V2 = (4/pi) VL held
    gives a negative I2 (the battery driving the coil; ``--link vdc_v=1 --link vl_v=1000``: RM -11.96 A, a "step
    peak" of 1,303 A), which the SBAR's diodes cannot."""
    m = rm_emf_margin(params)
    if m >= 1.0:
        return None
    i2 = float(steady_state(params, params.v2_rm_amp_v)[1])
    return (f"emf margin wLm V1 / (R1 (4/pi) VL) = {m:.3g} is below 1: the rectifier blocks in RM, where eq. 4's "
            f"envelope with V2 = (4/pi) VL held gives I2 = {i2:.4g} A < 0 (the battery driving the coil, which the "
            "SBAR's diodes cannot); use model='switching'")


#: plant models: name -> callable(params, d_short, control_period_s) -> dict(t_s, i1_a, i2_a, v2_v, ...)
MODELS: dict[str, Callable] = {"envelope": envelope_plant, "switching": _switching_plant, "modal": modal_plant}


def run_paper(params: LinkParams = TABLE_I, model: str = "envelope", t_switch_s: float = 1e-3,
              t_end_s: float = 31e-3, control_period_s: float | None = None,
              lpf: LowPassFilter = LowPassFilter(), trajectories=TRAJECTORIES, ramp_kind: str = "v2") -> list[PaperRun]:
    """Run the step, ramp and proposed V2* trajectories (RM -> SM at ``t_switch_s``) through plant ``model``;
    one :class:`PaperRun` per trajectory (time series in s, A, V; ``metrics``: Table II's columns).

    ``params``: the link (Table I by default; SI units: H, ohm, V, Hz). ``model``: ``"envelope"`` (eq. 4, the
    fundamental only; the default here, for the closed forms), ``"modal"`` (exact modes + the SBAR ripple: the
    instantaneous peak Table II measures; ``dronewpt paper``'s default) or ``"switching"`` (the circuit, slow).
    ``t_switch_s`` / ``t_end_s``: the switch and the window's end [s] (defaults 1 ms, 31 ms). ``control_period_s``:
    the controller's update period [s] (default the rectifier period 1/(2 f)). ``lpf``: the proposed controller's
    low-pass Q (time constant [s], order). ``trajectories``: a subset of ``("step", "ramp", "proposed")`` (one name
    alone is taken as one trajectory). ``ramp_kind``: ``"v2"`` ramps V2* (the paper's Fig. 6b), ``"duty"`` d_short.
    The proposed trajectory is the paper's controller: the I2 reference (RM -> SM step) low-passed by Q, through
    G22^-1 (eq. 8) to V2* and eq. 9's f^-1 to the duty. Warns (:class:`~wpt_receiver.notices.DronewptWarning`) when the link is outside a model's
    checked range or I2 has not settled by ``t_end_s``."""
    import time

    if isinstance(trajectories, str):   # ("step" iterated as 's', 't', ...: "trajectory='s' is invalid")
        trajectories = (trajectories,)

    if model not in MODELS:
        raise ValueError(f"model={model!r} is invalid; valid values: {', '.join(sorted(MODELS))}")
    period = params.rectifier_period_s if control_period_s is None else float(control_period_s)
    warn_off_resonance(params)   # (first: a far-off f_hz is often why the range warnings below fire)
    reason = envelope_range_problem(params) if model == "envelope" else None
    if reason is not None:
        warn(reason)
    runs = []
    for name in trajectories:
        t_ctrl, d, v2_ref = reference_duty(name, params, t_switch_s, t_end_s, period, lpf, ramp_kind)
        t0 = time.perf_counter()
        out = MODELS[model](params, d, period)
        wall = time.perf_counter() - t0
        m = transition_metrics(out["t_s"], out["i2_a"], t_switch_s, out["i1_a"], out["v2_v"],
                               i2_fund_a=out.get("i2_fund_a"))
        extra = {k: v for k, v in out.items() if k not in ("t_s", "i1_a", "i2_a", "v2_v")}
        runs.append(PaperRun(name, out["t_s"], v2_ref, t_ctrl, d, out["i1_a"], out["i2_a"], out["v2_v"], m, wall, extra))
        problem = None
        if not np.isfinite(m.settling_time_s):   # t_end_s = 3 ms: "final" 0.69 A mid-ring, overshoot 7,220 %
            problem = (f"{name}: I2 has not settled within 2 % by t_end_s={t_end_s!r}: its final_current_a "
                       f"({m.final_current_a:.4g} A) and overshoot_pct are not steady values; valid: a longer "
                       "window (default 31e-3 s)")
        elif model == "modal":
            problem = _modal_inconsistency(params, name, d, out, m)
        if problem is not None:
            warn(problem)
    return runs


#: :func:`_modal_inconsistency`'s tolerance on the RM start and the SM end against their closed forms (within 0.2 %
#: where the exact-mode model agrees with the switching model; 2-330 % where it does not)
MODAL_CHECK_RTOL = 0.02


def _modal_inconsistency(params: LinkParams, name: str, d, out: dict, m: TransitionMetrics) -> str | None:
    """What an exact-mode run gets physically wrong, checked after the fact (the run itself can leave the range
    where the model was checked in ways :func:`modal_range_problem` does not foresee): its RM start against eq.
    4-5's RM steady state, its short-mode end against the (exact, linear) short-mode phasor solution, and a
    negative battery energy (a diode rectifier cannot feed the coil). None when all hold."""
    from .envelope import steady_state
    fund = np.asarray(out["i2_fund_a"])
    rm, sm = float(steady_state(params, params.v2_rm_amp_v)[1]), float(steady_state(params, 0.0)[1])
    what = []
    if d[0] == 0.0 and rm > 0 and abs(fund[0] / rm - 1) > MODAL_CHECK_RTOL:
        what.append(f"its RM start {fund[0]:.4g} A against eq. 4-5's {rm:.4g} A")
    if d[-1] == 1.0 and abs(fund[-1] / sm - 1) > MODAL_CHECK_RTOL:
        what.append(f"its short-mode end {fund[-1]:.4g} A against the short-mode steady state {sm:.4g} A")
    if m.energy_to_battery_j < -1e-9:
        what.append(f"a negative battery energy {m.energy_to_battery_j:.3g} J")
    if not what:
        return None
    return (f"{name}: the exact-mode run is not physical here ({'; '.join(what)}): this link or control period "
            "is outside the range where the model was checked against the switching model; use model='switching'")
