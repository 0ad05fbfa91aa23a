"""The mission loop's physics, compiled with numba (``cache=True``): the one implementation.

Every formula of a mission step lives here once: the link's step (:func:`_step`) on the exact coupled
modes of eq. 1 with the SBAR's v2 from the harmonic balance (eq. 9 with its quadrature) and the
instantaneous peak (:mod:`wpt_receiver.modal_kernel`: modes per Lm and ZOH per dt cached in the work
array ``lw``, exact energy integrals), the battery ECM step, the CC-CV charger (BMS), the implicit VL
solve, the depletion cut, the row layout, pad gating and the fine/coarse windows. Eq. 4's 2x2 ZOH
(:func:`link_step`, :func:`link_stored_j`; :func:`link_disc`, plain Python, takes its coefficients from
:func:`wpt_receiver.envelope.zoh_discretise`) stays as the envs' link model's reference
(``tests/test_env_devices.py``); the mission loop does not use it. :class:`~.loop.MissionLoop` (Python) only orchestrates: it packs the
constants and the state (:mod:`.fastpath`), calls :func:`advance`, hands rows over, calls a Python
policy when the kernel asks for a duty, draws the sensor noise and words the errors.

**Records, not slot numbers.** ``s`` is a 1-element array of :data:`STATE_DTYPE` (the loop's state
by name: ``st = s[0]; st.soc``), ``c`` one of :data:`CONST_DTYPE` (the constants), ``smp`` the
trajectory samples (:data:`SAMPLE_DTYPE`: time, Lm, k, propulsion power, energising flag), ``rows``
``(capacity, 26)`` the time series in :data:`~.loop._COLUMNS` order.

**Resumable.** :func:`advance` runs from the state's cursor (sample ``k``; inside an interval: time
``t`` and ``sub``, the point of the iteration) and returns a status when Python has to act:

==============  ======================================================================================
``DONE``        sample ``k0 + len(smp) - 1`` reached (the end of the trajectory, or of a chunk of it)
``PAUSED``      sample ``k_stop`` reached (progress bar; call again with a larger ``k_stop``)
``FULL``        ``rows`` has no room for one more iteration: hand the rows over, set ``n_rows = 0``
``NEED_ACT``    a duty is due and the policy is Python: ``obs`` holds the normalised observation;
                write the policy's output to ``duty_in``, set ``duty_ready`` and call again
``NEED_NOISE``  the sensor-noise buffer is used up: refill ``noise`` (standard normals), ``noise_i = 0``
``DEPLETED``    the battery reached SoC 0 (the run ends there: ``depleted_at``, ``depleted_k``)
``ERR_POWER``   the battery cannot supply the propulsion power (``err_*`` hold the numbers)
``ERR_POLICY``  the policy's duty is not finite (``duty_in`` holds it)
==============  ======================================================================================

A compiled policy (``Policy.kernel()``, :data:`mission_sim.contract.POLICY_KERNEL_SIGNATURE`) is
passed as ``fn`` and called in place; with ``fn=None`` (a Python policy) the kernel returns
``NEED_ACT`` at the same point (:func:`advance` has both overloads). Both run this same code; they
differ only in who computes the duty. The per-sample arrays may be a chunk of the trajectory
starting at sample ``k0`` (state field); quiet flight looks ahead at most ``sim.flight_dt_s``, so a
chunk should reach that far beyond ``k_stop`` for the same merging. The link model (eq. 4) and its
discretisation are the section "the link": :func:`_link_a`, :func:`link_disc`, :func:`link_step`
(a different link model replaces these; the one other place the model enters is :func:`_settled`'s
closed-form steady state from R1, R2 and omega Lm).

This module imports numba: nothing imports it at module level (:mod:`.fastpath` loads it on the
first run; compiled once per machine, then loaded from numba's disk cache). Tests may run the
functions' ``py_func`` on ``np.recarray`` views of the records (or the whole module with
``NUMBA_DISABLE_JIT=1``): the attribute syntax works on both.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from numba import from_dtype, njit, types
from numba.core.errors import NumbaExperimentalFeatureWarning

from wpt_receiver.modal_kernel import (N_ZOH_C, advance_z, end_i2_affine, inst_peak, modes, phasors, readout,
                                       rect_affine, rect_current_a, refine_level, sbar_implicit, short_weight,
                                       steady_modes, stored_energy_j, zoh)
from wpt_receiver.modal_kernel import step as modal_step

from wpt_receiver.modal_link import SOURCES as _LINK_SOURCES
from wpt_receiver.kernel_cache import drop_stale_cache

from .. import contract as _contract
from ..contract import OBS_DIM
from . import loop_records as _loop_records
from .loop_records import (  # noqa: F401 - the records and status codes, one definition each (numba-free)
    CONST_DTYPE, DEPLETED, DONE, ERR_POLICY, ERR_POWER, FULL, LW_SIZE, NEED_ACT, NEED_NOISE, OK, PAUSED, SAMPLE_DTYPE,
    STATE_DTYPE, STATUS_NAMES, _LW_KEYS, _LW_LM, _LW_MODES, _LW_NEXT, _LW_PER_ROLE, _LW_SLOTS, _LW_ZOH, _NEED_DEPLETE,
    ocv_cell)


def _here():
    """This file, for :func:`wpt_receiver.kernel_cache.drop_stale_cache`."""


# numba's cache of this module holds the link kernel's code, its layout's, the contract's and the records' constants:
# dropped when those files change (numba keys the cache on this file alone)
drop_stale_cache(_here, (*_LINK_SOURCES, _contract, _loop_records))

__all__ = ["advance", "advance_for", "link_disc", "link_step", "link_stored_j", "LW_SIZE", "STATE_DTYPE",
           "CONST_DTYPE", "SAMPLE_DTYPE", "OK", "DONE", "PAUSED", "FULL", "NEED_ACT", "NEED_NOISE", "DEPLETED",
           "ERR_POWER", "ERR_POLICY", "STATUS_NAMES"]

_E0, _N_ENERGY = 15, 11   # the rows' energy columns (e_source_j .. e_rectifier_switches_j, loop._COLUMNS)
_SOC_COL = 12
_FINE_COL = 14
_FOUR_PI = 4.0 / math.pi
_F8 = types.float64[::1]
POLICY_FN = types.FunctionType(types.float64(_F8, _F8, _F8))


# ---------------------------------------------------------------------- the link (paper eq. 4)
@njit(cache=True)
def _link_a(c, lm_h):
    """``A`` of ``dx/dt = A x + B u`` (eq. 4, x = (I1, I2), u = (V1, V2)): (a00, a01, a10, a11) [1/s]."""
    wlm = c.omega * lm_h
    return -c.st_r1 / (2 * c.l1), -wlm / (2 * c.l1), wlm / (2 * c.l2), -c.st_r2 / (2 * c.l2)


def link_disc(c, lm_h, dt_s):
    """The coefficients :func:`link_step` takes for eq. 4 over ``dt_s``, in plain Python from
    :func:`wpt_receiver.envelope.zoh_discretise` (the one ZOH of the 2x2 link; this module kept a second, compiled
    copy with the old real-pole form until 2026-11-27): ``(Ad 00, 01, 10, 11, Bd 00, 01, 10, 11, A^-1 00, 01,
    10, 11, m10, m11, g1, g2)``; ``S2 = int I2 dt = m10 I1 + m11 I2 + g1 V1 + g2 V2`` (eq. 4's reference, the envs'
    link; the mission uses :mod:`wpt_receiver.modal_kernel`)."""
    from wpt_receiver.envelope import zoh_discretise
    c = np.rec.array(np.asarray(c).reshape(1))[0]      # a record (np.void has no attribute access)
    a00, a01, a10, a11 = _link_a.py_func(c, lm_h)
    ad, bd = zoh_discretise(np.array([[a00, a01], [a10, a11]]), np.diag([c.b0, c.b1]), dt_s)
    det = a00 * a11 - a01 * a10
    i00, i01, i10, i11 = a11 / det, -a01 / det, -a10 / det, a00 / det
    m10, m11 = bd[1, 0] / c.b0, bd[1, 1] / c.b1          # Bd = M B, M = A^-1 (Ad - I), B diagonal
    g1 = i10 * (bd[0, 0] - c.b0 * dt_s) + i11 * bd[1, 0]   # g = A^-1 (Bd - B dt)
    g2 = i10 * bd[0, 1] + i11 * (bd[1, 1] - c.b1 * dt_s)
    return tuple(float(v) for v in (*ad.ravel(), *bd.ravel(), i00, i01, i10, i11, m10, m11, g1, g2))


@njit(cache=True)
def _zoh(dd, a0, a1, v1, v2):
    """``x1 = Ad x0 + Bd u`` with ``dd`` from :func:`link_disc`."""
    return dd[0] * a0 + dd[1] * a1 + dd[4] * v1 + dd[5] * v2, dd[2] * a0 + dd[3] * a1 + dd[6] * v1 + dd[7] * v2


@njit(cache=True)
def _lyap_rows(c, lm_h):
    """Rows 1 and 3 of the inverse of the 3x3 Lyapunov map (p11, p12, p22) -> (q11, q12, q22), by cofactors."""
    a00, a01, a10, a11 = _link_a(c, lm_h)
    m00, m01, m02 = 2 * a00, 2 * a01, 0.0
    m10, m11, m12 = a10, a00 + a11, a01
    m20, m21, m22 = 0.0, 2 * a10, 2 * a11
    c00 = m11 * m22 - m12 * m21
    c01 = -(m10 * m22 - m12 * m20)
    c02 = m10 * m21 - m11 * m20
    det = m00 * c00 + m01 * c01 + m02 * c02
    return (c00 / det, -(m01 * m22 - m02 * m21) / det, (m01 * m12 - m02 * m11) / det,
            c02 / det, -(m00 * m21 - m01 * m20) / det, (m00 * m11 - m01 * m10) / det)


@njit(cache=True)
def link_step(c, dd, lm_h, dt_s, a0, a1, v1, v2):
    """One exact ZOH step of eq. 4 from ``(a0, a1) = (I1, I2)`` with ``(V1, V2)`` held, ``dd`` =
    :func:`link_disc` ``(c, lm_h, dt_s)``; returns ``(I1, I2, e_src_j, e_coil_j, e_rect_j, int_i2, p11, p22)``.

    ``S = int x dt = A^-1 (x1 - x0 - B u dt)``; ``P = int x x^T dt`` from the Lyapunov identity
    ``A P + P A^T = x1 x1^T - x0 x0^T - B u S^T - S u^T B^T``. Energies (envelope powers are ``V I / 2``):
    source ``V1 S1 / 2``, coils + folded devices ``(R1 P11 + R2 P22) / 2``, rectifier ``V2 S2 / 2``; with
    ``W`` = :func:`link_stored_j` they satisfy ``source = dW + losses + rectifier`` to rounding."""
    y0, y1 = _zoh(dd, a0, a1, v1, v2)
    bu0, bu1 = c.b0 * v1, c.b1 * v2
    r0 = y0 - a0 - bu0 * dt_s
    r1 = y1 - a1 - bu1 * dt_s
    s0 = dd[8] * r0 + dd[9] * r1
    s1 = dd[10] * r0 + dd[11] * r1
    q11 = y0 * y0 - a0 * a0 - 2 * bu0 * s0
    q12 = y0 * y1 - a0 * a1 - (bu0 * s1 + s0 * bu1)
    q22 = y1 * y1 - a1 * a1 - 2 * bu1 * s1
    l = _lyap_rows(c, lm_h)
    p11 = l[0] * q11 + l[1] * q12 + l[2] * q22
    p22 = l[3] * q11 + l[4] * q12 + l[5] * q22
    return y0, y1, 0.5 * v1 * s0, 0.5 * (c.st_r1 * p11 + c.st_r2 * p22), 0.5 * v2 * s1, s1, p11, p22


@njit(cache=True)
def link_stored_j(c, a0, a1):
    """Stored energy of the envelope model ``(L1 I1^2 + L2 I2^2) / 2`` [J]."""
    return 0.5 * (c.l1 * a0 * a0 + c.l2 * a1 * a1)


@njit(cache=True)
def _track_peak(st, c, lk, i2c, d, dt_each, vl, live, blocked):
    """Running peaks: of the i2 fundamental |I2| (and the duty there), of the instantaneous |i2| (the
    SBAR's harmonic ripple added, :func:`wpt_receiver.modal_kernel.inst_peak` at the clamp ``VL + Vf``, while
    it conducts, ``live``: :func:`_sbar_live`, and not ``blocked`` by the protection: :func:`_sbar_v2`; else no
    ripple), and the time |I2| is above rated (``dt_each`` per value)."""
    a = abs(i2c)
    if a > st.peak_env:
        st.peak_env, st.peak_d = a, d
    pk = inst_peak(lk[0], lk[1], d, i2c, vl + c.vf) if live and not blocked else a
    if pk > st.peak_inst:
        st.peak_inst = pk
    if a > c.rated:
        st.above += dt_each


# ---------------------------------------------------------------------- SBAR, battery, charger
#: :func:`.loop_records.ocv_cell` compiled (one source; the kernel's OCV)
_ocv_cell = njit(cache=True)(ocv_cell)


@njit(cache=True)
def _bat_step(c, soc, v1_v, i, dt_s):
    """Battery ECM step, current ``i`` [A] held (exact; OCV held at its start-of-step value):
    ``(soc1, v1_1, chem_j, r0_loss_j, r1_loss_j, c1_delta_j)`` (:mod:`.battery`)."""
    e = math.exp(-dt_s / c.tau1)
    vinf = c.r1b * i
    dv = v1_v - vinf
    int_v2 = vinf * vinf * dt_s + 2.0 * vinf * dv * c.tau1 * (1.0 - e) + dv * dv * 0.5 * c.tau1 * (1.0 - e * e)
    ocv = c.n_cells * _ocv_cell(soc)
    dq = i * dt_s
    v1n = vinf + dv * e
    return (soc + dq / c.capacity_c, v1n, ocv * dq, c.r0 * i * i * dt_s, int_v2 / c.r1b,
            0.5 * c.bat_c1 * (v1n * v1n - v1_v * v1_v))


@njit(cache=True)
def _charger_command(st, c, i_prop):
    """CC-CV charge manager (:mod:`.battery`, :class:`.battery.CcCvParams`): the SBAR command ``I_L*`` [A], the load
    current ``i_prop`` (propulsion + avionics) plus the battery's CC/CV current (at most ``cc_a``); when full the load
    current plus the CV current where that is negative, ``max(i_prop + min(0, (V_cv - OCV - v1) / R0), 0)`` (the
    charger's power path: the input feeds the load and the pack is held at the CV voltage, not pushed above it by a
    receiver delivering more than the load), and 0 (short mode) above the over-voltage trip ``v_trip``; ``full`` and
    ``cv`` clear once ``OCV + v1`` falls below the recharge threshold (and when a pad switches on:
    :func:`_gate_pad`)."""
    v_rest = c.n_cells * _ocv_cell(st.soc) + st.vrc
    if st.full and v_rest < c.v_recharge:
        st.full, st.cv = False, False
    i_cv = (c.v_cv - v_rest) / c.r0
    if i_cv < c.cc_a:
        st.cv = True
    tgt = min(c.cc_a, i_cv)
    if st.cv and tgt < c.cutoff_a:
        st.full = True
    if st.full:
        return 0.0 if v_rest > c.v_trip else max(i_prop + min(0.0, i_cv), 0.0)
    return max(tgt, 0.0) + i_prop


# ---------------------------------------------------------------------- link + battery node
@njit(cache=True)
def _solve_vl(st, c, dt, il0, il1, p_prop):
    """The battery node's VL [V] for the step (NaN if the battery cannot supply ``p_prop``; err_pmax set).

    Mean terminal voltage = A0 + G i_mean (held-current RC solution) and ``i_mean = I_L - P / VL`` with
    the rectified current affine in VL, ``I_L = il0 + il1 VL`` (:func:`wpt_receiver.modal_kernel.rect_affine`):
    a quadratic in VL, so V2, the battery and the propulsion power agree exactly and every energy closes
    to rounding."""
    frac = c.tau1 * (1.0 - math.exp(-dt / c.tau1)) / dt
    a0 = c.n_cells * _ocv_cell(st.soc) + st.vrc * frac
    g = c.r0 + c.r1b * (1.0 - frac)
    alpha = 1.0 - g * il1
    beta = a0 + g * il0
    disc = beta * beta - 4 * alpha * g * p_prop
    if disc < 0:
        st.err_pmax = beta * beta / (4 * alpha * g)
        return math.nan
    return (beta + math.sqrt(disc)) / (2 * alpha)


@njit(cache=True)
def _modes_of(lk, lm_h):
    """The exact modes at ``lm_h`` (:func:`wpt_receiver.modal_kernel.modes`), cached in the work array ``lw``."""
    lc, tab, lw = lk
    mc = lw[_LW_MODES:_LW_ZOH]
    if lw[_LW_LM].real != lm_h:
        modes(lc, lm_h, mc)
        lw[_LW_LM] = lm_h
        for j in range(_LW_SLOTS):
            lw[_LW_KEYS + j] = math.nan
    return mc


@njit(cache=True)
def _coefs(lk, lm_h, dt, role):
    """``(modes, ZOH over dt)`` at ``lm_h``: the ZOH kept in one of ``role``'s slots (0: a step, 1: its peak
    samples), found by its length, else made in the role's next slot (round robin; the other role's slots,
    in use by the same step, are never replaced)."""
    lw = lk[2]
    mc = _modes_of(lk, lm_h)
    lo = role * _LW_PER_ROLE
    for j in range(lo, lo + _LW_PER_ROLE):
        if lw[_LW_KEYS + j].real == dt:
            return mc, lw[_LW_ZOH + N_ZOH_C * j:_LW_ZOH + N_ZOH_C * (j + 1)]
    nxt = lw[_LW_NEXT + role].real
    j = lo + (0 if math.isnan(nxt) else int(nxt))
    lw[_LW_NEXT + role] = (j - lo + 1) % _LW_PER_ROLE
    zc = lw[_LW_ZOH + N_ZOH_C * j:_LW_ZOH + N_ZOH_C * (j + 1)]
    zoh(mc, dt, zc)
    lw[_LW_KEYS + j] = dt
    return mc, zc


@njit(cache=True)
def _ringing(st, c):
    """The coil currents at the last step's end have not died out (|I1| or |I2| >= ``settle_i2_tol_a``)."""
    return st.x0 >= c.settle_i2_tol or abs(st.x1) >= c.settle_i2_tol


@njit(cache=True)
def _protecting(st, c):
    """The receiver's protection holds the SBAR at d = 0 (plain diode rectification: both low-side switches off):
    the pad's V1 has reached 0 after its ramp while the coil currents still ring (:func:`_ringing`), with
    ``sim.rectify_after_pad_off`` (default). The receiver sees its input collapse; the tanks' energy then goes into
    the battery through the diodes until the currents have died out. The policy's duty is held, not applied: the
    rows record the applied duty (0). With the option off, v2 = 0 from the step V1 reaches 0 (a shorted secondary,
    the model before 2026-11-28: the two shorted tanks ring freely and the primary's energy beats into the secondary
    within ~1/(2 k f) = 79 us at k = 0.075; the short-mode / upper case, docs/mission.md "Pad switch-off")."""
    return c.rectify_off and st.v1 == 0.0 and _ringing(st, c)


@njit(cache=True)
def _sbar_live(st, c, fine):
    """Whether the SBAR's v2 acts in a step: with the pad on, and in fine steps while the protection holds d = 0
    after the pad's V1 has reached 0 (:func:`_protecting`). Otherwise v2 = 0 (the pad off: no current flows, or
    with ``sim.rectify_after_pad_off`` false the shorted secondary). Coarse steps with the pad off keep v2 = 0 (the
    fine window does not end while the protection's diodes conduct: :func:`_window_done`; once they block, a coarse
    step carries the ring-down in fine pieces, one row: :func:`_coarse_step`)."""
    return st.v1 > 0.0 or (fine and _protecting(st, c))


@njit(cache=True)
def _applied_duty(st, c, live):
    """The duty the SBAR applies in a step: the policy's, or 0 while the protection holds (:func:`_protecting`;
    ``live`` with V1 = 0 is exactly that case)."""
    return 0.0 if (live and st.v1 == 0.0) else st.d


@njit(cache=True)
def _sbar_v2(st, c, lk, mc, zc, v1c, live, d):
    """SBAR input of the step: ``(F, v2x)`` with ``V2 = F VL + v2x`` held over it: the clamp part per volt
    (eq. 9 with its quadrature, at the last VL; the commutation implicit,
    :func:`wpt_receiver.modal_kernel.sbar_implicit`) plus the forward drops and the shorted switches'
    excess ``(2 Ron - Rd) w(d) I2`` at the applied duty ``d`` (:func:`_applied_duty`); 0 when the SBAR does not act
    (``live`` False: :func:`_sbar_live`)."""
    if not live:
        return 0j, 0j, False
    if st.v1 == 0.0:
        # the protection (d = 0, diodes only) after the pad's switch-off: the diodes block when the V2 that holds
        # the step's end I2 at 0 lies within the clamp's fundamental (4/pi)(VL + Vf): the envelope's
        # always-conducting clamp cannot carry current below it (there it flips its sign step to step, ringing at
        # ~2 A and rectifying backwards); else they conduct (the clamp, below). Real diodes conduct
        # (discontinuously) once the emf w Lm I1 passes VL + Vf, neglected here: SwitchingLink from I2 = 0 at
        # emf / (VL + Vf) 1.1 / 1.2 / 1.27 gives 0.13 / 0.58 / 1.17 A, 0.3 / 3.2 / 7.4 % of the primary's stored
        # energy into the battery; a d = 0 drift switch-off at 1.22: 1.2 of 26 mJ vs the kernel's 0.4 mJ
        # (tests/test_pad_switch_off.py, docs/mission.md "Pad switch-off")
        vc = st.last_vl + c.vf
        z0, z1 = complex(st.z[0], st.z[1]), complex(st.z[2], st.z[3])
        q0, q1 = end_i2_affine(mc, zc, z0, z1, v1c)
        vb = -q0 / q1
        if abs(vb) <= _FOUR_PI * vc:
            f = vb / vc
            return f, f * c.vf, True
    ws = c.dr_short * short_weight(d)
    f, i2e, _ = sbar_implicit(lk[0], lk[1], mc, zc, complex(st.z[0], st.z[1]), complex(st.z[2], st.z[3]), v1c,
                           complex(st.v2re, st.v2im), d, st.last_vl + c.vf, ws)
    return f, f * c.vf + ws * i2e, False


@njit(cache=True)
def _step(st, c, lk, rows, t0, dt, lm, p_prop, row_k, fine):
    """Link (exact modes, ZOH, :mod:`wpt_receiver.modal_kernel`) and battery node over one step, VL solved
    implicitly; writes a row. OK, ERR_POWER, or _NEED_DEPLETE (SoC < 0: nothing written, I_b in tmp_ib).

    The SBAR's v2 follows i2's phase (its clamp part per volt ``F``, eq. 9 with the quadrature of the
    shifted commutation), with the pad on, and at d = 0 (the protection, blocking or conducting) while the coil
    currents ring after the pad's V1 reached 0 (:func:`_protecting`) in a step taken with ``fine``
    (:func:`_sbar_live`): the fine window's steps while the protection's diodes conduct (the window does not end then:
    :func:`_window_done`), and once they block the pieces of at most ``dtc`` in which a coarse step carries the
    ring-down, merged into its one coarse row (:func:`_coarse_step`); otherwise v2 = 0.
    The link energies close per step with ``W`` at the step's inputs; the stored energy of the
    feedthrough when the inputs change between steps (``jump``) is booked to the rectifier."""
    lc, tab, lw = lk
    v1 = st.v1
    lm_eff = lm if lm > 0 else 1e-12
    mc, zc = _coefs(lk, lm_eff, dt, 0)
    v1c = complex(0.0, -v1)          # v1 = V1 sin(w t)
    live = _sbar_live(st, c, fine)
    d = _applied_duty(st, c, live)   # the row records it
    f, v2x, blocked = _sbar_v2(st, c, lk, mc, zc, v1c, live, d)
    il0, il1 = rect_affine(mc, zc, dt, st.z, v1c, f, v2x)
    vl = _solve_vl(st, c, dt, il0, il1, p_prop)
    if math.isnan(vl):
        st.err_t, st.err_p, st.err_soc, st.err_k = t0, p_prop, st.soc, row_k
        return ERR_POWER
    v2 = f * vl + v2x
    z = st.z.copy()
    jump = stored_energy_j(lc, mc, z, v1c, v2, lm_eff) - st.w_end
    nq = 4   # peak samples of a fine step: its quarter points, and at least one per rectifier period (a
    # fine step in short mode is not divided: its ringing's crest would fall between quarter points)
    if fine:
        nq = max(4, math.ceil(dt / c.t_rect - 1e-9)) if c.t_rect > 0.0 else 4
        zc4 = _coefs(lk, lm_eff, dt / nq, 1)[1]
        zq = z.copy()
        for _ in range(nq - 1):
            advance_z(mc, zc4, zq, v1c, v2)
            _track_peak(st, c, lk, phasors(mc, zq, v1c, v2)[1], d, dt / nq, vl, live, blocked)
    out = np.empty(9)
    modal_step(lc, mc, zc, dt, z, v1c, v2, out)
    i_l = rect_current_a(f, complex(out[2], out[3]), dt)
    i_p = p_prop / vl
    i_b = i_l - i_p
    soc, vrc, e_chem, e_r0, e_r1, e_c1 = _bat_step(c, st.soc, st.vrc, i_b, dt)
    if soc < 0.0 and math.isnan(st.depleted_at):
        st.tmp_ib = i_b
        return _NEED_DEPLETE
    i1n, i2n = phasors(mc, z, v1c, v2)
    _track_peak(st, c, lk, i2n, d, dt / nq if fine else dt, vl, live, blocked)
    a2 = abs(i2n)
    y0, y1 = abs(i1n), (a2 if i2n.real >= 0.0 else -a2)
    st.z[:] = z
    st.v2re, st.v2im, st.w_end = v2.real, v2.imag, stored_energy_j(lc, mc, z, v1c, v2, lm_eff)
    st.x0, st.x1, st.soc, st.vrc, st.p11, st.p22 = y0, y1, soc, vrc, out[4], out[5]
    st.last_vl, st.last_ib, st.last_il, st.prot_blocked = vl, i_b, i_l, blocked
    e_out = vl * i_l * dt
    # v2's fundamental in phase with i2 (while the protection's diodes block, |I2| ~ 1e-10 A: its phase is rounding)
    v2_row = (v2 * i2n.conjugate()).real / a2 if a2 > 0.0 and not blocked else v2.real
    _write_row(st, c, rows, (t0 + dt, dt, float(row_k), lm, v1, y0, y1, d, v2_row, i_l, vl, i_b, soc, st.cmd,
                             1.0 if fine else 0.0, out[6]), out[7] + out[8] - jump - e_out, i_l * dt,
               short_weight(d), e_out, e_chem, e_r0, e_r1, e_c1, vl * i_p * dt)
    return OK


@njit(cache=True)
def _write_row(st, c, rows, head, e_loss, charge_c, w_short, e_out, e_chem, e_r0, e_r1, e_c1, e_prop):
    """Append one row: ``head`` (16 values), then the energies, with the link losses ``e_loss`` (coils +
    devices) split: the coils take ``(R1 P11 + R2 P22) / 2``, the inverter its folded 2 Ron's share, the
    rectifier diodes ``Vf0 * charge`` plus their Rd's share outside the short window, the rectifier
    switches what is left (so the four add up to ``e_loss`` exactly)."""
    e_inv = 0.5 * c.inv_r * st.p11
    e_dio = c.vf0 * charge_c + 0.5 * c.rd * st.p22 * (1.0 - w_short)
    e_coil = 0.5 * (c.coil_r1 * st.p11 + c.coil_r2 * st.p22)
    e_sw = 0.0 if c.is_ideal else e_loss - e_coil - e_inv - e_dio
    row = rows[st.n_rows]
    for j in range(16):
        row[j] = head[j]
    row[16] = e_loss if c.is_ideal else e_coil
    row[17], row[18], row[19], row[20], row[21], row[22] = e_out, e_chem, e_r0, e_r1, e_c1, e_prop
    row[23], row[24], row[25] = e_inv, e_dio, e_sw
    st.n_rows += 1


@njit(cache=True)
def _deplete(s, c, lk, rows, t0, dt, lm, p_prop, row_k, fine):
    """The battery reaches SoC 0 inside this step: cut the step there and end the mission (DEPLETED).

    SoC is linear in time for the step's held current, so it crosses 0 after ``h = SoC0 Q / -I_b``;
    I_b depends a little on the step length (VL is solved with the battery), so ``h`` is refined by
    re-running the step (fixed point; the state before it restored between tries). The cut step is
    the run's last row, with SoC 0 to rounding (1e-9)."""
    st = s[0]
    i_b, soc0 = st.tmp_ib, st.soc
    saved = s.copy()
    st.depleted_at = t0
    h = dt
    for _ in range(20):
        h = min(dt, soc0 * c.capacity_c / -i_b) if i_b < 0.0 else dt
        if h <= 1e-12:  # already empty at t0
            h = 0.0
            break
        if _step(st, c, lk, rows, t0, h, lm, p_prop, row_k, fine) == ERR_POWER:
            return ERR_POWER
        if abs(st.soc) <= 1e-9:
            break
        i_b = st.last_ib
        s[0] = saved[0]          # the row is dropped with n_rows
        st = s[0]
        st.depleted_at = t0
    if h > 0.0 and st.soc < 0.0:
        st.soc = 0.0
        rows[st.n_rows - 1, _SOC_COL] = 0.0
    st.depleted_at, st.depleted_k = t0 + h, row_k
    return DEPLETED


@njit(cache=True)
def _step_d(s, c, lk, rows, t0, dt, lm, p_prop, row_k, fine):
    """:func:`_step`, running :func:`_deplete` when the battery runs out in it."""
    r = _step(s[0], c, lk, rows, t0, dt, lm, p_prop, row_k, fine)
    if r == _NEED_DEPLETE:
        return _deplete(s, c, lk, rows, t0, dt, lm, p_prop, row_k, fine)
    return r


@njit(cache=True)
def _coarse_step(s, c, lk, rows, t0, dt, lm, p_prop, row_k):
    """A coarse step (:func:`_step_d`); while the protection holds d = 0 with its diodes blocking
    (``prot_blocked``: I2 held at 0, the primary decays on its own in R1 + 2 Ron over 2 L1 / (R1 + 2 Ron), up to
    seconds with small R1) it is carried in fine steps of at most ``dtc`` (:func:`_fine_step`, the blocked v2
    decided per step: a v2 held over a long step cannot keep I2 at 0 within it, the beat would drain the primary
    into R2) until the currents have died out, then one step with v2 = 0; merged into one row (a coarse row:
    ``fine`` 0), so the fine window ends at ``max_fine_s`` (:func:`_window_done`) and the rows stay bounded."""
    st = s[0]
    if not (_protecting(st, c) and st.prot_blocked):
        return _step_d(s, c, lk, rows, t0, dt, lm, p_prop, row_k, False)
    n0 = st.n_rows
    t, t_end = t0, t0 + dt
    while t < t_end - 1e-12:
        st = s[0]
        if _protecting(st, c):
            h = min(c.dtc, t_end - t)
            r = _fine_step(s, c, lk, rows, t, h, lm, p_prop, row_k)
        else:
            h = t_end - t
            r = _step_d(s, c, lk, rows, t, h, lm, p_prop, row_k, False)
        _merge_rows(s[0], rows, n0)
        rows[n0, _FINE_COL] = 0.0
        if r != OK:
            return r
        t += h
    return OK


@njit(cache=True)
def _sub_step(s, saved, c, lk, rows, t0, h, lm, p_prop, row_k):
    """One rectifier-period sub-step of a fine step (:func:`_step_d`), redone in 2^L pieces of ``h / 2^L`` when
    its I2 moved too much for one V2 (:func:`wpt_receiver.modal_kernel.refine_level`: the end I2 phasor off the
    start's by more than ``refine_tol`` of |I2|, L at most ``refine_levels``; the env's criterion and levels).

    V2 decided at the sub-step's end and held over it is a backward-Euler step on the envelope mode the clamp's
    load makes (~2 rectifier periods at 11 A): in a large transient (a step's charge start) it damps and delays the
    ringing. Each piece is a full :func:`_step` (V2 implicit at its end, the battery node solved with it, its
    row, the peak samples), so the energies close per piece as per step; the unrefined try is undone by restoring
    the state (``saved``, a scratch copy of ``s``; its row dropped with ``n_rows``). Below the tolerance the
    sub-step is the one before, to the bit."""
    if c.refine_levels <= 0:
        return _step_d(s, c, lk, rows, t0, h, lm, p_prop, row_k, True)
    st = s[0]
    mc = _modes_of(lk, lm if lm > 0 else 1e-12)
    v1c = complex(0.0, -st.v1)
    i2s = phasors(mc, st.z, v1c, complex(st.v2re, st.v2im))[1]
    saved[0] = s[0]
    r = _step_d(s, c, lk, rows, t0, h, lm, p_prop, row_k, True)
    if r != OK:
        return r
    st = s[0]
    lev = refine_level(i2s, phasors(mc, st.z, v1c, complex(st.v2re, st.v2im))[1], c.refine_tol, c.refine_levels)
    if lev == 0:
        return OK
    s[0] = saved[0]
    m = 1 << lev
    for i in range(m):
        r = _step_d(s, c, lk, rows, t0 + i * (h / m), h / m, lm, p_prop, row_k, True)
        if r != OK:
            return r
    return OK


@njit(cache=True)
def _fine_step(s, c, lk, rows, t0, dt, lm, p_prop, row_k):
    """A fine step, in rectifier-period sub-steps while the SBAR rectifies (pad on, d < 1).

    The SBAR's v2 follows i2 (its phase and, through the commutation, its size) every half cycle;
    holding the v2 of the step's start over a step that is a sizeable part of the envelope's beat
    period would feed the beat instead of damping it. So v2 is updated every rectifier period
    T = 1/(2f) (the duty is held: the policy is not called). A sub-step whose I2 moves by more than
    ``refine_tol`` of |I2| is redone in pieces (:func:`_sub_step`, the env's criterion): near a tolerance the
    stepping depends on the last bits of the state, as the env's does (docs/performance.md)."""
    st = s[0]
    live = _sbar_live(st, c, True)
    if live and _applied_duty(st, c, live) < 1.0:
        k_sub = math.ceil(dt / c.t_rect - 1e-9) if dt > 1.5 * c.t_rect else 1
        h = dt / k_sub
        n0 = st.n_rows
        saved = s.copy()
        for j in range(k_sub):
            r = _sub_step(s, saved, c, lk, rows, t0 + j * h, h, lm, p_prop, row_k)
            if r != OK:
                return r
        _merge_rows(s[0], rows, n0)
        return OK
    return _step_d(s, c, lk, rows, t0, dt, lm, p_prop, row_k, True)   # short mode, or pad off and not protecting: V2 = 0


@njit(cache=True)
def _merge_rows(st, rows, n0):
    """The rows ``n0..`` of one fine step's sub-steps as one row: the state at its end, ``dt`` and every
    energy summed (exactly the sub-steps' sums), the battery current as its mean over the step and the
    rectifier current as the one that delivers the step's rectifier energy at the stored VL (``e_rectifier_j =
    battery_v rect_current_a dt_s`` holds row by row), so the stored series has one row per control period."""
    if st.n_rows - n0 <= 1:
        return
    out, last = rows[n0], rows[st.n_rows - 1]
    dt, q_rect, q_bat = out[1], out[9] * out[1], out[11] * out[1]
    for i in range(n0 + 1, st.n_rows):       # energies summed into the first row, in place
        r = rows[i]
        dt += r[1]
        q_rect += r[9] * r[1]
        q_bat += r[11] * r[1]
        for j in range(_E0, _E0 + _N_ENERGY):
            out[j] += r[j]
    for j in range(_E0):
        out[j] = last[j]
    out[1], out[11] = dt, q_bat / dt
    out[9] = out[17] / (out[10] * dt) if out[10] != 0.0 else q_rect / dt   # e_rectifier_j / (battery_v dt)
    st.n_rows = n0 + 1


# ---------------------------------------------------------------------- policy, windows
@njit(cache=True)
def _duty(st, c, t, noise, obs, fn, params, pstate):
    """The policy's duty at ``t``: ``(status, d)``. The observation per the contract (measured |I2| plus
    the sensor noise ``noise_a * noise[noise_i]``, time since the command went to 0 saturating at 1 s here,
    10 ms in the contract), normalised into ``obs``; then the compiled policy ``fn``, or NEED_ACT for a
    Python one (``fn`` None; its output comes back in ``duty_in``). d is clipped into [0, 1]; not finite: ERR_POLICY."""
    if st.duty_ready:
        st.duty_ready = False
        out = st.duty_in
    else:
        i2m = abs(st.x1)
        if c.noise_a > 0.0:
            if st.noise_i >= len(noise):
                return NEED_NOISE, 0.0
            i2m = i2m + c.noise_a * noise[st.noise_i]
            st.noise_i += 1
        else:
            i2m = i2m + 0.0
        t_since = min(t - st.t_cmd_zero, 1.0) if st.cmd == 0.0 else 0.0
        vals = (i2m, st.last_vl, st.last_ib, st.last_il, st.soc, st.cmd, st.d, t_since)
        for j in range(OBS_DIM):
            obs[j] = min(max(2.0 * (vals[j] - c.obs_lo[j]) * c.obs_inv[j] - 1.0, -1.0), 1.0)
        if fn is None:      # a Python policy (this branch is resolved at compile time)
            return NEED_ACT, 0.0
        out = fn(obs, params, pstate)
    if not math.isfinite(out):
        st.duty_in = out
        return ERR_POLICY, 0.0
    return OK, min(max(out, 0.0), 1.0)


@njit(cache=True)
def _open_window(st, c, t):
    """Start a fine window at t (lasts at least ``min_fine_s``, at most ``max_fine_s``)."""
    st.in_fine = True
    st.n_windows += 1
    st.fine_until_min = t + c.min_fine
    st.fine_deadline = t + c.max_fine


@njit(cache=True)
def _settled(st, c, lk, lm):
    """V1 at its target and I2 within ``settle_i2_tol_a`` of the steady state for the held inputs (pad
    off: the coil currents have died out)."""
    v1, tol = st.v1, c.settle_i2_tol
    if abs(v1 - (c.v1_nom if st.tx_on else 0.0)) > 0.0:
        return False
    if v1 == 0.0:
        return not _ringing(st, c)
    mc = _modes_of(lk, lm if lm > 0 else 1e-12)
    v1c, v2 = complex(0.0, -v1), complex(st.v2re, st.v2im)
    zs0, zs1 = steady_modes(mc, v1c, v2)
    return abs(phasors(mc, st.z, v1c, v2)[1] - readout(mc, 1, zs0, zs1, v1c, v2)) < tol


@njit(cache=True)
def _answering(st):
    """True while the receiver is shorted (d = 1, the clip) with a positive charge command and the pad on.

    Short mode delivers no charge current (I_L = 0 < I_L*), so no charging controller rests there: the
    policy is still moving towards rectification, possibly hidden behind the clip (a stateful policy's
    V2* below 0 V, e.g. ``model_based_budget``'s relaxed reference held while the command was 0). A
    real receiver's DSP runs it every control period until the duty leaves 1; so does the fine window
    (up to ``sim.max_fine_s``). A policy called once per coarse period instead would advance its filter
    by one control period per call and stay shorted for seconds."""
    return st.tx_on and st.cmd > 0.0 and st.d >= 1.0 - 1e-9


@njit(cache=True)
def _window_done(st, c, lk, t, d_prev, lm):
    """Close the fine window once the SBAR output ``1 - sin(pi d / 2)`` and I2 have settled (or at its
    deadline). Settles on V2, not on the duty: near short mode the duty is ill-conditioned (arcsin).

    Not while the receiver is shorted under a positive charge command (:func:`_answering`): the policy
    has not answered the command yet, and outside the window it would be called once per
    ``coarse_policy_period_s`` instead of once per control period. Not at the deadline while the protection holds
    d = 0 after the pad's switch-off with its diodes conducting (:func:`_protecting`; once they block, coarse steps
    carry the ring-down: :func:`_coarse_step`)."""
    dv = abs(math.sin(0.5 * math.pi * st.d) - math.sin(0.5 * math.pi * d_prev))
    if t >= st.fine_until_min and (dv < c.settle_duty_tol or st.v1 == 0.0) and not _answering(st) \
            and _settled(st, c, lk, lm):
        st.in_fine = False
    elif t >= st.fine_deadline and st.v1 == (c.v1_nom if st.tx_on else 0.0) \
            and not (_protecting(st, c) and not st.prot_blocked):
        st.in_fine = False
        st.n_cut += 1


@njit(cache=True)
def _fine_begin(st, c, t_k, t_next, lm, lm_n, fast_lm, off_due):
    """Start of a fine step at ``st.t``: its length and Lm (interpolated in time when Lm changes fast),
    per-step gating and the V1 ramp; the duty is asked for next (``sub`` 3) unless the coarse call's is fresh."""
    t = st.t
    dt = min(c.dtc, t_next - t)
    lm_s = lm
    if fast_lm:
        lm_s = lm + (lm_n - lm) * (t + 0.5 * dt - t_k) / (t_next - t_k)
    st.dt_f, st.lm_s = dt, lm_s
    if fast_lm and st.tx_on and lm_s * c.inv_sqrt_l1l2 < c.k_off:
        st.tx_on = False
        st.cmd = 0.0
    if st.tx_on and st.cmd == 0.0 and off_due and t - st.t_cmd_zero >= c.tx_off_delay:
        st.tx_on = False
    target = c.v1_nom if st.tx_on else 0.0
    if st.v1 != target:
        step_v = c.ramp_rate * dt
        st.v1 = min(target, st.v1 + step_v) if target > st.v1 else max(target, st.v1 - step_v)
    st.d_prev = st.d
    st.sub = 4 if st.fresh else 3


@njit(cache=True)
def _fine_end(s, c, lk, rows, p_k, k, fast_lm):
    """The fine step with the duty applied, then the window end check; the iteration is done (``sub`` 0)."""
    st = s[0]
    st.t_last_act = st.t
    r = _fine_step(s, c, lk, rows, st.t, st.dt_f, st.lm_s, p_k, k)
    if r != OK:
        return r
    st = s[0]
    st.n_fine += 1
    if not (fast_lm and st.v1 > 0.0):
        _window_done(st, c, lk, st.t + st.dt_f, st.d_prev, st.lm_s)
    st.fresh = False
    st.t += st.dt_f
    st.sub = 0
    return OK


@njit(cache=True)
def _coarse_duty(st, c, d_new):
    """A policy call outside a fine window: a duty move above ``duty_event_tol`` opens one (and that
    duty is applied in its first fine step: ``fresh``)."""
    st.t_last_act = st.t
    moved = abs(d_new - st.d) > c.duty_event_tol
    st.d = d_new
    if moved:
        _open_window(st, c, st.t)
    st.fresh = moved
    st.sub = 2


@njit(cache=True)
def _interval(s, c, lk, smp, rows, noise, obs, fn, params, pstate):
    """Sample k's interval ``[t_k, t_k+1)`` from ``st.t``: fine steps while needed, then one coarse step
    (the ZOH step is exact for any length). With the pad on and Lm changing fast (or k crossing the
    switch-off threshold) fine steps use Lm interpolated in time and gating is checked per step.
    Resumable: ``sub`` 0 iteration start, 1 coarse duty due, 2 fine or coarse, 3 fine duty due, 4 fine step."""
    st = s[0]
    k = st.k
    i = k - st.k0
    here, nxt = smp[i], smp[i + 1]
    t_k, t_next, p_k, lm, lm_n = here.t, nxt.t, here.p, here.lm, nxt.lm
    fast_lm = abs(lm_n - lm) > c.lm_rel_tol * max(abs(lm), 1e-9) or nxt.k < c.k_off
    off_due = not here.elig or not nxt.elig
    while st.t < t_next - 1e-12:
        if st.sub == 0:
            if st.n_rows + c.row_margin > rows.shape[0]:
                return FULL
            if fast_lm and st.v1 > 0.0 and not st.in_fine:
                _open_window(st, c, st.t)
            st.sub = 1 if not st.in_fine and st.t - st.t_last_act >= c.coarse_period - 1e-12 else 2
        if st.sub == 1:
            r, d = _duty(st, c, st.t, noise, obs, fn, params, pstate)
            if r != OK:
                return r
            _coarse_duty(st, c, d)
        if st.sub == 2:
            if not st.in_fine:
                r = _coarse_step(s, c, lk, rows, st.t, t_next - st.t, lm, p_k, k)
                if r != OK:
                    return r
                st = s[0]
                st.n_coarse += 1
                st.t, st.sub = t_next, 0
                continue
            _fine_begin(st, c, t_k, t_next, lm, lm_n, fast_lm, off_due)
        if st.sub == 3:
            r, d = _duty(st, c, st.t, noise, obs, fn, params, pstate)
            if r != OK:
                return r
            st.d, st.sub = d, 4
        r = _fine_end(s, c, lk, rows, p_k, k, fast_lm)
        if r != OK:
            return r
        st = s[0]
    st.phase, st.k = 0, k + 1
    return OK


# ---------------------------------------------------------------------- per sample: gating, BMS, quiet flight
@njit(cache=True)
def _gate_pad(st, c, here, t_k, ending):
    """Pad gating (transmitter side) at a sample; True if it is an event (opens a fine window).

    On in an energising phase with ``k >= k_on`` (a new charge cycle: ``full`` and ``cv`` cleared); off at once (ramp down) when ``k < k_off``; at the
    phase's end the command drops to 0 first and the pad stays on ``tx_off_delay_s``."""
    if st.tx_on:
        if here.k < c.k_off:
            st.tx_on = False
            if st.cmd != 0.0:
                st.t_cmd_zero = t_k
            st.cmd = 0.0
        elif not here.elig or ending:
            if st.cmd != 0.0:
                st.cmd = 0.0
                st.t_cmd_zero = t_k
            elif t_k - st.t_cmd_zero >= c.tx_off_delay:
                st.tx_on = False
        else:
            return False
        return True
    if here.elig and not ending and here.k >= c.k_on and st.v1 == 0.0:
        # input power appears: the drone's host starts a new charge cycle (a charger IC's CE toggled), so the
        # charger tops the pack off at every pad visit and terminates again at the cut-off
        st.tx_on, st.full, st.cv = True, False, False
        return True
    return False


@njit(cache=True)
def _bms_command(st, c, here, t_k, ending):
    """Battery management: a new charge command every ``bms_period_s``, applied if it moves by more than the dead band,
    between zero and non-zero, or as the charger enters or leaves *full* (the full command differs from the last CV
    one by about the cut-off current, which the dead band would swallow); True if it changed."""
    if not (st.tx_on and st.v1 == c.v1_nom and here.elig and not ending and t_k - st.t_last_bms >= c.bms_period - 1e-12):
        return False
    st.t_last_bms = t_k
    was_full = st.full
    new = _charger_command(st, c, here.p / st.last_vl)
    if (abs(new - st.cmd) > c.cmd_deadband or (new == 0.0) != (st.cmd == 0.0)
            or (st.full != was_full and new != st.cmd)):
        if new == 0.0:
            st.t_cmd_zero = t_k
        st.cmd = new
        return True
    return False


@njit(cache=True)
def _quiet_flight(s, c, lk, smp, rows, k, t_k):
    """Pad off, nothing pending: samples merged into one step of up to ``flight_dt_s`` with the mean
    propulsion power; the policy is not called (its duty is held). Sets the next sample."""
    st = s[0]
    k0 = st.k0
    n_end = k0 + len(smp)
    j = k + 1
    while j < n_end - 1 and not smp[j - k0].elig and smp[j + 1 - k0].t - t_k <= c.flight_dt + 1e-9:
        j += 1
    dt = smp[j - k0].t - t_k
    acc = 0.0
    for i in range(k - k0, j - k0):
        acc += smp[i].p * (smp[i + 1].t - smp[i].t)
    r = _coarse_step(s, c, lk, rows, t_k, dt, smp[k - k0].lm, acc / dt, k)
    if r == OK:
        st = s[0]
        st.n_coarse += 1
        st.k = j
    return r


@njit(cache=True)
def _begin_sample(s, c, lk, smp, rows):
    """Sample k: gating, BMS (an event opens a fine window), then quiet flight or the interval."""
    st = s[0]
    k = st.k
    here, nxt = smp[k - st.k0], smp[k + 1 - st.k0]
    t_k = here.t
    # "ending": the energising phase ends at the next sample, so charging stops (command 0, then the
    # pad ramps down) while the drone still hovers
    ending = here.elig and not nxt.elig
    event = _gate_pad(st, c, here, t_k, ending)
    event = _bms_command(st, c, here, t_k, ending) or event
    if event:
        _open_window(st, c, t_k)
    if not st.in_fine and not st.tx_on and st.v1 == 0.0 and st.cmd == 0.0:
        return _quiet_flight(s, c, lk, smp, rows, k, t_k)
    st.phase, st.t, st.sub, st.fresh = 1, t_k, 0, False
    return OK


def _advance(k_stop, s, c, smp, rows, noise, obs, fn, params, pstate, lc, tab, lw):
    """Run the mission from the state's cursor until Python has to act; returns the status (module notes)."""
    cc = c[0]
    lk = (lc, tab, lw)
    while True:
        st = s[0]
        if st.phase == 0:
            if st.k >= st.k0 + len(smp) - 1:
                return DONE
            if st.k >= k_stop:
                return PAUSED
            if st.n_rows + cc.row_margin > rows.shape[0]:
                return FULL
            r = _begin_sample(s, cc, lk, smp, rows)
        else:
            r = _interval(s, cc, lk, smp, rows, noise, obs, fn, params, pstate)
        if r != OK:
            return r


def _array_of(dtype):
    return types.Array(from_dtype(dtype), 1, "C")


_ARGS = (types.int64, _array_of(STATE_DTYPE), _array_of(CONST_DTYPE), _array_of(SAMPLE_DTYPE), types.float64[:, ::1],
         _F8, _F8)
_LINK = (_F8, types.float64[:, :, :, ::1], types.complex128[::1])    # lc, tab, lw (modal_kernel)
# two overloads of the one loop: a compiled policy (first-class function), or none (a Python policy:
# NEED_ACT; ``fn is None`` prunes the call at compile time, and the call from Python skips the
# conversion of a function argument, ~0.1 ms, which would dominate a round trip per policy call)
_SIGNATURES = {True: types.int64(*_ARGS, POLICY_FN, _F8, _F8, *_LINK),
               False: types.int64(*_ARGS, types.none, _F8, _F8, *_LINK)}
_ONE = {}


def _compiled(sigs):
    """:func:`_advance` compiled for ``sigs`` (loaded from numba's disk cache, shared by every dispatcher of
    it; compiled the first time); the policy is a first-class function."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
        return njit(sigs, cache=True)(_advance)


def advance_for(compiled_policy: bool):
    """The loop compiled for a compiled policy (``fn`` a :data:`POLICY_FN`) or for a Python one (``fn``
    None): only that overload is loaded (each costs ~0.04 s of start-up, measured; the driver needs one)."""
    d = _ONE.get(bool(compiled_policy))
    if d is None:
        d = _ONE[bool(compiled_policy)] = _compiled([_SIGNATURES[bool(compiled_policy)]])
    return d


def __getattr__(name):
    """``advance``: both overloads in one dispatcher, made on first access (tests and callers that pass
    either kind of policy; :mod:`.fastpath` takes the one it needs from :func:`advance_for`)."""
    if name == "advance":
        adv = globals()["advance"] = _compiled(list(_SIGNATURES.values()))
        return adv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
