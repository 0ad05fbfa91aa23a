"""The MPC's prediction model of the exact-mode link (``EnvConfig(link_model="modal")``): what
:class:`policies.mpc.MPCPolicy` predicts with when its :class:`~mission_sim.contract.PolicyContext` says the
plant is the modal link (``link_model="modal"``); eq. 4's model (:class:`policies.mpc._Model`) otherwise.

Why eq. 4 is not enough there (measured on nominal windows 1000-1003 with the eq. 4 MPC on the modal plant,
docs/rl.md): the steady I2 of both links agree within 0.03 % at every duty, and the ripple excess the MPC
adds is within 0.02 A of the modal peak's; but the SBAR's v2 has a quadrature component (eq. 9
generalised: ``V2 = (4/pi) Vc (j e^{-j e} - sin(pi d/2))``, the commutation angle ``e`` off ``pi/2`` by the
harmonics' shift) of 1.4-4.7 V, steepest near short mode (``~ sqrt(V2)``), and on the exact modes
(asymmetric about w, ``w / sqrt(1 -+ k)``) a change of it rings |I2|. The eq. 4 MPC ends its after-stop
ramp with a step from d ~ 0.94 to 1 (0.2 V in phase, ~1 V in quadrature) and the modal link rings
0.7-1.0 A above the eq. 4 prediction 1 ms later: the measured overshoot is that ring.

The model here (4 real states + the MPC's input disturbance ``w``):

* the link's two positive-frequency modes (:func:`wpt_receiver.modal.link_matrices`, the devices'
  resistances folded in, Table I's Lm), in the frame rotating at w and turned to I2's phase in short
  mode, each scaled to its contribution to I2 [A]; the negative-frequency modes' quasi-static response
  as the feedthrough of V1 and V2 to I2 (all from :func:`wpt_receiver.modal_kernel.modes`); discretised
  with the modes' exact ZOH (:func:`wpt_receiver.modal_kernel.zoh`) at the control period and at its half
  (the env's mid-step samples);
* the input V2 in I2's frame is ``u + r(u)``: ``u`` the MPC's decision (eq. 9's V2, the duty from
  ``f^-1``, the in-phase part in eq. 4's model), ``r(u) = P(d(u)) Vc / Vc0 - u`` the residual, complex,
  with ``P(d)`` the SBAR's fundamental in I2's frame at the modal link's periodic steady state at duty
  ``d`` (:func:`wpt_receiver.modal_kernel.steady_state`, nominal Lm and battery ``Vc0``; the shift of the
  commutation depends on |I2| / Vc, the duty and the phase, which move little about the operating
  point); linearised along the plan like the ripple excess (the MPC's SCP);
* the output is ``Re I2`` in that frame (|I2| to second order in the phase, which stays within a
  degree under the MPC's plans).

With it, the MPC also ends its descent with the last :data:`policies.mpc._TAIL_V` of V2 linear in the duty
(:meth:`policies.mpc.MPCPolicy._duty_tail`): the same ramp rings ~9x less that way, and both models predict
it within 0.08 A. Nominal, 100 windows on the modal plant: overshoot 6.39 % -> 2.57 %, energy after the
stop 0.832 -> 0.806 J (docs/rl.md, "The MPC on the exact-mode link").

Checked by ``tests/test_mpc_modal.py``: the open-loop prediction of a V2 ramp against the modal plant, and
the MPC on the modal plant at its floor.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["ModalModel", "v2_frame_table"]

_N_D = 201          # duty grid of the residual table (quadratic towards d = 1, where the quadrature is steep)


@lru_cache(maxsize=4)
def _sbar_table(table_link, devices_name: str):
    """The SBAR table (:func:`wpt_receiver.modal_kernel.modal_table`) of ``table_link`` (``LinkParams.at_default_vl``: at
    ``LinkParams``' default VL, as the mission loop's, ``mission_sim.world.loop``; the table holds VL only through
    the inverter's harmonics against the clamp, the clamp itself is each caller's ``VL + Vf``). Links that differ
    only in their pack voltage share one table (1.1 MB; built in seconds on a disk-cache miss)."""
    from wpt_receiver import modal_kernel as mk
    from wpt_receiver.devices import preset
    return mk.modal_table(table_link, preset(devices_name))


@lru_cache(maxsize=4)
def _link_modes(link, devices_name: str):
    """``(lc, tab, mc, dev)``: the link's constants, SBAR table (:func:`_sbar_table`: at LinkParams' default VL,
    shared by every pack voltage, as the mission loop's) and modes (:func:`wpt_receiver.modal_kernel.modes`, at
    the link's Lm) and the device set of the preset. The link's own VL is the clamp's (``VL + Vf``) in
    :func:`v2_frame_table` and :func:`policies.budget_modal._plant`."""
    from wpt_receiver import modal_kernel as mk
    from wpt_receiver.devices import preset
    dev = preset(devices_name)
    lc, tab = mk.link_constants(link, dev), _sbar_table(link.at_default_vl(), devices_name)
    mc = np.empty(mk.N_MODES_C, dtype=np.complex128)
    mk.modes(lc, link.lm_h, mc)
    return lc, tab, mc, dev


@lru_cache(maxsize=4)
def v2_frame_table(link, devices_name: str):
    """``(d grid, P(d) complex [V], Vc0 [V], theta [rad])``: the SBAR's fundamental in I2's frame
    (``V2 conj(I2) / |I2|``) at the modal link's periodic steady state per duty, at the link's Lm and
    battery voltage (clamp ``Vc0 = VL + Vf``), and I2's phase in short mode ``theta``. A link whose I2
    vanishes at some duty (a blocking link: I2's frame undefined) is refused."""
    from wpt_receiver import modal_kernel as mk
    lc, tab, mc, dev = _link_modes(link, devices_name)
    vc0 = link.vl_v + dev.rect_vf_v
    v1 = -1j * link.v1_amp_v
    d = 1.0 - (1.0 - np.linspace(0.0, 1.0, _N_D)) ** 2
    p = np.empty(_N_D, dtype=complex)
    z = np.zeros(4)
    theta = 0.0
    for i, dk in enumerate(d):
        v2 = mk.steady_state(lc, mc, tab, dk, v1, vc0, z)
        i2 = mk.phasors(mc, z, v1, v2)[1]
        if not abs(i2) > 1e-9:   # [A]; NaN too
            raise ValueError(f"the modal MPC's link has |I2| = {abs(i2):.3g} A at duty {dk:.3f} (it blocks): "
                             "I2's frame is undefined; valid: a link whose steady I2 is non-zero at every duty")
        p[i] = v2 * np.conj(i2) / abs(i2)
        theta = float(np.angle(i2))
    return d, p, vc0, theta


def _real_system(link, devices_name, theta, dt_s):
    """The modal model (:func:`wpt_receiver.modal_kernel.modes`) as a real one in I2's frame (turned by
    ``-theta``), discretised with the modes' exact ZOH (:func:`wpt_receiver.modal_kernel.zoh`) over ``dt_s``
    [s]: ``(Ad (4, 4), Bd (4, 3), C (4,), D (3,))``, states ``s_m = S_m z_m e^{-j theta}`` [A] (Re, Im per
    mode; ``S_m`` the mode's I2 shape, so ``C`` sums the real parts), inputs ``[Re V2', Im V2', 1]`` (``V2' =
    V2 e^{-j theta}``; the last the pad's V1, constant), output Re I2 (the feedthrough ``D`` of the
    negative-frequency modes)."""
    E, beta, gamma, c1, d2 = complex_system(link, devices_name, theta, dt_s)
    Ad, Bd = np.zeros((4, 4)), np.zeros((4, 3))
    for k in range(2):
        e = E[k]
        Ad[2 * k:2 * k + 2, 2 * k:2 * k + 2] = [[e.real, -e.imag], [e.imag, e.real]]
        # per unit Re V2', Im V2' (1j beta: exact) and the constant V1 drive
        for j, gain in enumerate((beta[k], 1j * beta[k], gamma[k])):
            Bd[2 * k, j], Bd[2 * k + 1, j] = gain.real, gain.imag
    C = np.array([1.0, 0.0, 1.0, 0.0])
    D = np.array([d2.real, -d2.imag, c1.real])
    return Ad, Bd, C, D


def complex_system(link, devices_name, theta, dt_s):
    """The modal model (:func:`wpt_receiver.modal_kernel.modes`) in I2's frame (turned by ``-theta``) over ``dt_s``
    [s] with the modes' exact ZOH (:func:`wpt_receiver.modal_kernel.zoh`), as complex per-mode constants: ``s_m <-
    E_m s_m + beta_m V2' + gamma_m`` and ``I2' = s_0 + s_1 + c1 + d2 V2'`` (``V2' = V2 e^{-j theta}``; ``gamma`` and
    ``c1`` carry the pad's constant V1 drive): ``(E (2,), beta (2,), gamma (2,), c1, d2)``. The one source of
    :func:`_real_system` (its real 4-state form) and of :class:`policies.mpc_lock.LockedModel`."""
    from wpt_receiver import modal_kernel as mk
    mc = _link_modes(link, devices_name)[2]
    zc = np.empty(mk.N_ZOH_C, dtype=np.complex128)
    mk.zoh(mc, dt_s, zc)
    rot, v1 = np.exp(-1j * theta), -1j * link.v1_amp_v
    E, beta, gamma = (np.empty(2, dtype=np.complex128) for _ in range(3))
    for k in range(2):
        shape, g1, g2 = mc[mk.MC_S + 4 * k + 1], mc[mk.MC_G1 + k], mc[mk.MC_G2 + k]
        phi = zc[mk.ZC_PHI + k]
        E[k], beta[k], gamma[k] = zc[mk.ZC_E + k], phi * (shape * g2), phi * (shape * g1 * v1 * rot)
    return E, beta, gamma, complex(mc[mk.MC_D + 2] * v1 * rot), complex(mc[mk.MC_D + 3])


class ModalModel:
    """Condensed predictions over ``n_pred`` steps (the samples the env's peak takes: mid-step and end of
    every step, ``2 n_pred`` rows): ``I2 = F z + G v + h + Gr r`` with ``z = [s (4), w]``, ``v`` the knots of
    the V2 plan (``M`` (n_pred, knots), the MPC's basis: V2 linear between them), ``r = [Re r_0 .. Re r_{n-1},
    Im r_0 .. Im r_{n-1}]`` the residual of V2 in I2's frame per step (:meth:`residual`); one-step ``ad, bu, br,
    e`` and the measurement ``c, du, dr, d0``. The filter's gain ``kalman`` is set by its maker
    (:func:`policies.mpc._modal_model`, eq. 4's filter problem on this model)."""

    modal = True

    def __init__(self, link, devices_name, dt_s, n_pred, M):
        self.d_grid, p, self.vc0, theta = v2_frame_table(link, devices_name)
        self.p_re, self.p_im = p.real.copy(), p.imag.copy()
        ad, bd, C, D = _real_system(link, devices_name, theta, dt_s)
        am, bm = _real_system(link, devices_name, theta, 0.5 * dt_s)[:2]
        self.nx = 4
        self.ad, self.bu, self.br, self.e = ad, bd[:, 0], bd[:, :2], bd[:, 2]
        self.c, self.du, self.dr, self.d0 = C, D[0], D[:2], D[2]
        self.b2 = self.bu
        # steady state per unit of the inputs [in-phase V2, quadrature V2, V1 drive] (a constant of the model)
        self._ss = np.linalg.solve(np.eye(4) - ad, np.column_stack([self.bu, self.br[:, 1], self.e])).T
        self._condense(ad, bd, am, bm, C, D, n_pred, M)
        self.kalman = None

    def _condense(self, ad, bd, am, bm, C, D, n, M):
        """``F, h, Gu, Gr, G, M, ends`` (class docstring)."""
        F = np.zeros((2 * n, 5))
        h = np.zeros(2 * n)
        imp = np.zeros((2, 2, n))   # output of the mid / end sample of a step to each of Re / Im V2' i steps earlier
        Phi, c = np.eye(4), np.zeros(4)
        x = bd[:, :2].copy()
        for k in range(n):
            for r, (A_, B_) in enumerate(((am, bm), (ad, bd))):
                F[2 * k + r, :4] = C @ A_ @ Phi
                h[2 * k + r] = C @ (A_ @ c + B_[:, 2]) + D[2]
            if k:
                imp[:, :, k] = np.stack([C @ am @ x, C @ ad @ x], axis=1)
                x = ad @ x
            Phi, c = ad @ Phi, ad @ c + bd[:, 2]
        imp[:, :, 0] = np.stack([C @ bm[:, :2] + D[:2], C @ bd[:, :2] + D[:2]], axis=1)
        lag = np.arange(n)[:, None] - np.arange(n)[None, :]
        G2 = [np.where(lag >= 0, imp[j][:, np.maximum(lag, 0)], 0.0).transpose(1, 0, 2).reshape(2 * n, n) for j in (0, 1)]
        F[:, 4] = G2[0].sum(axis=1)
        self.F, self.h, self.Gu, self.M = F, h, G2[0], M
        self.Gr = np.concatenate(G2, axis=1)
        self.G = G2[0] @ M
        self.ends = np.arange(1, 2 * n, 2)

    def residual(self, u, vc):
        """``(Re r, Im r)`` [V]: the modal link's V2 in I2's frame minus ``u`` at the eq. 9 V2 ``u`` [V] (any
        shape) and clamp ``vc`` [V] (broadcast): the table's ``P(d)`` at ``d = f^-1(u)``, scaled by ``vc / Vc0``."""
        from wpt_receiver import duty_from_v2_clipped
        d = duty_from_v2_clipped(u, vc)
        s = vc / self.vc0
        return np.interp(d, self.d_grid, self.p_re) * s - u, np.interp(d, self.d_grid, self.p_im) * s

    def residual_slope(self, u, vc, h=0.25):
        """``(r(u), dr/du)`` (each ``(Re, Im)``) by a central difference of ``h`` [V] inside ``[0, (4/pi) vc]``."""
        vmax = 4.0 / np.pi * vc
        hi, lo = np.minimum(u + h, vmax), np.maximum(u - h, 0.0)
        r0, rh, rl = self.residual(u, vc), self.residual(hi, vc), self.residual(lo, vc)
        den = np.maximum(hi - lo, 1e-9)
        return r0, ((rh[0] - rl[0]) / den, (rh[1] - rl[1]) / den)

    def step(self, z, u, vc, r=None):
        """One step of the estimates ``z`` (..., 5) under the V2 ``u`` (...) [V] at the clamp ``vc`` (``r``: the
        residual :meth:`residual` of ``u``, if already computed)."""
        rr, ri = self.residual(u, vc) if r is None else r
        out = np.empty_like(z)
        out[..., :4] = (z[..., :4] @ self.ad.T + (u + z[..., 4])[..., None] * self.bu + rr[..., None] * self.br[:, 0]
                        + ri[..., None] * self.br[:, 1] + self.e)
        out[..., 4] = z[..., 4]
        return out

    def measure(self, z, u, vc, r=None):
        """The I2 [A] the sensor reads at the end of a step with V2 ``u`` from the state ``z`` (after it)."""
        rr, ri = self.residual(u, vc) if r is None else r
        return z[..., :4] @ self.c + self.du * (u + z[..., 4]) + self.dr[0] * rr + self.dr[1] * ri + self.d0

    def step_measure(self, z, u, vc):
        """:meth:`step` and :meth:`measure` after it, the residual of ``u`` computed once."""
        r = self.residual(u, vc)
        x = self.step(z, u, vc, r)
        return x, self.measure(x, u, vc, r)

    def steady(self, u, w, vc):
        """The steady state ``s`` (..., 4) and I2 [A] at the V2 ``u`` with the disturbance ``w`` [V]."""
        rr, ri = self.residual(u, vc)
        inp = np.stack([u + w + rr, ri, np.ones_like(rr)], axis=-1)
        s = inp @ self._ss
        return s, s @ self.c + self.du * (u + w) + self.dr[0] * rr + self.dr[1] * ri + self.d0
