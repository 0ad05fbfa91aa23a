"""The rectifier's phase lock in the modal MPC's after-stop prediction (:mod:`policies.mpc_modal`,
:class:`policies.mpc.MPCPolicy` with a budget on the exact-mode link; docs/rl.md, "The rectifier's phase lock
in the modal MPC's prediction").

The condensed modal model holds the SBAR's V2 at ``P(d)`` in the short-mode frame. The rectifier commutates on
i2, so its V2 is ``P(d) e^{j arg I2}``: to a change of I2's phase it is a resistance ``|V2| / |I2|`` (0-2.6 ohm
over a budgeted descent), and during a fast descent that changes the ring of the two modes' beat in |I2|
(``benchmarks/diag_mpc_modal_lock.py``: the per-step |I2| peak of the descent 3x closer to the env's with V2
turned onto I2's phase every sub-step). Here the same model, in complex form (the two modes ``sigma_m`` in
I2's short-mode frame, each scaled to its share of I2):

    sigma_m <- E_m sigma_m + beta_m V + gamma_m          (one sub-step of ``dt / ns``, exact ZOH)
    I2'     =  sigma_0 + sigma_1 + c1 + d2 V
    V       =  Q_k a / |a|,  a = sigma_0 + sigma_1 + c1 + d2 V   (the fixed point, :data:`FIX_ITERS` iterations)

with ``Q_k = P(d(u_k)) vc / Vc0 + w`` the plan's V2 in I2's own frame at step ``k`` (``u`` the eq. 9 V2 the
MPC plans in, ``w`` its disturbance estimate, as :func:`benchmarks.diag_mpc_modal_lock.replay` did). Sampled at
each half step (the QP's rows: mid-step and end) as the largest |I2'| of its sub-steps. :func:`locked_rows` rolls it out along a
plan and, in forward mode, gives the rows' derivatives with respect to the plan's free knots (the MPC's basis
``M``: V2 linear between knots) and along the plan itself: the locked rows' linearisation ``rows(v) ~ rows(v_bar)
+ J (M v - v_bar)`` the MPC's after-stop QP takes in its sequential convex iterations (a time-varying
condensation: the lock's gain varies with V2 along the plan). :func:`locked_step` is the same model over one control
period, which the MPC's estimator steps after the stop (open loop: its correction from the noisy I2 lost the ring).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["LockedModel", "locked_rows", "locked_step", "FIX_ITERS", "SUBSTEPS"]

#: sub-steps per control period (the lock is applied at each; 2 are unstable, 8 within 0.05 points of 64)
SUBSTEPS = 8
#: iterations of the feedthrough's fixed point ``V = Q a / |a|`` (|d2| = 0.025 S: at most ~1 A of I2's 11 A)
FIX_ITERS = 3
#: below this |V2| in I2's frame [V] a step is the unlocked model's (a resistance |V2| / |I2| < 0.2 ohm; below
#: policies.mpc._TAIL_V the duty tail decides anyway): two exact half steps, 4x cheaper than the sub-steps
QMIN_V = 2.0


@njit(cache=True)
def _rows_kernel(sig0, q, dq, M, vbar, E, beta, gamma, Eh, betah, gammah, qmin, c1, d2, ns, rows, J, Jv, grad):
    """Rollout of receivers ``r``: ``sig0`` (n, 2) the modes now, ``q`` / ``dq`` (n, N) complex the plan's V2 in
    I2's frame per step and its derivative in ``u``, ``M`` (N, f) the basis' free knots, ``vbar`` (n, N) the plan
    (the last direction). Writes ``rows`` (n, 2N) |I2'| at mid-step and end; with ``grad`` also ``J`` (n, 2N, f)
    and ``Jv`` (n, 2N) (the derivative along ``vbar``). A step whose ``|Q|`` is below ``qmin`` [V] is two exact
    half steps (``Eh, betah, gammah``) with V held at ``Q`` (unlocked: the condensed model's step)."""
    nr, N = q.shape
    f = M.shape[1]
    nd = f + 1 if grad else 0
    ds0 = np.zeros(nd, dtype=np.complex128)
    ds1 = np.zeros(nd, dtype=np.complex128)
    dv = np.zeros(nd, dtype=np.complex128)
    dQ = np.zeros(nd, dtype=np.complex128)
    half = ns // 2
    for r in range(nr):
        s0, s1 = sig0[r, 0], sig0[r, 1]
        ds0[:] = 0.0
        ds1[:] = 0.0
        for k in range(N):
            Q, dqk = q[r, k], dq[r, k]
            if grad:
                for i in range(f):
                    dQ[i] = dqk * M[k, i]
                dQ[f] = dqk * vbar[r, k]
            if abs(Q) < qmin:
                for j in range(2):
                    s0 = Eh[0] * s0 + betah[0] * Q + gammah[0]
                    s1 = Eh[1] * s1 + betah[1] * Q + gammah[1]
                    for i in range(nd):
                        ds0[i] = Eh[0] * ds0[i] + betah[0] * dQ[i]
                        ds1[i] = Eh[1] * ds1[i] + betah[1] * dQ[i]
                    _sample(s0, s1, c1, d2, Q, ds0, ds1, dQ, f, grad, r, 2 * k + j, rows, J, Jv)
                continue
            for j in range(ns):
                base = s0 + s1 + c1
                # the fixed point V = Q a / |a|, a = base + d2 V, and its derivatives (unrolled)
                v = Q
                for i in range(nd):
                    dv[i] = dQ[i]
                for _ in range(FIX_ITERS):
                    a = base + d2 * v
                    aa = abs(a)
                    if aa < 1e-9:
                        break
                    nrm = a / aa
                    for i in range(nd):
                        da = ds0[i] + ds1[i] + d2 * dv[i]
                        dn = 1j * nrm * (nrm.real * da.imag - nrm.imag * da.real) / aa
                        dv[i] = dQ[i] * nrm + Q * dn
                    v = Q * nrm
                s0 = E[0] * s0 + beta[0] * v + gamma[0]
                s1 = E[1] * s1 + beta[1] * v + gamma[1]
                for i in range(nd):
                    ds0[i] = E[0] * ds0[i] + beta[0] * dv[i]
                    ds1[i] = E[1] * ds1[i] + beta[1] * dv[i]
                # the row of each half step: its largest sub-step sample (the env's peak is the step's largest)
                row = 2 * k + (1 if j >= half else 0)
                if j == 0 or j == half or abs(s0 + s1 + c1 + d2 * v) > rows[r, row]:
                    _sample(s0, s1, c1, d2, v, ds0, ds1, dv, f, grad, r, row, rows, J, Jv)


@njit(cache=True)
def _sample(s0, s1, c1, d2, v, ds0, ds1, dv, f, grad, r, row, rows, J, Jv):
    """Row ``row`` of receiver ``r``: |I2'| and (``grad``) its derivatives."""
    i2 = s0 + s1 + c1 + d2 * v
    a2 = abs(i2)
    rows[r, row] = a2
    if grad:
        u2 = i2 / max(a2, 1e-12)
        for i in range(f + 1):
            d = ds0[i] + ds1[i] + d2 * dv[i]
            if i < f:
                J[r, row, i] = u2.real * d.real + u2.imag * d.imag
            else:
                Jv[r, row] = u2.real * d.real + u2.imag * d.imag


class LockedModel:
    """The locked model's constants for a link, device preset and control period (:func:`locked_rows`)."""

    def __init__(self, link, devices_name, dt_s, ns=SUBSTEPS):
        from .mpc_modal import complex_system, v2_frame_table
        theta = v2_frame_table(link, devices_name)[3]
        self.ns = int(ns)
        for tag, h in (("", dt_s / ns), ("h", 0.5 * dt_s)):   # the sub-step and the half step
            E, beta, gamma, self.c1, self.d2 = complex_system(link, devices_name, theta, h)
            setattr(self, "E" + tag, E)
            setattr(self, "beta" + tag, beta)
            setattr(self, "gamma" + tag, gamma)


def _modes(z):
    """The two modes (n, 2) complex of the estimates ``z`` (n, 5): ``[s0r, s0i, s1r, s1i, w]``."""
    return np.stack([z[:, 0] + 1j * z[:, 1], z[:, 2] + 1j * z[:, 3]], axis=1)


def locked_rows(lm, model, z, plan, vc, M, grad=True, qmin=None):
    """The locked model's rows along the V2 plans ``plan`` (n, N) [V] from the estimates ``z`` (n, 5) at the clamp
    voltages ``vc`` (n,) [V]: ``rows`` (n, 2N) [A], and with ``grad`` ``J`` (n, 2N, f) (per free knot of ``M``
    (N, f)) and ``Jv`` (n, 2N) (along ``plan``); ``model`` the :class:`policies.mpc_modal.ModalModel` (its
    residual table)."""
    n, N = plan.shape
    (rr, ri), (sr, si) = model.residual_slope(plan, vc[:, None])
    q = (plan + rr + z[:, 4:5]) + 1j * ri
    dq = (1.0 + sr) + 1j * si
    sig = _modes(z)
    f = M.shape[1]
    rows = np.empty((n, 2 * N))
    J = np.zeros((n, 2 * N, f) if grad else (0, 0, 0))
    Jv = np.zeros((n, 2 * N) if grad else (0, 0))
    _rows_kernel(sig, np.ascontiguousarray(q), np.ascontiguousarray(dq), np.ascontiguousarray(M),
                 np.ascontiguousarray(plan, dtype=float), lm.E, lm.beta, lm.gamma, lm.Eh, lm.betah, lm.gammah,
                 QMIN_V if qmin is None else float(qmin), lm.c1, lm.d2, lm.ns,
                 rows, J, Jv, grad)
    return rows, J, Jv


@njit(cache=True)
def _step_kernel(sig, q, E, beta, gamma, c1, d2, ns, out, y):
    """One control period of the locked model for rows ``i``: modes ``sig`` (m, 2) under the V2 ``q`` (m,) in I2's
    frame; the modes after it into ``out`` (m, 2) and the |I2'| at its end into ``y`` (m,)."""
    for i in range(sig.shape[0]):
        s0, s1, Q = sig[i, 0], sig[i, 1], q[i]
        v = Q
        for _ in range(ns):
            v = Q
            for _ in range(FIX_ITERS):
                a = s0 + s1 + c1 + d2 * v
                aa = abs(a)
                if aa < 1e-9:
                    break
                v = Q * a / aa
            s0 = E[0] * s0 + beta[0] * v + gamma[0]
            s1 = E[1] * s1 + beta[1] * v + gamma[1]
        out[i, 0], out[i, 1] = s0, s1
        y[i] = abs(s0 + s1 + c1 + d2 * v)


def locked_step(lm, model, z, u, vc):
    """The locked model's step of the estimates ``z`` (..., 5) under the eq. 9 V2 ``u`` (...) [V] at the clamp
    voltages ``vc`` (...) [V] (what :meth:`policies.mpc_modal.ModalModel.step_measure` does unlocked): ``(z after
    the step, the |I2| [A] the sensor reads at its end)``. It always sub-steps with the lock, also below
    :data:`QMIN_V`, where :func:`locked_rows` switches to the unlocked half steps: below it the estimator's model
    and the prediction's differ (not measured apart; left as it is)."""
    z = np.asarray(z, dtype=float)
    shape = z.shape[:-1]
    zf = z.reshape(-1, z.shape[-1])
    rr, ri = model.residual(np.broadcast_to(u, shape).reshape(-1), np.broadcast_to(vc, shape).reshape(-1))
    q = (np.broadcast_to(u, shape).reshape(-1) + rr + zf[:, 4]) + 1j * ri
    sig = _modes(zf)
    out, y = np.empty_like(sig), np.empty(len(zf))
    _step_kernel(sig, q, lm.E, lm.beta, lm.gamma, lm.c1, lm.d2, lm.ns, out, y)
    x = zf.copy()
    x[:, 0], x[:, 1], x[:, 2], x[:, 3] = out[:, 0].real, out[:, 0].imag, out[:, 1].real, out[:, 1].imag
    return x.reshape(z.shape), y.reshape(shape)
