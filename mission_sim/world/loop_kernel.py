""":class:`~.loop.MissionLoop`'s run compiled with numba (``cache=True``): the fast path.

The same algorithm, step for step and in the same floating-point operations, as the pure-Python
reference in :mod:`.loop` (which stays the reference; ``tests/test_mission_fast.py`` compares the
two on the default mission to 1e-9). What differs is only where numpy and libm round differently
in the last bit (numpy's SIMD ``exp``/``arcsin``, BLAS dot products), which the test bounds.

This module imports numba at import time, so nothing imports it at module level: it is loaded by
:mod:`.fastpath` on the first compiled run (compiled once per machine, then loaded from numba's
disk cache). The policy comes in as a compiled function of the signature
:data:`mission_sim.contract.POLICY_KERNEL_SIGNATURE` (the optional ``Policy.kernel`` hook).

Arrays: ``cst`` constants (``C_*`` indices, filled by :func:`.fastpath.pack_constants`), ``s``
the loop state (``S_*``; :class:`~.loop.MissionLoop`'s slots of the same names), ``t_all``,
``lm_all``, ``k_all``, ``p_all``, ``elig`` per trajectory sample, ``rows`` (capacity, 26) the time
series in :data:`~.loop._COLUMNS` order. :func:`run_kernel` returns the next sample index and a
status (``OK``; ``FULL``: call again from that sample with more rows; ``DEPLETED``; ``ERR_POWER``,
``ERR_POLICY``: rerun the reference path, which raises the error with its message).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from numba import njit, types
from numba.core.errors import NumbaExperimentalFeatureWarning

__all__ = ["run_kernel", "POLICY_FN", "OK", "FULL", "DEPLETED", "ERR_POWER", "ERR_POLICY", "N_STATE", "N_CONST",
           "S_NAMES", "C_NAMES"]

OK, FULL, DEPLETED, ERR_POWER, ERR_POLICY, _NEED_DEPLETE = 0, 1, 2, 3, 4, 5

S_NAMES = ("x0", "x1", "v1", "tx_on", "cmd", "d", "soc", "vrc", "last_vl", "last_ib", "last_il", "in_fine",
           "fine_until_min", "fine_deadline", "t_cmd_zero", "t_last_bms", "t_last_act", "peak_env", "peak_d",
           "above", "n_fine", "n_coarse", "n_windows", "n_cut", "n_rows", "cv", "full", "depleted_at", "depleted_k",
           "p11", "p22", "tmp_ib")
(S_X0, S_X1, S_V1, S_TX_ON, S_CMD, S_D, S_SOC, S_VRC, S_LVL, S_LIB, S_LIL, S_IN_FINE, S_FMIN, S_FDEAD, S_TCZ, S_TBMS,
 S_TACT, S_PENV, S_PD, S_ABOVE, S_NFINE, S_NCOARSE, S_NWIN, S_NCUT, S_NROWS, S_CV, S_FULL, S_DEPAT, S_DEPK, S_P11,
 S_P22, S_TMPIB) = range(len(S_NAMES))
N_STATE = len(S_NAMES)
#: the slots deplete() saves and restores (``_STEP_STATE`` of the reference)
_SAVED = (S_X0, S_X1, S_SOC, S_VRC, S_PENV, S_PD, S_ABOVE, S_LVL, S_LIB, S_LIL)

C_NAMES = ("dtc", "k_on", "k_off", "ramp_rate", "rated", "inv_sqrt_l1l2", "t_rect", "r0", "r1b", "n_cells", "tau1",
           "vf", "dr_short", "v1_nom", "l1", "l2", "st_r1", "st_r2", "omega", "b0", "b1", "bat_c1", "capacity_c",
           "tx_off_delay", "bms_period", "cmd_deadband", "min_fine", "max_fine", "flight_dt", "lm_rel_tol",
           "coarse_period", "duty_event_tol", "settle_duty_tol", "settle_i2_tol", "cc_a", "v_cv", "cutoff_a",
           "inv_r", "vf0", "rd", "is_ideal", "coil_r1", "coil_r2", "v_recharge")
(C_DTC, C_K_ON, C_K_OFF, C_RAMP, C_RATED, C_INV_SQRT, C_T_RECT, C_R0, C_R1B, C_NCELLS, C_TAU1, C_VF, C_DR_SHORT,
 C_V1NOM, C_L1, C_L2, C_ST_R1, C_ST_R2, C_OMEGA, C_B0, C_B1, C_BAT_C1, C_CAP, C_TX_OFF_DELAY, C_BMS_PERIOD,
 C_CMD_DEADBAND, C_MIN_FINE, C_MAX_FINE, C_FLIGHT_DT, C_LM_REL_TOL, C_COARSE_PERIOD, C_DUTY_EVENT_TOL,
 C_SETTLE_DUTY_TOL, C_SETTLE_I2_TOL, C_CC, C_V_CV, C_CUTOFF, C_INV_R, C_VF0, C_RD, C_IS_IDEAL, C_COIL_R1,
 C_COIL_R2, C_V_RECHARGE) = range(len(C_NAMES))
N_CONST = len(C_NAMES)
_SOC_COL = 12
_FOUR_PI = 4.0 / math.pi
_F8 = types.float64[::1]
POLICY_FN = types.FunctionType(types.float64(_F8, _F8, _F8))


# ---------------------------------------------------------------------- the link (LinkStepper)
@njit(cache=True)
def _disc(cst, lm_h, dt_s):
    """``LinkStepper.disc``: (d00, d01, d10, d11, bd00, bd01, bd10, bd11, i00, i01, i10, i11, m10, m11, g1, g2)."""
    l1, l2, w, b0, b1 = cst[C_L1], cst[C_L2], cst[C_OMEGA], cst[C_B0], cst[C_B1]
    wlm = w * lm_h
    a00, a01, a10, a11 = -cst[C_ST_R1] / (2 * l1), -wlm / (2 * l1), wlm / (2 * l2), -cst[C_ST_R2] / (2 * l2)
    s = 0.5 * (a00 + a11)
    det = a00 * a11 - a01 * a10
    q2 = s * s - det
    q = math.sqrt(abs(q2))
    qt = q * dt_s
    e = math.exp(s * dt_s)
    if qt < 1e-8:
        ec, es = e, e * dt_s
    elif q2 < 0:
        ec, es = e * math.cos(qt), e * math.sin(qt) / q
    else:
        ep, em = math.exp((s + q) * dt_s), math.exp((s - q) * dt_s)
        ec, es = 0.5 * (ep + em), 0.5 * (ep - em) / q
    d00, d01 = ec + es * (a00 - s), es * a01
    d10, d11 = es * a10, ec + es * (a11 - s)
    i00, i01, i10, i11 = a11 / det, -a01 / det, -a10 / det, a00 / det
    m00 = i00 * (d00 - 1) + i01 * d10
    m01 = i00 * d01 + i01 * (d11 - 1)
    m10 = i10 * (d00 - 1) + i11 * d10
    m11 = i10 * d01 + i11 * (d11 - 1)
    bd00, bd10 = m00 * b0, m10 * b0
    bd01, bd11 = m01 * b1, m11 * b1
    g1 = i10 * (bd00 - b0 * dt_s) + i11 * bd10
    g2 = i10 * bd01 + i11 * (bd11 - b1 * dt_s)
    return (d00, d01, d10, d11, bd00, bd01, bd10, bd11, i00, i01, i10, i11, m10, m11, g1, g2)


@njit(cache=True)
def _lyap_rows(cst, lm_h):
    """Rows 1 and 3 of the inverse Lyapunov map (``LinkStepper._lyap_inv``: l0, l1, l2, l6, l7, l8)."""
    wlm = cst[C_OMEGA] * lm_h
    l1, l2 = cst[C_L1], cst[C_L2]
    a00, a01, a10, a11 = -cst[C_ST_R1] / (2 * l1), -wlm / (2 * l1), wlm / (2 * l2), -cst[C_ST_R2] / (2 * l2)
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
def _link_step(s, cst, lm_h, dt_s, v1, v2, dd):
    """``LinkStepper.step`` from state (S_X0, S_X1); p11, p22 into the state; returns
    ``(y0, y1, e_src, e_coil, e_rect, int_i2)``."""
    a0, a1 = s[S_X0], s[S_X1]
    y0 = dd[0] * a0 + dd[1] * a1 + dd[4] * v1 + dd[5] * v2
    y1 = dd[2] * a0 + dd[3] * a1 + dd[6] * v1 + dd[7] * v2
    bu0, bu1 = cst[C_B0] * v1, cst[C_B1] * v2
    r0 = y0 - a0 - bu0 * dt_s
    r1 = y1 - a1 - bu1 * dt_s
    s0 = dd[8] * r0 + dd[9] * r1
    s1 = dd[10] * r0 + dd[11] * r1
    q11 = y0 * y0 - a0 * a0 - 2 * bu0 * s0
    q12 = y0 * y1 - a0 * a1 - (bu0 * s1 + s0 * bu1)
    q22 = y1 * y1 - a1 * a1 - 2 * bu1 * s1
    l = _lyap_rows(cst, lm_h)
    p11 = l[0] * q11 + l[1] * q12 + l[2] * q22
    p22 = l[3] * q11 + l[4] * q12 + l[5] * q22
    s[S_P11], s[S_P22] = p11, p22
    e_coil = 0.5 * (cst[C_ST_R1] * p11 + cst[C_ST_R2] * p22)
    return y0, y1, 0.5 * v1 * s0, e_coil, 0.5 * v2 * s1, s1


@njit(cache=True)
def _i2_samples(cst, lm_h, dt_s, a0, a1, v1, v2, m, out):
    """``LinkStepper.i2_samples`` into ``out[:m - 1]``."""
    dd = _disc(cst, lm_h, dt_s / m)
    for j in range(m - 1):
        a0, a1 = (dd[0] * a0 + dd[1] * a1 + dd[4] * v1 + dd[5] * v2, dd[2] * a0 + dd[3] * a1 + dd[6] * v1 + dd[7] * v2)
        out[j] = a1


@njit(cache=True)
def _track_peak(s, cst, i2s, d, dt_each):
    i2s = abs(i2s)
    if i2s > s[S_PENV]:
        s[S_PENV], s[S_PD] = i2s, d
    if i2s > cst[C_RATED]:
        s[S_ABOVE] += dt_each


# ---------------------------------------------------------------------- battery
@njit(cache=True)
def _ocv_cell(s):
    s = 0.0 if s < 0.0 else (1.0 if s > 1.0 else s)
    return -1.031 * math.exp(-35.0 * s) + 3.685 + 0.2156 * s - 0.1178 * s * s + 0.3201 * s * s * s


@njit(cache=True)
def _bat_step(cst, soc, v1_v, i, dt_s):
    """``battery.scalar_stepper``'s step: (soc1, v1_1, chem_j, r0_loss_j, r1_loss_j, c1_delta_j)."""
    r0, r1, tau, c1, n_cells, cap = cst[C_R0], cst[C_R1B], cst[C_TAU1], cst[C_BAT_C1], cst[C_NCELLS], cst[C_CAP]
    e = math.exp(-dt_s / tau)
    vinf = r1 * i
    dv = v1_v - vinf
    int_v2 = vinf * vinf * dt_s + 2.0 * vinf * dv * tau * (1.0 - e) + dv * dv * 0.5 * tau * (1.0 - e * e)
    ocv = n_cells * _ocv_cell(soc)
    dq = i * dt_s
    v1n = vinf + dv * e
    return (soc + dq / cap, v1n, ocv * dq, r0 * i * i * dt_s, int_v2 / r1, 0.5 * c1 * (v1n * v1n - v1_v * v1_v))


@njit(cache=True)
def _charger_command(s, cst, i_prop):
    """``CcCvCharger.command_a`` for one battery (its cv / full flags in the state; both clear below
    the recharge threshold)."""
    sc = min(max(s[S_SOC], 0.0), 1.0)
    ocv = cst[C_NCELLS] * (-1.031 * math.exp(-35.0 * sc) + 3.685 + 0.2156 * sc - 0.1178 * sc ** 2
                           + 0.3201 * math.pow(sc, 3.0))
    v_rest = ocv + s[S_VRC]
    if s[S_FULL] != 0.0 and v_rest < cst[C_V_RECHARGE]:
        s[S_FULL], s[S_CV] = 0.0, 0.0
    i_cv = (cst[C_V_CV] - v_rest) / cst[C_R0]
    if i_cv < cst[C_CC]:
        s[S_CV] = 1.0
    tgt = min(cst[C_CC], i_cv)
    if s[S_CV] != 0.0 and tgt < cst[C_CUTOFF]:
        s[S_FULL] = 1.0
    if s[S_FULL] != 0.0:
        return 0.0
    return max(tgt, 0.0) + i_prop


# ---------------------------------------------------------------------- link + battery node
@njit(cache=True)
def _step(s, cst, rows, t0, dt, lm, p_prop, row_k, fine):
    """``MissionLoop.step``: OK, ERR_POWER, or _NEED_DEPLETE (SoC < 0: nothing written, I_b in S_TMPIB)."""
    a0, a1, v1, d, soc, vrc, tau1 = s[S_X0], s[S_X1], s[S_V1], s[S_D], s[S_SOC], s[S_VRC], cst[C_TAU1]
    sgn = (a1 > 0.0) - (a1 < 0.0)
    c = _FOUR_PI * 1.0 * (1.0 - math.sin(0.5 * np.pi * d)) * sgn if v1 > 0.0 else 0.0
    w_short = d + math.sin(math.pi * d) / math.pi
    v2x = c * cst[C_VF] + (cst[C_DR_SHORT] * w_short * a1 if v1 > 0.0 else 0.0)
    frac = tau1 * (1.0 - math.exp(-dt / tau1)) / dt
    a0b = cst[C_NCELLS] * _ocv_cell(soc) + vrc * frac
    g = cst[C_R0] + cst[C_R1B] * (1.0 - frac)
    lm_eff = lm if lm > 0 else 1e-12
    dd = _disc(cst, lm_eff, dt)
    s0 = dd[12] * a0 + dd[13] * a1 + dd[14] * v1 + dd[15] * v2x
    alpha = 1.0 - g * c * c * dd[15] / (2 * dt)
    beta = a0b + g * c * s0 / (2 * dt)
    disc = beta * beta - 4 * alpha * g * p_prop
    if disc < 0:
        return ERR_POWER
    vl = (beta + math.sqrt(disc)) / (2 * alpha)
    v2 = c * vl + v2x
    if fine:
        smp = np.empty(3)
        _i2_samples(cst, lm_eff, dt, a0, a1, v1, v2, 4, smp)
        for j in range(3):
            _track_peak(s, cst, smp[j], d, dt / 4)
    y0, y1, e_src, e_coil, e_rect, int_i2 = _link_step(s, cst, lm_eff, dt, v1, v2, dd)
    i_l = 0.5 * c * int_i2 / dt
    i_p = p_prop / vl
    i_b = i_l - i_p
    soc, vrc, e_chem, e_r0, e_r1, e_c1 = _bat_step(cst, soc, vrc, i_b, dt)
    if soc < 0.0 and math.isnan(s[S_DEPAT]):
        s[S_TMPIB] = i_b
        return _NEED_DEPLETE
    _track_peak(s, cst, y1, d, dt / 4 if fine else dt)
    s[S_X0], s[S_X1], s[S_SOC], s[S_VRC] = y0, y1, soc, vrc
    s[S_LVL], s[S_LIB], s[S_LIL] = vl, i_b, i_l
    e_out = vl * i_l * dt
    _write_row(s, cst, rows, (t0 + dt, dt, float(row_k), lm, v1, y0, y1, d, v2, i_l, vl, i_b, soc, s[S_CMD], 1.0 if fine else 0.0,
                              e_src), e_coil + e_rect - e_out, i_l * dt, w_short, e_out, e_chem, e_r0, e_r1, e_c1,
               vl * i_p * dt)
    return OK


@njit(cache=True)
def _write_row(s, cst, rows, head, e_loss, charge_c, w_short, e_out, e_chem, e_r0, e_r1, e_c1, e_prop):
    """Append one row: ``head`` (16 values) and ``MissionLoop.device_split``'s energies."""
    p11, p22 = s[S_P11], s[S_P22]
    e_inv = 0.5 * cst[C_INV_R] * p11
    e_dio = cst[C_VF0] * charge_c + 0.5 * cst[C_RD] * p22 * (1.0 - w_short)
    e_coil = 0.5 * (cst[C_COIL_R1] * p11 + cst[C_COIL_R2] * p22)
    ideal = cst[C_IS_IDEAL] != 0.0
    e_sw = 0.0 if ideal else e_loss - e_coil - e_inv - e_dio
    r = int(s[S_NROWS])
    row = rows[r]
    for j in range(16):
        row[j] = head[j]
    row[16] = e_loss if ideal else e_coil
    row[17], row[18], row[19], row[20], row[21], row[22] = e_out, e_chem, e_r0, e_r1, e_c1, e_prop
    row[23], row[24], row[25] = e_inv, e_dio, e_sw
    s[S_NROWS] = r + 1


@njit(cache=True)
def _deplete(s, cst, rows, t0, dt, lm, p_prop, row_k, fine):
    """``MissionLoop.deplete``: cut the step where SoC reaches 0 (fixed point); DEPLETED or ERR_POWER."""
    i_b = s[S_TMPIB]
    soc0, cap = s[S_SOC], cst[C_CAP]
    saved = np.empty(len(_SAVED))
    for j in range(len(_SAVED)):
        saved[j] = s[_SAVED[j]]
    s[S_DEPAT] = t0
    h = dt
    for _ in range(20):
        h = min(dt, soc0 * cap / -i_b) if i_b < 0.0 else dt
        if h <= 1e-12:
            h = 0.0
            break
        if _step(s, cst, rows, t0, h, lm, p_prop, row_k, fine) == ERR_POWER:
            return ERR_POWER
        if abs(s[S_SOC]) <= 1e-9:
            break
        i_b = s[S_LIB]
        s[S_NROWS] -= 1
        for j in range(len(_SAVED)):
            s[_SAVED[j]] = saved[j]
    if h > 0.0 and s[S_SOC] < 0.0:
        s[S_SOC] = 0.0
        rows[int(s[S_NROWS]) - 1, _SOC_COL] = 0.0
    s[S_DEPAT], s[S_DEPK] = t0 + h, row_k
    return DEPLETED


@njit(cache=True)
def _step_d(s, cst, rows, t0, dt, lm, p_prop, row_k, fine):
    """:func:`_step`, running :func:`_deplete` when the battery runs out in it."""
    r = _step(s, cst, rows, t0, dt, lm, p_prop, row_k, fine)
    if r == _NEED_DEPLETE:
        return _deplete(s, cst, rows, t0, dt, lm, p_prop, row_k, fine)
    return r


@njit(cache=True)
def _fine_step(s, cst, rows, t0, dt, lm, p_prop, row_k):
    """``MissionLoop.fine_step``: split into rectifier-period sub-steps when I2 changes sign in it."""
    a0, a1, d, v1, t_rect = s[S_X0], s[S_X1], s[S_D], s[S_V1], cst[C_T_RECT]
    if v1 > 0.0 and d < 1.0 and dt > 1.5 * t_rect and a1 != 0.0:
        lm_eff = lm if lm > 0 else 1e-12
        v2p = (_FOUR_PI * (1.0 - math.sin(0.5 * math.pi * d)) * (s[S_LVL] + cst[C_VF]) * (1.0 if a1 > 0.0 else -1.0)
               + cst[C_DR_SHORT] * (d + math.sin(math.pi * d) / math.pi) * a1)
        smp = np.empty(8)
        _i2_samples(cst, lm_eff, dt, a0, a1, v1, v2p, 8, smp)
        dd = _disc(cst, lm_eff, dt)
        smp[7] = dd[2] * a0 + dd[3] * a1 + dd[6] * v1 + dd[7] * v2p
        cross = False
        for j in range(8):
            if smp[j] * a1 <= 0.0:
                cross = True
        if cross:
            k_sub = math.ceil(dt / t_rect - 1e-9)
            h = dt / k_sub
            for j in range(k_sub):
                r = _step_d(s, cst, rows, t0 + j * h, h, lm, p_prop, row_k, True)
                if r != OK:
                    return r
            return OK
    return _step_d(s, cst, rows, t0, dt, lm, p_prop, row_k, True)


# ---------------------------------------------------------------------- policy, windows
@njit(cache=True)
def _act(s, pol, t):
    """``MissionLoop.act`` (no sensor noise): the contract's observation, the policy, d in [0, 1] (NaN: not finite)."""
    fn, params, state, lo, inv, obs = pol
    t_since = min(t - s[S_TCZ], 1.0) if s[S_CMD] == 0.0 else 0.0
    vals = (abs(s[S_X1]) + 0.0, s[S_LVL], s[S_LIB], s[S_LIL], s[S_SOC], s[S_CMD], s[S_D], t_since)
    for j in range(8):
        obs[j] = min(max(2.0 * (vals[j] - lo[j]) * inv[j] - 1.0, -1.0), 1.0)
    out = fn(obs, params, state)
    if not math.isfinite(out):
        return math.nan
    return min(max(out, 0.0), 1.0)


@njit(cache=True)
def _open_window(s, cst, t):
    s[S_IN_FINE] = 1.0
    s[S_NWIN] += 1
    s[S_FMIN] = t + cst[C_MIN_FINE]
    s[S_FDEAD] = t + cst[C_MAX_FINE]


@njit(cache=True)
def _settled(s, cst, lm):
    """``MissionLoop.settled``."""
    v1, tol = s[S_V1], cst[C_SETTLE_I2_TOL]
    if abs(v1 - (cst[C_V1NOM] if s[S_TX_ON] != 0.0 else 0.0)) > 0.0:
        return False
    if v1 == 0.0:
        return abs(s[S_X0]) < tol and abs(s[S_X1]) < tol
    d = s[S_D]
    c = _FOUR_PI * (1.0 - math.sin(0.5 * math.pi * d))
    wlm = cst[C_OMEGA] * lm
    r2 = cst[C_ST_R2] + cst[C_DR_SHORT] * (d + math.sin(math.pi * d) / math.pi)
    det = cst[C_ST_R1] * r2 + wlm * wlm
    i2ss = (wlm * v1 - cst[C_ST_R1] * c * (s[S_LVL] + cst[C_VF])) / det if lm > 0 else 0.0
    return abs(s[S_X1] - i2ss) < tol


@njit(cache=True)
def _window_done(s, cst, t, d_prev, lm):
    """``MissionLoop.window_done``."""
    dv = abs(math.sin(0.5 * math.pi * s[S_D]) - math.sin(0.5 * math.pi * d_prev))
    if t >= s[S_FMIN] and (dv < cst[C_SETTLE_DUTY_TOL] or s[S_V1] == 0.0) and _settled(s, cst, lm):
        s[S_IN_FINE] = 0.0
    elif t >= s[S_FDEAD] and s[S_V1] == (cst[C_V1NOM] if s[S_TX_ON] != 0.0 else 0.0):
        s[S_IN_FINE] = 0.0
        s[S_NCUT] += 1


@njit(cache=True)
def _fine_tick(s, cst, rows, pol, t, dt, lm_s, p_k, k, fast_lm, off_due, fresh):
    """``MissionLoop.fine_tick``: gating and V1 ramp, policy, fine step, window end check."""
    if fast_lm and s[S_TX_ON] != 0.0 and lm_s * cst[C_INV_SQRT] < cst[C_K_OFF]:
        s[S_TX_ON] = 0.0
        s[S_CMD] = 0.0
    if s[S_TX_ON] != 0.0 and s[S_CMD] == 0.0 and off_due and t - s[S_TCZ] >= cst[C_TX_OFF_DELAY]:
        s[S_TX_ON] = 0.0
    v1 = s[S_V1]
    target = cst[C_V1NOM] if s[S_TX_ON] != 0.0 else 0.0
    if v1 != target:
        step_v = cst[C_RAMP] * dt
        v1 = min(target, v1 + step_v) if target > v1 else max(target, v1 - step_v)
        s[S_V1] = v1
    d_prev = s[S_D]
    if not fresh:
        d = _act(s, pol, t)
        if math.isnan(d):
            return ERR_POLICY
        s[S_D] = d
    s[S_TACT] = t
    r = _fine_step(s, cst, rows, t, dt, lm_s, p_k, k)
    if r != OK:
        return r
    s[S_NFINE] += 1
    if fast_lm and v1 > 0.0:
        return OK
    _window_done(s, cst, t + dt, d_prev, lm_s)
    return OK


@njit(cache=True)
def _coarse_policy(s, cst, pol, t):
    """``MissionLoop.coarse_policy``: 1 if the duty moved (a window opened), 0 if not, -1 on a policy error."""
    d_new = _act(s, pol, t)
    if math.isnan(d_new):
        return -1
    s[S_TACT] = t
    moved = abs(d_new - s[S_D]) > cst[C_DUTY_EVENT_TOL]
    s[S_D] = d_new
    if moved:
        _open_window(s, cst, t)
    return 1 if moved else 0


@njit(cache=True)
def _interval(s, cst, rows, pol, arrays, k, t_k, ending):
    """``MissionLoop.interval``: fine steps while needed, then one coarse step to t_k+1."""
    t_all, lm_all, k_all, p_all, elig = arrays
    t_next, p_k, lm, lm_n = t_all[k + 1], p_all[k], lm_all[k], lm_all[k + 1]
    fast_lm = abs(lm_n - lm) > cst[C_LM_REL_TOL] * max(abs(lm), 1e-9) or k_all[k + 1] < cst[C_K_OFF]
    off_due = elig[k] == 0.0 or ending
    t = t_k
    fresh = False
    while t < t_next - 1e-12:
        if fast_lm and s[S_V1] > 0.0 and s[S_IN_FINE] == 0.0:
            _open_window(s, cst, t)
        if s[S_IN_FINE] == 0.0 and t - s[S_TACT] >= cst[C_COARSE_PERIOD] - 1e-12:
            moved = _coarse_policy(s, cst, pol, t)
            if moved < 0:
                return ERR_POLICY
            fresh = moved == 1
        if s[S_IN_FINE] != 0.0:
            dt = min(cst[C_DTC], t_next - t)
            lm_s = lm
            if fast_lm:
                lm_s = lm + (lm_n - lm) * (t + 0.5 * dt - t_k) / (t_next - t_k)
            r = _fine_tick(s, cst, rows, pol, t, dt, lm_s, p_k, k, fast_lm, off_due, fresh)
            if r != OK:
                return r
            fresh = False
            t += dt
        else:
            r = _step_d(s, cst, rows, t, t_next - t, lm, p_k, k, False)
            if r != OK:
                return r
            s[S_NCOARSE] += 1
            t = t_next
    return OK


@njit(cache=True)
def _quiet_flight(s, cst, rows, arrays, k, t_k):
    """``MissionLoop.quiet_flight``: (next k, status)."""
    t_all, lm_all, k_all, p_all, elig = arrays
    n = len(t_all)
    j = k + 1
    while j < n - 1 and elig[j] == 0.0 and t_all[j + 1] - t_k <= cst[C_FLIGHT_DT] + 1e-9:
        j += 1
    dt = t_all[j] - t_k
    acc = 0.0
    for i in range(k, j):
        acc += p_all[i] * (t_all[i + 1] - t_all[i])
    r = _step_d(s, cst, rows, t_k, dt, lm_all[k], acc / dt, k, False)
    if r == OK:
        s[S_NCOARSE] += 1
    return j, r


@njit(cache=True)
def _gate_pad(s, cst, arrays, k, t_k, ending):
    """``MissionLoop.gate_pad``: True on an event."""
    elig = arrays[4]
    kk = arrays[2][k]
    if s[S_TX_ON] != 0.0:
        if kk < cst[C_K_OFF]:
            s[S_TX_ON] = 0.0
            if s[S_CMD] != 0.0:
                s[S_TCZ] = t_k
            s[S_CMD] = 0.0
        elif elig[k] == 0.0 or ending:
            if s[S_CMD] != 0.0:
                s[S_CMD] = 0.0
                s[S_TCZ] = t_k
            elif t_k - s[S_TCZ] >= cst[C_TX_OFF_DELAY]:
                s[S_TX_ON] = 0.0
        else:
            return False
        return True
    if elig[k] != 0.0 and not ending and kk >= cst[C_K_ON] and s[S_V1] == 0.0:
        s[S_TX_ON] = 1.0
        return True
    return False


@njit(cache=True)
def _bms_command(s, cst, arrays, k, t_k, ending):
    """``MissionLoop.bms_command``: True if the command changed."""
    if not (s[S_TX_ON] != 0.0 and s[S_V1] == cst[C_V1NOM] and arrays[4][k] != 0.0 and not ending
            and t_k - s[S_TBMS] >= cst[C_BMS_PERIOD] - 1e-12):
        return False
    s[S_TBMS] = t_k
    new = _charger_command(s, cst, arrays[3][k] / s[S_LVL])
    cmd = s[S_CMD]
    if abs(new - cmd) > cst[C_CMD_DEADBAND] or (new == 0.0) != (cmd == 0.0):
        if new == 0.0:
            s[S_TCZ] = t_k
        s[S_CMD] = new
        return True
    return False


@njit(cache=True)
def _rows_needed(cst, dt):
    """Most rows one trajectory interval of length ``dt`` can write (fine steps split to rectifier periods)."""
    return (math.ceil(dt / cst[C_DTC]) + 2) * (math.ceil(cst[C_DTC] / cst[C_T_RECT]) + 1) + 4


@njit(cache=True)
def _sample(s, cst, rows, pol, arrays, k):
    """``MissionLoop.sample``: (next k, status)."""
    t_all, elig = arrays[0], arrays[4]
    t_k = t_all[k]
    ending = elig[k] != 0.0 and elig[k + 1] == 0.0
    event = _gate_pad(s, cst, arrays, k, t_k, ending)
    event = _bms_command(s, cst, arrays, k, t_k, ending) or event
    if event:
        _open_window(s, cst, t_k)
    if s[S_IN_FINE] == 0.0 and s[S_TX_ON] == 0.0 and s[S_V1] == 0.0 and s[S_CMD] == 0.0:
        return _quiet_flight(s, cst, rows, arrays, k, t_k)
    return k + 1, _interval(s, cst, rows, pol, arrays, k, t_k, ending)


def _run(k, k_stop, s, cst, t_all, lm_all, k_all, p_all, elig, rows, fn, params, state, lo, inv):
    """Run the mission from trajectory sample ``k`` until ``k >= k_stop``; returns ``(k, status)``
    (module docstring)."""
    arrays = (t_all, lm_all, k_all, p_all, elig)
    pol = (fn, params, state, lo, inv, np.empty(8))
    n = min(len(t_all), k_stop + 1)
    cap = rows.shape[0]
    while k < n - 1:
        if s[S_NROWS] + _rows_needed(cst, t_all[k + 1] - t_all[k]) > cap:
            return k, FULL
        k, r = _sample(s, cst, rows, pol, arrays, k)
        if r != OK:
            return k, r
    return k, OK


with warnings.catch_warnings():  # compiled (or loaded from the cache) here; the policy is a first-class function
    warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
    run_kernel = njit(types.UniTuple(types.int64, 2)(types.int64, types.int64, _F8, _F8, _F8, _F8, _F8, _F8, _F8,
                                                     types.float64[:, ::1], POLICY_FN, _F8, _F8, _F8, _F8),
                      cache=True)(_run)
