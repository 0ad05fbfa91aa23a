"""V2* reference trajectories of the paper's simulation (Fig. 6 a-c) for the RM -> SM transition.

* step: V2* jumps from (4/pi) VL to 0 at the switching instant (plain mode switch).
* ramp: V2* falls linearly to 0 over ``ramp_duration_s``. The paper picks the slope "such that
  the time constant is the same as that of the proposed method"; we use the time constant of the
  proposed V2*, which is the pole of G22^-1 at -beta2/alpha2: ``tau = alpha2/beta2 = 2 L1 / R1``
  (4.37 ms with Table I). ``kind="duty"`` ramps d_short linearly 0 -> 1 instead.
* proposed: I2ref steps from the RM to the SM steady current and passes through the
  inverse-model controller (:class:`~wpt_receiver.inverse_controller.InverseModelController`).

Each returns the short duty per control period; the plant models take duties, so the same
sequence drives the envelope and the switching-level models.
"""

from __future__ import annotations

import numpy as np

from .envelope import steady_state
from .inverse_controller import InverseModelController, LowPassFilter
from .params import LinkParams
from .sbar import duty_from_v2_clipped

__all__ = ["ramp_duration_s", "step_duty", "ramp_duty", "proposed_duty", "reference_duty", "TRAJECTORIES"]

TRAJECTORIES = ("step", "ramp", "proposed")


def ramp_duration_s(params: LinkParams) -> float:
    """Ramp length: the time constant 2 L1 / R1 of the proposed V2* [s]."""
    return 2.0 * params.l1_h / params.r1_ohm


def _grid(t_switch_s: float, t_end_s: float, period_s: float) -> np.ndarray:
    if not 0 < t_end_s < np.inf:      # NaN was reported as a bad t_switch_s, inf as a control period in [inf, inf]
        raise ValueError(f"t_end_s={t_end_s!r} is invalid; valid range: (0, inf) s, after t_switch_s")
    if not (0 <= t_switch_s < t_end_s):
        raise ValueError(f"t_switch_s={t_switch_s!r} is invalid; valid range: [0, t_end_s={t_end_s!r})")
    if not (np.isfinite(period_s) and t_end_s / 1e7 <= period_s <= (t_end_s - t_switch_s) / 10):
        raise ValueError(f"control_period_s={period_s!r} is invalid; valid range: "
                         f"[{t_end_s / 1e7:g}, {(t_end_s - t_switch_s) / 10:g}] s for this window")
    return np.arange(int(round(t_end_s / period_s))) * period_s


def step_duty(t_s: np.ndarray, t_switch_s: float) -> np.ndarray:
    """d_short = 0 before the switch, 1 from the switch on."""
    return (np.asarray(t_s) >= t_switch_s - 1e-12).astype(float)


def ramp_duty(t_s: np.ndarray, t_switch_s: float, duration_s: float, vl_v: float, kind: str = "v2") -> np.ndarray:
    """Linear ramp of V2* (``kind="v2"``, the paper's Fig. 6b) or of d_short (``kind="duty"``)."""
    frac = np.clip((np.asarray(t_s) - t_switch_s) / duration_s, 0.0, 1.0)
    if kind == "duty":
        return frac
    if kind != "v2":
        raise ValueError(f"kind={kind!r} is invalid; valid values: 'v2', 'duty'")
    v2 = 4.0 / np.pi * vl_v * (1.0 - frac)
    return duty_from_v2_clipped(v2, vl_v)


def proposed_duty(t_s: np.ndarray, t_switch_s: float, params: LinkParams, control_period_s: float,
                  lpf: LowPassFilter = LowPassFilter()):
    """Duties from the inverse-model controller for I2ref stepping RM -> SM at ``t_switch_s``.

    Returns ``(d_short, v2_cmd_v)``.
    """
    i2_rm = steady_state(params, params.v2_rm_amp_v)[1]
    i2_sm = steady_state(params, 0.0)[1]
    ref = np.where(np.asarray(t_s) >= t_switch_s - 1e-12, i2_sm, i2_rm)
    ctl = InverseModelController(params, control_period_s, lpf)
    v2, d = ctl.run(ref)
    return d, v2


def reference_duty(name: str, params: LinkParams, t_switch_s: float, t_end_s: float,
                   control_period_s: float | None = None, lpf: LowPassFilter = LowPassFilter(),
                   ramp_kind: str = "v2"):
    """``(t_s, d_short, v2_ref_v)`` for trajectory ``name`` in ``TRAJECTORIES`` on the control grid."""
    period = params.rectifier_period_s if control_period_s is None else control_period_s
    t = _grid(t_switch_s, t_end_s, period)
    if name == "step":
        d = step_duty(t, t_switch_s)
        v2 = 4 / np.pi * params.vl_v * (1 - np.sin(np.pi / 2 * d))
    elif name == "ramp":
        d = ramp_duty(t, t_switch_s, ramp_duration_s(params), params.vl_v, ramp_kind)
        v2 = 4 / np.pi * params.vl_v * (1 - np.sin(np.pi / 2 * d))
    elif name == "proposed":
        d, v2 = proposed_duty(t, t_switch_s, params, period, lpf)
    else:
        raise ValueError(f"trajectory={name!r} is invalid; valid values: {', '.join(TRAJECTORIES)}")
    return t, d, v2
