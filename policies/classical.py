"""Classical policies: step, ramp and the paper's model-based inverse controller.

All three turn the charge command (a DC current ``I_L*`` into the battery, 0 = stop) into a
target fundamental ``V2_target`` with the assumed link model, and differ only in how they move
``V2*`` there:

* step: at once (the plain mode switch of an unsynchronised ON-OFF SBAR),
* ramp: linearly, at ``(4/pi) VL`` per ``2 L1 / R1`` (the paper's ramp slope),
* model_based: I2ref = steady I2 for ``V2_target`` -> Q -> G22^-1 -> V2* (paper Fig. 5).

The duty comes from the inverse of eq. 9 with the *measured* battery voltage as VL.
"""

from __future__ import annotations

import math

import numpy as np

from mission_sim.contract import OBS_DIM, OBS_INDEX, PolicyContext, denormalise_obs, denormalise_obs_field

_I_CMD, _I_VL = OBS_INDEX["charge_cmd_a"], OBS_INDEX["battery_v"]
from wpt_receiver import InverseModelController, LowPassFilter, duty_from_v2_clipped
from wpt_receiver.references import ramp_duration_s

__all__ = ["target_v2", "StepPolicy", "RampPolicy", "ModelBasedPolicy"]


def _link_constants(ctx: PolicyContext, lm_h=None):
    p = ctx.link
    lm = p.lm_h if lm_h is None else np.asarray(lm_h, dtype=float)
    wlm = p.omega_rad_s * lm
    return wlm * p.v1_amp_v, p.r1_ohm * p.r2_ohm + wlm**2, p.r1_ohm


def target_v2(ctx: PolicyContext, charge_cmd_a, vl_v, lm_h=None) -> np.ndarray:
    """V2 [V] that makes the SBAR deliver ``charge_cmd_a`` [A] at battery voltage ``vl_v`` in steady state.

    Power balance of a lossless rectifier, ``V2 I2 / 2 = VL I_L``, with the assumed steady
    ``I2 = (w Lm V1 - R1 V2) / det`` gives ``R1 V2^2 - w Lm V1 V2 + 2 VL I_L det = 0``; the
    smaller root is taken and clipped into ``[0, (4/pi) VL]`` (a command beyond what RM can
    deliver saturates at RM).
    """
    return _target_v2(_link_constants(ctx, lm_h), charge_cmd_a, vl_v)


def _target_v2_scalar(consts, charge_cmd_a: float, vl_v: float) -> float:
    """:func:`_target_v2` on Python floats (the same operations in the same order: bit-identical)."""
    wlm_v1, det, r1 = consts
    disc = max(wlm_v1**2 - 8.0 * r1 * vl_v * max(charge_cmd_a, 0.0) * det, 0.0)
    v2 = (wlm_v1 - math.sqrt(disc)) / (2.0 * r1)
    return min(max(v2, 0.0), 4.0 / np.pi * vl_v)


def _target_v2(consts, charge_cmd_a, vl_v):
    wlm_v1, det, r1 = consts
    il = np.maximum(np.asarray(charge_cmd_a, dtype=float), 0.0)
    vl = np.asarray(vl_v, dtype=float)
    disc = np.maximum(wlm_v1**2 - 8.0 * r1 * vl * il * det, 0.0)
    v2 = (wlm_v1 - np.sqrt(disc)) / (2.0 * r1)
    return np.minimum(np.maximum(v2, 0.0), 4.0 / np.pi * vl)


class _CommandPolicy:
    name = "base"

    def __init__(self, ctx: PolicyContext = PolicyContext()):
        self.ctx = ctx
        self.n = 1
        self._consts = _link_constants(ctx)

    def reset(self, n: int = 1) -> None:
        self.n = int(n)
        self._v2 = None

    def kernel(self):
        """The optional fast-path hook of :class:`mission_sim.contract.Policy`: ``(fn, params, state)``
        (:mod:`policies.kernels`), or None for a subclass that changes what ``act`` computes."""
        spec = self.kernel_spec()
        if spec is None:
            return None
        from .kernels import KERNELS  # numba: imported on the first compiled mission only
        name, params, state = spec
        return KERNELS[name], params, state

    def kernel_name(self):
        """The name of this policy's kernel in :data:`policies.kernels.KERNELS`, or None (no kernel: a subclass
        that changes what ``act`` computes, or a batch)."""
        return self.name if type(self) in _KERNEL_CLASSES and self.n == 1 else None

    def kernel_spec(self):
        """:meth:`kernel` without numba: ``(name, params, state)``, the kernel by its name in
        :data:`policies.kernels.KERNELS` (an ahead-of-time build of the mission loop binds it in by name:
        :mod:`mission_sim.world.aot`), or None."""
        if self.kernel_name() is None:
            return None
        wlm_v1, det, r1 = self._consts
        head = [float(wlm_v1), float(det), float(r1), float(wlm_v1**2)]
        return self.name, np.array(head + self._kernel_params()), np.zeros(1 + self._kernel_state_size())

    def _kernel_params(self) -> list:
        return []

    def _kernel_state_size(self) -> int:
        return 0

    def _measure(self, obs):
        phys = denormalise_obs(obs)
        if phys.ndim == 1:
            phys = phys[None, :]
        return phys[:, _I_CMD], phys[:, _I_VL]


class StepPolicy(_CommandPolicy):
    """Jump to the target duty at once."""

    name = "step"

    def act(self, obs):
        cmd, vl = self._measure(obs)
        return duty_from_v2_clipped(_target_v2(self._consts, cmd, vl), vl)


class RampPolicy(_CommandPolicy):
    """Move V2* towards the target at the paper's ramp rate ((4/pi) VL per 2 L1/R1)."""

    name = "ramp"
    #: how far its RM -> SM transition's instantaneous |i2| peaks above the steady short-mode I2 (a fraction), the
    #: larger of two ``dronewpt paper --no-plot`` measurements (modal model): 10.27 % at Table I (12.59 A against
    #: 11.41 A) and 8.65 % at the pad-gate warning's operating point (``--link lm_h=4.98e-6 --link vl_v=32.8``:
    #: 15.57 A against 14.33 A, above the 15 A rating at the default gate). Read by the mission's setup warning on
    #: ``coupling.tx_min_k`` (:func:`mission_sim.setup_warnings.short_mode_rating_warning`); not part of the
    #: :class:`~mission_sim.contract.Policy` protocol.
    rm_sm_overshoot = 0.1027

    def act(self, obs):
        cmd, vl = self._measure(obs)
        tgt = _target_v2(self._consts, cmd, vl)
        if self._v2 is None or len(self._v2) != len(tgt):
            self._v2 = tgt.copy()
        rate = 4.0 / np.pi * vl / ramp_duration_s(self.ctx.link) * self.ctx.control_period_s
        self._v2 = self._v2 + np.clip(tgt - self._v2, -rate, rate)
        return duty_from_v2_clipped(self._v2, vl)

    def _kernel_params(self) -> list:
        return [float(ramp_duration_s(self.ctx.link)), float(self.ctx.control_period_s)]

    def _kernel_state_size(self) -> int:
        return 1


class ModelBasedPolicy(_CommandPolicy):
    """The paper's inverse-model controller (Fig. 5) driven by the charge command."""

    name = "model_based"
    #: how far its RM -> SM transition's instantaneous |i2| peaks above the steady short-mode I2 (a fraction): 4.6 %,
    #: the harmonic ripple at the intermediate duties it passes (its fundamental overshoots by 0.0 %; switching and
    #: modal model, Table I: 11.95 A against 11.41 A, docs/devices.md "Detuning"; 3.65 % at the pad-gate warning's
    #: operating point, ``dronewpt paper --no-plot --link lm_h=4.98e-6 --link vl_v=32.8``: Table I's is the larger,
    #: the one declared). Read by the mission's setup warning on
    #: ``coupling.tx_min_k`` (:func:`mission_sim.setup_warnings.short_mode_rating_warning`); not part of the
    #: :class:`~mission_sim.contract.Policy` protocol.
    rm_sm_overshoot = 0.046

    def __init__(self, ctx: PolicyContext = PolicyContext(), lpf: LowPassFilter = LowPassFilter()):
        super().__init__(ctx)
        self.lpf = lpf
        self._ctl = None

    def reset(self, n: int = 1) -> None:
        super().reset(n)
        self._ctl = None

    def i2_ref(self, cmd, vl):
        """Reference I2 [A] for a charge command: the assumed steady I2 at the target V2,
        ``I2 = (w Lm V1 - R1 V2) / det``."""
        wlm_v1, det, r1 = self._consts
        return (wlm_v1 - r1 * _target_v2(self._consts, cmd, vl)) / det

    def act(self, obs, restart=None):
        """Duties for ``obs``; ``restart`` (row indices) starts those receivers' controllers afresh in
        the steady state of their current reference (a new charging window in a batched env)."""
        if restart is None and self._ctl is not None and self._ctl.n == 1 and np.shape(obs) in ((1, OBS_DIM), (OBS_DIM,)):
            return self._act1(obs)
        cmd, vl = self._measure(obs)
        ref = self.i2_ref(cmd, vl)
        if self._ctl is None or self._ctl.n != len(ref):
            self._ctl = InverseModelController(self.ctx.link, self.ctx.control_period_s, self.lpf, n=len(ref))
            self._ctl.reset(ref)
        elif restart is not None and len(restart):
            ad, bd, _, _ = self._ctl.discrete_ss
            xss = np.linalg.solve(np.eye(len(ad)) - ad, bd)
            self._ctl.x[restart] = (ref[restart] - self._ctl.i2_sm_a)[:, None] * xss[None, :]
        return duty_from_v2_clipped(self._ctl.update(ref), vl)

    def _act1(self, obs):
        """:meth:`act` for one receiver on Python floats (numpy's per-call overhead was 30 us at n = 1)."""
        cmd, vl = denormalise_obs_field(obs, _I_CMD), denormalise_obs_field(obs, _I_VL)
        return np.array([duty_from_v2_clipped(self._ctl.update1(self._i2_ref1(cmd, vl)), vl)])

    def _i2_ref1(self, cmd: float, vl: float) -> float:
        """:meth:`i2_ref` for one receiver on floats."""
        wlm_v1, det, r1 = self._consts
        return (wlm_v1 - r1 * _target_v2_scalar(self._consts, cmd, vl)) / det

    def _controller(self) -> InverseModelController:
        return InverseModelController(self.ctx.link, self.ctx.control_period_s, self.lpf, n=1)

    def _kernel_params(self) -> list:
        ctl = self._controller()
        ad, bd, cd, dd = ctl.discrete_ss
        return [float(ctl.i2_sm_a), float(dd), float(len(bd)), *np.ravel(ad).tolist(), *bd.tolist(), *cd.tolist(),
                *ctl._xss.tolist()]

    def _kernel_state_size(self) -> int:
        return int(self.lpf.order) + 1


#: the classes whose ``act`` the compiled kernels reproduce (subclasses get no kernel)
_KERNEL_CLASSES = (StepPolicy, RampPolicy, ModelBasedPolicy)
