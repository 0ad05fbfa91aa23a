"""SBAR duty mapping (paper eq. 9) and its inverse.

``v2 = f(d_short) = (4/pi) VL (1 - sin(pi/2 d_short))`` is the fundamental amplitude of the
rectifier's input voltage when the two lower switches short the coil for ``d_short * T`` in every
rectifier period ``T`` (half the inverter period). The relation assumes that the short window is
centred on the peak of the i2 half-cycle: the removed part of the square wave is then the
centred slice of width ``d_short * pi`` whose fundamental is ``(4/pi) VL sin(pi/2 d_short)``.
For other placements of the window the fundamental is smaller in the in-phase component and a
quadrature component appears (see the switching-level model); the paper's experiment shows the
controller still works with the window shifted by pi/2.
"""

from __future__ import annotations

import math

import numpy as np

from .params import check_control_period

__all__ = ["v2_from_duty", "duty_from_v2", "duty_from_v2_clipped"]

_FOUR_OVER_PI = 4.0 / np.pi


def _check_vl(vl_v: float) -> float:
    vl_v = float(vl_v)
    if not np.isfinite(vl_v) or vl_v <= 0:
        raise ValueError(f"vl_v={vl_v!r} is invalid; valid range: (0, inf)")
    return vl_v


def check_duty(d_short) -> np.ndarray:
    """``d_short`` as a float array, after checking every duty is in [0, 1] (NaN refused)."""
    d = np.asarray(d_short, dtype=float)
    bad = ~np.isfinite(d) | (d < 0.0) | (d > 1.0)
    if np.any(bad):
        raise ValueError(f"d_short={float(d[bad].flat[0])!r} is out of range; valid range: [0, 1]")
    return d


def check_duty_run(d_short, control_period_s: float, substeps: int) -> np.ndarray:
    """A run's duties (one per control period) as a float array, after checking them and the period: the modal
    models ran d = 1.5 or -0.1 silently, gave NaN currents for a NaN duty or period, a run of zero length in time
    for a zero period and an IndexError for no duties."""
    d = check_duty(d_short)
    if d.ndim != 1 or d.size == 0:
        raise ValueError(f"d_short of shape {d.shape} is invalid; valid: a non-empty 1-D sequence of duties")
    check_control_period(control_period_s)
    if (isinstance(substeps, bool) or not isinstance(substeps, (int, float, np.integer, np.floating))
            or not math.isfinite(substeps) or int(substeps) != substeps or substeps < 1):
        raise ValueError(f"substeps={substeps!r} is invalid; valid range: integer >= 1")
    return d


def v2_from_duty(d_short, vl_v: float):
    """Fundamental amplitude of v2 [V] for short duty ``d_short`` in [0, 1] (eq. 9)."""
    vl_v = _check_vl(vl_v)
    d = check_duty(d_short)
    out = _FOUR_OVER_PI * vl_v * (1.0 - np.sin(0.5 * np.pi * d))
    return out if out.ndim else float(out)


def duty_from_v2(v2_v, vl_v: float):
    """Inverse of eq. 9: the short duty [-] that gives fundamental amplitude ``v2_v`` [V].

    Valid for ``v2_v`` in ``[0, (4/pi) VL]``; anything else raises ``ValueError``.
    """
    vl_v = _check_vl(vl_v)
    v = np.asarray(v2_v, dtype=float)
    vmax = _FOUR_OVER_PI * vl_v
    bad = ~np.isfinite(v) | (v < 0.0) | (v > vmax * (1 + 1e-12))
    if np.any(bad):
        raise ValueError(f"v2_v={float(v[bad].flat[0])!r} is out of range; valid range: [0, {vmax:.6g}] V")
    return duty_from_v2_clipped(v, vl_v)


def duty_from_v2_clipped(v2_v, vl_v: float):
    """Like :func:`duty_from_v2` but saturates ``v2_v`` into ``[0, (4/pi) VL]`` (no errors).

    This is what a controller does with a command outside the actuator's range. Python floats in
    give a float out by the same arithmetic without numpy's per-call overhead (n = 1 loops); ``vl_v = 0``
    takes numpy's path, as an array does (IEEE division, a RuntimeWarning), not Python's ZeroDivisionError.
    A NaN ``v2_v`` stays NaN (a mission refuses a policy's NaN duty by name); the exported C gives d = 0.
    """
    if type(v2_v) is float and type(vl_v) is float and vl_v != 0.0:
        s = min(max(1.0 - v2_v / (_FOUR_OVER_PI * vl_v), 0.0), 1.0)
        return float((2.0 / np.pi) * np.arcsin(s))
    v = np.asarray(v2_v, dtype=float)
    s = np.minimum(np.maximum(1.0 - v / (_FOUR_OVER_PI * vl_v), 0.0), 1.0)  # np.clip is slow on tiny arrays
    out = (2.0 / np.pi) * np.arcsin(s)
    return out if out.ndim else float(out)


def rectifier_v2(d_short, vl_v, i2_amp_a, *, sin=np.sin, sign=np.sign):
    """Fundamental amplitude of v2 [V] the SBAR presents to an I2 envelope of either sign (eq. 9).

    ``V2 = (4/pi) VL (1 - sin(pi/2 d_short)) sign(I2)``. The diodes (and the synchronous switches)
    conduct with the *instantaneous* i2, so the rectifier's square wave is always in phase with
    i2: a negative envelope amplitude is i2 shifted by pi, i.e. by one rectifier period
    ``T = 1/(2f)``, so the clocked short window still sits on a half-cycle peak and only the sign
    of the fundamental follows I2. The rectifier therefore always absorbs power (V2 I2 >= 0, the
    battery never drives the coil), unlike the paper's linear envelope with ``V2 = f(d)`` held
    positive. ``I2 = 0`` gives ``V2 = 0``.

    Vectorised over any broadcastable inputs, no range checks (hot loops; see :func:`v2_from_duty`
    for the checked mapping). ``sin`` and ``sign`` are the elementwise functions to use: the
    numpy ones by default, ``math.sin`` and a float sign for Python floats in a scalar loop.
    """
    return _FOUR_OVER_PI * vl_v * (1.0 - sin(0.5 * np.pi * d_short)) * sign(i2_amp_a)


def rectifier_current(d_short, i2_abs_mean_a, *, sin=np.sin):
    """Mean DC output current I_L [A] of the lossless SBAR, ``(2/pi) (1 - sin(pi/2 d_short)) |I2|``.

    From ``V2 I2 / 2 = VL I_L`` with :func:`rectifier_v2`: ``I_L >= 0`` whatever the sign of the
    envelope. ``i2_abs_mean_a`` is the mean of ``|I2|`` over the interval of interest (pass
    ``abs(i2)`` for an instantaneous value). Vectorised, no range checks.
    """
    return (2.0 / np.pi) * (1.0 - sin(0.5 * np.pi * d_short)) * i2_abs_mean_a


# ============================================================================ devices, averaged
def short_weight(d_short, *, sin=np.sin):
    """Share of ``int i2^2`` that flows in the short window, ``d + sin(pi d)/pi`` [-].

    With ``i2 = I2 cos(wt)`` and the window of width ``d pi`` centred on the peak (eq. 9's
    placement), ``<i2^2>`` splits into ``(I2^2/2) w`` in the short and ``(I2^2/2)(1 - w)`` in
    diode conduction."""
    return d_short + sin(np.pi * d_short) / np.pi


def rectifier_v2_devices(d_short, vl_v, i2_amp_a, devices, *, sin=np.sin, sign=np.sign):
    """Fundamental of v2 [V] with real devices, the averaged counterpart of the switching model.

    Outside the short window the diode path clamps ``v2 = sign(i2)(VL + Vf0) + Rd i2``, inside it
    ``v2 = 2 Ron i2``; the fundamental is ``(4/pi)(VL + Vf0)(1 - sin(pi/2 d)) sign(I2) +
    (Rd (1 - w) + 2 Ron w) I2`` with ``w`` = :func:`short_weight`. ``devices`` is a
    :class:`wpt_receiver.devices.DeviceSet` (IDEAL gives :func:`rectifier_v2`)."""
    w = short_weight(d_short, sin=sin)
    r_eff = devices.rect_rd_ohm * (1.0 - w) + devices.short_r_ohm * w
    return (_FOUR_OVER_PI * (vl_v + devices.rect_vf_v) * (1.0 - sin(0.5 * np.pi * d_short)) * sign(i2_amp_a)
            + r_eff * i2_amp_a)


def rectifier_v2_folded(d_short, vl_v, i2_amp_a, devices, *, sin=np.sin, sign=np.sign):
    """:func:`rectifier_v2_devices` minus ``Rd I2``: the V2 input of an envelope model whose R2
    already holds the rectifying path's ``Rd`` (:func:`wpt_receiver.devices.envelope_params`).
    What is left besides the clamp is ``(2 Ron - Rd) w I2``, small for real parts."""
    w = short_weight(d_short, sin=sin)
    return (_FOUR_OVER_PI * (vl_v + devices.rect_vf_v) * (1.0 - sin(0.5 * np.pi * d_short)) * sign(i2_amp_a)
            + (devices.short_r_ohm - devices.rect_rd_ohm) * w * i2_amp_a)


def conduction_losses(d_short, i1_amp_a, i2_amp_a, devices, *, sin=np.sin) -> dict:
    """Averaged conduction loss of each device group [W] for fundamental amplitudes I1, I2 [A].

    Rectifier: the diode path carries ``<|i2|> = I_L`` (:func:`rectifier_current`) and
    ``<i2^2> = (I2^2/2)(1 - w)``; the shorted channels ``(I2^2/2) w`` (``w`` =
    :func:`short_weight`). Inverter: the two driven channels carry ``I1^2/2`` (dead time
    neglected). Keys as :data:`wpt_receiver.switching.circuit.LOSS_GROUPS`. Vectorised."""
    w = short_weight(d_short, sin=sin)
    i_avg = rectifier_current(d_short, abs(i2_amp_a), sin=sin)
    i2sq = 0.5 * i2_amp_a * i2_amp_a
    dd, body = devices.rect_diode, devices.rect_switch.body
    return {"inverter_switches": devices.inv_r_ohm * 0.5 * i1_amp_a * i1_amp_a,
            "inverter_diodes": 0.0 * i1_amp_a,
            "rectifier_diodes": dd.vf0_v * i_avg + dd.rd_ohm * i2sq * (1.0 - w),
            "rectifier_switches": body.vf0_v * i_avg + body.rd_ohm * i2sq * (1.0 - w) + devices.short_r_ohm * i2sq * w}
